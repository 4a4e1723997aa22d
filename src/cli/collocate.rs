//! `gedisim collocate`.

use std::path::PathBuf;
use std::time::Instant;
use tracing::info;

use clap::Args;

use gedisim::Result;

use super::reporters::{cpu_seconds, peak_rss_mb, Bars};
use super::simulate::PulseArgs;

#[derive(Args)]
pub struct CollocateArgs {
    /// Dataset directory with ingested shots (with L1B waveforms) and ALS.
    #[arg(long)]
    dataset: PathBuf,
    /// beam: each beam (its ground track) cut into segments; granule (alias: track): all beams of
    /// a granule share an offset per along-track segment; shot: one offset per shot from it and
    /// its neighbours.
    #[arg(long, value_enum, default_value = "beam")]
    level: LevelArg,
    /// Longest segment: shots (beam level) or along-track shot steps (granule level).
    #[arg(long, default_value_t = 40)]
    segment: usize,
    /// Largest horizontal shift searched (m).
    #[arg(long, default_value_t = 10.0)]
    max_shift: f64,
    /// Horizontal grid step (m).
    #[arg(long, default_value_t = 1.0)]
    step: f64,
    /// Fewest shots of a segment: shorter runs are reported and not solved (1: solve every run).
    #[arg(long, default_value_t = gedisim::kernels::collocate::segments::MIN_SEGMENT)]
    min_segment: usize,
    #[command(flatten)]
    pulse: PulseArgs,
    /// Collocate on the Ballista cluster whose scheduler is at this address (`gedisim cluster`):
    /// one plan, a partition per granule; every node must see the dataset (and a pulse file) at the
    /// same path.
    #[arg(long, value_name = "df://HOST:PORT")]
    cluster: Option<String>,
    /// Print wall time and peak memory at the end.
    #[arg(long)]
    stats: bool,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum LevelArg {
    Beam,
    #[value(alias = "track")]
    Granule,
    Shot,
}

pub fn collocate(a: CollocateArgs) -> Result<()> {
    use gedisim::ops::collocate::CollocateOptions;
    let start = Instant::now();
    let level = collocate_level(a.level);
    let ds = gedisim::dataset::Dataset::create(&a.dataset)?;
    let opts = CollocateOptions {
        level,
        segment: a.segment,
        max_shift: a.max_shift,
        step: a.step,
        min_segment: a.min_segment,
        pulse: a.pulse.model("recorded", None),
    };
    let engine = a.cluster.map(gedisim::ops::collocate::Engine::Cluster).unwrap_or_default();
    let report = gedisim::ops::collocate::collocate_on(&engine, &ds, &opts, &Bars::new())?;
    for s in &report.short_runs {
        info!("too short, not collocated: {s}");
    }
    let skipped: Vec<String> = report.skipped.iter().map(|(k, v)| format!("{k} {v}")).collect();
    if !skipped.is_empty() {
        info!("shots not used: {}", skipped.join(", "));
    }
    info!("{} shots read, {} {} offsets → {}", report.shots, report.segments, level.name(), report.table.display());
    if a.stats {
        println!(
            "collocate: {:.2} s, CPU {:.2} s, peak RSS {:.1} MB, {} ALS points kept from {} row groups",
            start.elapsed().as_secs_f64(),
            cpu_seconds(),
            peak_rss_mb(),
            report.als_points_read,
            report.als_row_groups_read
        );
    }
    Ok(())
}

pub fn collocate_level(l: LevelArg) -> gedisim::kernels::collocate::segments::Level {
    use gedisim::kernels::collocate::segments::Level;
    match l {
        LevelArg::Beam => Level::Beam,
        LevelArg::Granule => Level::Granule,
        LevelArg::Shot => Level::Shot,
    }
}
