//! `gedisim run`, and the printing of what a run did (shared with `demo` and `diagnose`).

use std::path::{Path, PathBuf};
use tracing::{info, warn};

use clap::Args;

use gedisim::ops::run::RunOptions;
use gedisim::Result;

use super::collocate::{collocate_level, LevelArg};
use super::reporters::Bars;

/// Options of the ingest chain shared by `run` and `diagnose --als`.
#[derive(Args)]
pub struct ChainArgs {
    /// Corine Land Cover GeoTIFF (EPSG:3035) or CSV shot_number,forest_type: forest type of every shot.
    #[arg(long)]
    pub landcover: Option<PathBuf>,
    /// Projected CRS (default: the dataset's ALS CRS, else 2154).
    #[arg(long)]
    pub epsg: Option<u32>,
    /// Geoid offset N (m, ellipsoid − orthometric) for every shot, instead of each shot's L1B geoid.
    #[arg(long, allow_hyphen_values = true, value_parser = super::values::geoid_offset)]
    pub geoid_offset: Option<f64>,
    #[command(flatten)]
    pub shots: super::ingest::ShotArgs,
}

impl ChainArgs {
    /// `run`'s options for these inputs into the dataset `out` (the rest at their defaults).
    pub fn run_options(
        self,
        als: Vec<PathBuf>,
        l1b: Vec<PathBuf>,
        l2a: Vec<PathBuf>,
        out: &Path,
    ) -> Result<RunOptions> {
        Ok(RunOptions {
            als,
            l1b,
            l2a,
            landcover: self.landcover,
            epsg: self.epsg,
            geoid_offset: self.geoid_offset,
            shots: self.shots.choice()?,
            ..RunOptions::new(out)
        })
    }
}

#[derive(Args)]
pub struct RunArgs {
    /// LAS/LAZ tiles or folders (may be left out once the dataset holds the tiles).
    #[arg(long, num_args = 1..)]
    als: Vec<PathBuf>,
    /// GEDI L1B files or folders.
    #[arg(long, num_args = 1..)]
    l1b: Vec<PathBuf>,
    /// GEDI L2A files or folders.
    #[arg(long, num_args = 1..)]
    l2a: Vec<PathBuf>,
    #[command(flatten)]
    chain: ChainArgs,
    /// Dataset directory (created if needed).
    #[arg(long, alias = "out")]
    dataset: PathBuf,
    /// Keep shots at most this many days before the start or after the end of the ALS acquisition
    /// of their footprint (not applied where the tiles carry no date).
    #[arg(long, allow_hyphen_values = true, default_value_t = gedisim::kernels::study::select::DEFAULT_MAX_DAYS_APART)]
    max_days_apart: f64,
    /// Collocation level of new granules (see `collocate`).
    #[arg(long, value_enum, default_value = "beam")]
    level: LevelArg,
    /// Longest collocation segment (see `collocate`).
    #[arg(long, default_value_t = 40)]
    segment: usize,
    /// Fewest shots of a collocation segment (see `collocate`; 1: solve every run).
    #[arg(long, default_value_t = gedisim::kernels::collocate::segments::MIN_SEGMENT)]
    min_segment: usize,
    // The collocation's transmit pulse: the study's simulation keeps its 15 ns Gaussian.
    #[command(flatten)]
    pulse: super::simulate::PulseArgs,
    /// Collocate and simulate on the Ballista cluster whose scheduler is at this address
    /// (`gedisim cluster`): a plan each, a partition per granule to collocate and per group of a
    /// granule's blocks to simulate; every node must see the dataset at the same path.
    #[arg(long, value_name = "df://HOST:PORT")]
    cluster: Option<String>,
    /// Print what the run did as one JSON object on stdout (instead of the filter table).
    #[arg(long)]
    json: bool,
}

pub fn run_command(a: RunArgs) -> Result<()> {
    use gedisim::ops::collocate::CollocateOptions;
    let base = a.chain.run_options(a.als, a.l1b, a.l2a, &a.dataset)?;
    let opts = RunOptions {
        collocate: CollocateOptions {
            level: collocate_level(a.level),
            segment: a.segment,
            min_segment: a.min_segment,
            pulse: a.pulse.model("recorded", None),
            ..CollocateOptions::default()
        },
        rules: gedisim::kernels::study::select::StudyRules { max_days_apart: a.max_days_apart, ..Default::default() },
        engine: a.cluster.map(gedisim::ops::run::Engine::Cluster).unwrap_or_default(),
        ..base
    };
    let report = gedisim::ops::run::run_study(&opts, &Bars::new())?;
    if a.json {
        print_ingest_and_collocation(&report);
        println!("{}", report.json());
    } else {
        print_run(&report);
    }
    Ok(())
}

/// What the ingest and collocation of a run did (stderr).
pub fn print_ingest_and_collocation(r: &gedisim::ops::run::RunReport) {
    use gedisim::ops::ingest_als::TileOutcome;
    let c = r.counts();
    if !r.ingested.is_empty() {
        info!(
            "GEDI: {} granules ingested ({} shots), {} already ingested",
            c.granules_new, c.shots_ingested, c.granules_already
        );
    }
    if let Some(line) = &r.shots_kept {
        info!("     {line}");
    }
    if !r.tiles.is_empty() {
        info!(
            "ALS: {} tiles ingested ({} points), {} already ingested",
            c.tiles_new, c.points_ingested, c.tiles_already
        );
        let windows: Vec<_> = r
            .tiles
            .iter()
            .filter_map(|t| if let TileOutcome::Ingested { window: Some(w), .. } = t { Some(w) } else { None })
            .collect();
        if !windows.is_empty() {
            let sum = |f: fn(&&gedisim::ops::ingest_als::WindowRead) -> u64| windows.iter().map(f).sum::<u64>();
            info!(
                "     {} COPC tiles read only around the shots: {} new cells of {} m; {} of {} points decoded",
                windows.len(),
                sum(|w| w.cells_new as u64),
                gedisim::kernels::geo::cells::READ_CELL_M,
                sum(|w| w.copc.points_decoded),
                sum(|w| w.copc.points_in_tile),
            );
        }
    }
    for w in &r.warnings {
        warn!("{w}");
    }
    if let Some(s) = &r.strata {
        let mut counts: Vec<_> = s.counts.iter().collect();
        counts.sort();
        let counts: Vec<String> = counts.iter().map(|(k, v)| format!("{k} {v}")).collect();
        info!("strata: {} shots ({})", s.rows, counts.join(", "));
    }
    match &r.collocation {
        Some(c) => {
            let skipped: Vec<String> = c.skipped.iter().map(|(k, v)| format!("{k} {v}")).collect();
            let skipped =
                if skipped.is_empty() { String::new() } else { format!("; shots not used: {}", skipped.join(", ")) };
            info!(
                "collocation: {} granules, {} shots read, {} segments solved, {} runs too short{skipped} → {}",
                r.collocated.len(),
                c.shots,
                c.segments,
                c.short_runs.len(),
                c.table.display()
            );
        }
        None => info!("collocation: every granule already collocated"),
    }
    super::reporters::print_fetched(&r.als_inputs);
}

/// What a run did (stderr), then the filters and the results (stdout).
pub fn print_run(r: &gedisim::ops::run::RunReport) {
    use gedisim::kernels::study::select::Filter;
    print_ingest_and_collocation(r);
    let c = r.counts();
    if c.granules_simulated == 0 {
        let covered: usize = r.granules.iter().map(|g| g.covered).sum();
        if covered == 0 {
            info!("simulation: no shot footprint is covered by the ALS, nothing simulated");
        } else {
            info!("simulation: up to date, nothing simulated ({covered} covered shots)");
        }
    } else {
        let (ok, skipped) = c.simulated;
        info!(
            "simulation: {} shots of {} granules ({ok} simulated, {skipped} skipped by the simulator)",
            ok + skipped,
            c.granules_simulated
        );
    }
    let written = r.granules_processed();
    info!("results: {written} granules written, {} up to date", r.granules.len() - written);
    if r.nothing_new() {
        info!("nothing new since the last run: no ingest, collocation or simulation; results unchanged");
    }
    let t = &r.totals;
    println!(
        "Filters over the {} granules of the dataset (rows = shots × 3 weightings × 7 algorithms; a row counts \
        at the first filter it fails):",
        r.granules.len()
    );
    println!("  {:>10}  candidate rows ({} shots)", t.candidates, t.shots);
    for f in Filter::ALL {
        let mut line = format!("− {:>10}  {}", t.removed_by(f), f.describe(&r.rules));
        if f == Filter::AcquisitionWindow && t.window_unknown > 0 {
            line += &format!(" (not applied to {} rows: no ALS date or shot date)", t.window_unknown);
        }
        println!("{line}");
    }
    println!("= {:>10}  rows kept ({} shots) → {}", t.kept, t.shots_kept, r.dataset.join("results").display());
}
