//! `gedisim demo`.

use std::path::PathBuf;
use std::time::Instant;
use tracing::{info, warn};

use clap::Args;

use gedisim::Result;

use super::reporters::Bars;
use super::run::print_run;

#[derive(Args)]
pub struct DemoArgs {
    /// Output folder: world/ (tiles, granules, truth.json) and dataset/ (tables, report/).
    #[arg(long, default_value = "gedisim-demo")]
    out: PathBuf,
    /// Effect withheld from the simulation and planted in the generated granules (see `scenario`).
    #[arg(long, default_value = "ground_detection")]
    effect: String,
    /// Seed of the generated granules.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Granules (passes) crossing each tile.
    #[arg(long, default_value_t = 8)]
    passes: usize,
    /// Replace a demo of another effect or seed in --out.
    #[arg(long)]
    force: bool,
}

pub fn demo(a: DemoArgs) -> Result<()> {
    let start = Instant::now();
    let opts = gedisim::ops::demo::DemoOptions {
        out: a.out.clone(),
        effect: a.effect,
        seed: a.seed,
        passes: a.passes,
        force: a.force,
    };
    let d = gedisim::ops::demo::run_demo(&opts, &Bars::new())?;
    match &d.world {
        Some(w) => {
            w.notes.iter().for_each(|n| warn!("{n}"));
            info!(
                "world: {} tiles, {} granules, {} shots, effect {} → {}",
                w.tiles,
                w.granules,
                w.shots,
                opts.effect,
                d.world_dir.display()
            )
        }
        None => info!("world: reusing {} (effect {}, seed {})", d.world_dir.display(), opts.effect, opts.seed),
    }
    print_run(&d.run);
    for (name, missing) in &d.report.skipped {
        info!("report: {name} skipped (no {} table)", missing.join(", "));
    }
    println!();
    print!("{}", d.headline.ground_table());
    println!();
    print!("{}", d.headline.msd_table());
    println!();
    println!("report: {}", d.report.html.display());
    println!();
    println!("Diagnosis (the withheld effect is not told; truth: {}):", d.world_dir.join("truth.json").display());
    if d.diagnosis.reused {
        info!("diagnosis: inputs unchanged since {}, reused", a.out.join("diagnosis").display());
    }
    for line in &d.diagnosis.json.summary {
        println!("  {line}");
    }
    println!("diagnosis: {}", a.out.join("diagnosis").join("diagnosis.json").display());
    info!("demo finished in {:.0} s", start.elapsed().as_secs_f64());
    Ok(())
}
