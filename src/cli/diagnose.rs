//! `gedisim diagnose`.

use std::path::PathBuf;
use std::time::Instant;
use tracing::info;

use clap::Args;

use gedisim::{Error, Result};

use super::reporters::Bars;
use super::run::{print_ingest_and_collocation, ChainArgs};
use super::simulate::PulseArgs;

#[derive(Args)]
pub struct DiagnoseArgs {
    /// A dataset after `gedisim run` (or at least `ingest als`, `ingest gedi`; collocated here if it has no offsets).
    #[arg(long, conflicts_with_all = ["als", "l1b", "l2a"])]
    dataset: Option<PathBuf>,
    /// ALS tiles (files or folders): with --l1b and --l2a, the whole chain into <out>/dataset.
    #[arg(long, num_args = 1.., requires_all = ["l1b", "l2a"])]
    als: Vec<PathBuf>,
    /// L1B granules (files or folders).
    #[arg(long, num_args = 1..)]
    l1b: Vec<PathBuf>,
    /// L2A granules (files or folders).
    #[arg(long, num_args = 1..)]
    l2a: Vec<PathBuf>,
    #[command(flatten)]
    chain: ChainArgs,
    /// Output directory (diagnosis.json, tables, figures).
    #[arg(long)]
    out: PathBuf,
    /// Try only these effects (comma-separated; default: every effect the diagnosis fits).
    #[arg(long, value_delimiter = ',')]
    effects: Vec<String>,
    #[command(flatten)]
    pulse: PulseArgs,
    /// Print the verdict as one JSON object on stdout (instead of the summary lines).
    #[arg(long)]
    json: bool,
    /// Diagnose again even when <out> holds the diagnosis of the same inputs.
    #[arg(long)]
    force: bool,
    /// Self-test: twin sets of the shots per planted hypothesis (each leading candidate, and none),
    /// ranked the same way; they decide the verdict and say how often it is right. 0 skips it
    /// (docs/diagnosis.md, "The self-test").
    #[arg(long, default_value_t = gedisim::kernels::diagnose::selftest::TWINS, value_name = "N")]
    twins: usize,
    /// The configuration, the effects and the self-test on the shots of whole tracks drawn at
    /// random until they hold N shots; where the gap lies on every shot. 0: every shot
    /// (docs/diagnosis.md, "Shots ranked").
    #[arg(long, default_value_t = gedisim::kernels::diagnose::sample::RANKED_SHOTS, value_name = "N")]
    ranked_shots: usize,
}

pub fn diagnose(a: DiagnoseArgs) -> Result<()> {
    use gedisim::ops::diagnose::DiagnoseInput;
    let start = Instant::now();
    let input = match a.dataset {
        Some(d) => DiagnoseInput::Dataset(d),
        None if a.als.is_empty() => return Err(Error::Usage("give --dataset, or --als with --l1b and --l2a".into())),
        // The first half of `gedisim run`, with the diagnosis's per-beam collocation.
        None => DiagnoseInput::Chain(Box::new(a.chain.run_options(a.als, a.l1b, a.l2a, &a.out.join("dataset"))?)),
    };
    let opts = gedisim::ops::diagnose::DiagnoseOptions {
        effects: a.effects,
        pulse: a.pulse.model("recorded", None),
        twins: a.twins,
        ranked_shots: a.ranked_shots,
        force: a.force,
    };
    let r = gedisim::ops::diagnose::diagnose(input, &a.out, &opts, &Bars::new())?;
    if let Some(chain) = &r.chain {
        print_ingest_and_collocation(chain);
    }
    if let Some(c) = &r.collocated {
        info!("no offsets table: collocated per beam first ({} segments → {})", c.segments, c.table.display());
    }
    let out = &r.output;
    let shots = &out.json.shots;
    let dropped: Vec<(&str, usize)> = shots.dropped.iter().map(|d| (d.reason.as_str(), d.n)).collect();
    let dropped = gedisim::ops::diagnose::dropped_text(&dropped);
    info!("shots: {} read, {} used, {} ranked; dropped: {dropped}", shots.read, shots.used, shots.ranked);
    if out.reused {
        info!(
            "inputs unchanged since {}: diagnosis reused (--force recomputes)",
            a.out.join("diagnosis.json").display()
        );
    }
    if a.json {
        let j = &out.json;
        let value = serde_json::json!({
            "out": a.out,
            "diagnosis_json": a.out.join("diagnosis.json"),
            "unexplained": j.unexplained,
            "ladder": j.ladder.iter().map(|t| serde_json::json!({
                "name": t.name, "params": t.params, "shrink": t.held_out.shrink, "ci95": t.held_out.ci95
            })).collect::<Vec<_>>(),
            "ambiguous_with": j.ambiguous_with,
            "verdict": j.verdict,
            "self_test": j.self_test.as_ref().and_then(|t| t.named.clone()),
            "signs": j.signs,
            "baseline": j.baseline,
            "shots": j.shots,
            "summary": j.summary,
            "files": out.files,
            "seconds": start.elapsed().as_secs_f64(),
        });
        println!("{value}");
    } else {
        for line in &out.json.summary {
            println!("{line}");
        }
    }
    info!("diagnosis.json, tables, figures → {} ({:.1} s)", a.out.display(), start.elapsed().as_secs_f64());
    Ok(())
}
