//! The `gedisim` command line: parses arguments, calls the library, shows progress.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};

use gedisim::dataset::Dataset;
use gedisim::ingest::als::{self, AlsOptions, TileOutcome};
use gedisim::{Error, Result};

#[derive(Parser)]
#[command(name = "gedisim", version, about = "Simulate GEDI waveforms from ALS, process them like GEDI L2A, and diagnose the sim-to-real gap")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Ingest ALS tiles or GEDI granules into a dataset's Parquet tables.
    #[command(subcommand)]
    Ingest(IngestCommand),
    /// Simulate GEDI waveforms from ALS: direct mode (--als, --footprints, --out) or dataset mode (--dataset).
    Simulate(SimulateArgs),
    /// Geolocation offsets (dx, dy, dz) of the shots against the ALS → <dataset>/offsets/.
    Collocate(CollocateArgs),
    /// GEDI L2A processing (algorithms a1–a6) of the waveforms of an L1B file.
    L2a(L2aArgs),
    /// Run SQL over a dataset's tables (with gedisim's functions).
    Sql(SqlArgs),
    /// The study's tables (queries/*.sql over results/), figures and report.html → <dataset>/report/.
    Report(ReportArgs),
    /// Hand a table off in another format.
    #[command(subcommand)]
    Export(ExportCommand),
    /// The study end to end: ingest → collocate → simulate → filters → <dataset>/results/
    /// (only new granules are processed on a re-run).
    Run(RunArgs),
    /// The whole study on the bundled LiDAR HD tiles with generated GEDI granules: scenario,
    /// run, report; prints the headline tables and the path of report.html.
    Demo(DemoArgs),
    /// Build a test world: real ALS tiles + pseudo-real GEDI L1B/L2A granules with one withheld
    /// effect, and truth.json (docs/scenario.md).
    Scenario(ScenarioArgs),
    /// Where the sim-to-real gap lies, which unmodelled effect causes it and how far it shrinks
    /// once modelled (held-out tracks) → <out>/diagnosis.json, tables, figures (docs/diagnosis.md).
    Diagnose(DiagnoseArgs),
    /// Measurements used by the benchmarks.
    #[command(subcommand, hide = true)]
    Bench(BenchCommand),
}

#[derive(Subcommand)]
enum IngestCommand {
    /// LAS/LAZ files or folders → <dataset>/als/ and <dataset>/tiles/.
    Als(IngestAlsArgs),
    /// GEDI L1B and/or L2A granules (V1 or V2) → <dataset>/shots/ and <dataset>/granules/.
    Gedi(IngestGediArgs),
    /// Forest type of every shot from a Corine Land Cover GeoTIFF (EPSG:3035) or a CSV
    /// `shot_number,forest_type` → <dataset>/strata/.
    Strata(IngestStrataArgs),
}

#[derive(Args)]
struct IngestStrataArgs {
    /// Corine Land Cover GeoTIFF in EPSG:3035 (.tif), or a CSV with columns shot_number, forest_type (.csv).
    #[arg(long)]
    landcover: PathBuf,
    /// Dataset directory (with a shots table for a raster).
    #[arg(long)]
    dataset: PathBuf,
}

#[derive(Args)]
struct IngestGediArgs {
    /// L1B files or folders holding them.
    #[arg(long, num_args = 1..)]
    l1b: Vec<PathBuf>,
    /// L2A files or folders holding them.
    #[arg(long, num_args = 1..)]
    l2a: Vec<PathBuf>,
    /// Dataset directory (created if needed).
    #[arg(long)]
    out: PathBuf,
    /// Projected CRS of the shots' x, y (default: the dataset's ALS CRS, else 2154).
    #[arg(long)]
    epsg: Option<u32>,
    /// Geoid offset N (m, ellipsoid − orthometric) for every shot, instead of each shot's L1B geoid.
    #[arg(long, allow_hyphen_values = true)]
    geoid_offset: Option<f64>,
    /// Fail when a shot of a paired granule is in only one of L1B and L2A (default: keep it, warn).
    #[arg(long)]
    strict_join: bool,
}

#[derive(Args)]
struct IngestAlsArgs {
    /// LAS/LAZ files, or folders holding them.
    #[arg(required = true)]
    inputs: Vec<PathBuf>,
    /// Dataset directory (created if needed).
    #[arg(long)]
    out: PathBuf,
    /// Keep noise (7, 18) and IGN artefact/virtual classes (64–67).
    #[arg(long)]
    keep_all_classes: bool,
    /// EPSG code of tiles that carry no CRS record.
    #[arg(long)]
    epsg: Option<u32>,
    /// Print wall time, points/s and peak memory at the end.
    #[arg(long)]
    stats: bool,
}

#[derive(Args)]
struct SimulateArgs {
    /// LAS/LAZ file (direct mode).
    #[arg(long, requires_all = ["footprints", "out"], conflicts_with = "dataset")]
    als: Option<PathBuf>,
    /// CSV with a header naming id, x, y (direct mode; in dataset mode, footprints to simulate
    /// instead of the ingested shots, e.g. inventory plots).
    #[arg(long)]
    footprints: Option<PathBuf>,
    /// Output Parquet file (direct mode; dataset mode with --footprints, default
    /// <dataset>/sim/<CSV name>.parquet).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Dataset directory: simulate every ingested shot into <dataset>/sim/shots.parquet (or the
    /// --footprints) from the ingested ALS points.
    #[arg(long)]
    dataset: Option<PathBuf>,
    /// gedirat reproduces Hancock's gediRat exactly (batch-dependent bin grid, every point of
    /// every class); default fixes its slips.
    #[arg(long, value_enum, default_value = "default")]
    profile: ProfileArg,
    /// Pulse: `gaussian` (FWHM 15 ns unless --psigma) or a two-column pulse file (range m, amplitude).
    #[arg(long, default_value = "gaussian")]
    pulse: String,
    /// Turn off ALS density normalisation.
    #[arg(long)]
    no_norm: bool,
    /// Footprint Gaussian σ (m).
    #[arg(long, default_value_t = 5.5)]
    fsigma: f32,
    /// Gaussian pulse σ (m) instead of the 15 ns FWHM.
    #[arg(long)]
    psigma: Option<f32>,
    /// Convolve each return with the pulse while binning instead of after.
    #[arg(long)]
    pulse_before: bool,
    /// Direct mode with the default profile: keep the classes that ingest drops (7, 18, 64–67).
    #[arg(long)]
    keep_all_classes: bool,
    /// Print wall time, waveforms/s and peak memory at the end.
    #[arg(long)]
    stats: bool,
}

#[derive(Args)]
struct CollocateArgs {
    /// Dataset directory with ingested shots (with L1B waveforms) and ALS.
    #[arg(long)]
    dataset: PathBuf,
    /// beam: each beam cut into segments; track: all beams of a granule share an offset per
    /// along-track segment; shot: one offset per shot from it and its neighbours.
    #[arg(long, value_enum, default_value = "beam")]
    level: LevelArg,
    /// Longest segment: shots (beam level) or along-track shot steps (track level).
    #[arg(long, default_value_t = 40)]
    segment: usize,
    /// Largest horizontal shift searched (m).
    #[arg(long, default_value_t = 10.0)]
    max_shift: f64,
    /// Horizontal grid step (m).
    #[arg(long, default_value_t = 1.0)]
    step: f64,
    /// Fewest shots of a segment: shorter runs are reported and not solved (1: solve every run).
    #[arg(long, default_value_t = gedisim::collocate::segments::MIN_SEGMENT)]
    min_segment: usize,
    /// Print wall time and peak memory at the end.
    #[arg(long)]
    stats: bool,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum LevelArg {
    Beam,
    Track,
    Shot,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum ProfileArg {
    Gedirat,
    Default,
}

#[derive(Args)]
struct L2aArgs {
    /// GEDI L1B file (V1 or V2).
    #[arg(long)]
    l1b: PathBuf,
    /// Output Parquet file: one row per shot × algorithm.
    #[arg(long)]
    out: PathBuf,
    /// Algorithms to run, e.g. 1,3.
    #[arg(long, value_delimiter = ',', default_value = "1,2,3,4,5,6")]
    algorithms: Vec<u8>,
}

#[derive(Args)]
struct SqlArgs {
    /// Dataset directory.
    #[arg(long)]
    dataset: PathBuf,
    /// The SQL statement (or use -f).
    query: Option<String>,
    /// File holding the SQL statement.
    #[arg(short = 'f', long = "file")]
    file: Option<PathBuf>,
    /// Write the result to this Parquet or CSV file instead of printing it.
    #[arg(long)]
    out: Option<PathBuf>,
}

#[derive(Args)]
struct ReportArgs {
    /// Dataset directory (with a results table).
    #[arg(long)]
    dataset: PathBuf,
    /// Output directory (default <dataset>/report).
    #[arg(long)]
    out: Option<PathBuf>,
}

#[derive(Subcommand)]
enum ExportCommand {
    /// A table (shots or results) as GeoParquet 1.1: WKB point geometry (lon, lat; OGC:CRS84) and a bbox covering column.
    Geoparquet(ExportGeoArgs),
}

#[derive(Args)]
struct ExportGeoArgs {
    /// Dataset directory.
    #[arg(long)]
    dataset: PathBuf,
    /// Table to export: shots or results.
    #[arg(long)]
    table: String,
    /// Output file (.parquet).
    #[arg(long)]
    out: PathBuf,
}

/// Options of the ingest chain shared by `run` and `diagnose --als`.
#[derive(Args)]
struct ChainArgs {
    /// Corine Land Cover GeoTIFF (EPSG:3035) or CSV shot_number,forest_type: forest type of every shot.
    #[arg(long)]
    landcover: Option<PathBuf>,
    /// Projected CRS (default: the dataset's ALS CRS, else 2154).
    #[arg(long)]
    epsg: Option<u32>,
    /// Geoid offset N (m, ellipsoid − orthometric) for every shot, instead of each shot's L1B geoid.
    #[arg(long, allow_hyphen_values = true)]
    geoid_offset: Option<f64>,
}

#[derive(Args)]
struct RunArgs {
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
    #[arg(long)]
    out: PathBuf,
    /// Keep shots at most this many days before the start or after the end of the ALS acquisition
    /// of their footprint (not applied where the tiles carry no date).
    #[arg(long, allow_hyphen_values = true, default_value_t = gedisim::study::select::DEFAULT_MAX_DAYS_APART)]
    max_days_apart: f64,
    /// Collocation level of new granules (see `collocate`).
    #[arg(long, value_enum, default_value = "beam")]
    level: LevelArg,
    /// Longest collocation segment (see `collocate`).
    #[arg(long, default_value_t = 40)]
    segment: usize,
    /// Fewest shots of a collocation segment (see `collocate`; 1: solve every run).
    #[arg(long, default_value_t = gedisim::collocate::segments::MIN_SEGMENT)]
    min_segment: usize,
}

#[derive(Args)]
struct DemoArgs {
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

#[derive(Args)]
struct ScenarioArgs {
    /// Withheld effect: none, geolocation, datum, weighting, pulse, footprint, noise,
    /// canopy_change, occlusion, ground_detection, or a pair such as datum+pulse.
    #[arg(long)]
    effect: String,
    /// Scale of the main parameter's departure from nominal (1 = the realistic default).
    #[arg(long, allow_hyphen_values = true)]
    magnitude: Option<f64>,
    /// Effect parameter as key=value (repeatable), e.g. --param dz_m=0.8; effect.key for a pair.
    #[arg(long = "param", value_name = "KEY=VALUE")]
    params: Vec<String>,
    /// Seed of every random draw (same seed, same granules).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// LAS/LAZ files or folders (default: the bundled tests/data/als tiles).
    #[arg(long, num_args = 1..)]
    als: Vec<PathBuf>,
    /// Output folder: als/, gedi/, truth.json.
    #[arg(long)]
    out: PathBuf,
    /// Granules (passes, eight beams each) crossing each tile.
    #[arg(long, default_value_t = 8)]
    passes: usize,
    /// Nominal geoid height N (m) stored in geophys_corr/geoid.
    #[arg(long, allow_hyphen_values = true, default_value_t = gedisim::scenario_io::DEFAULT_GEOID_M)]
    geoid: f64,
    /// RMS per axis of the random horizontal offset of each track (m).
    #[arg(long, default_value_t = 3.0)]
    offset_sigma: f64,
    /// CRS of tiles that carry none.
    #[arg(long, default_value_t = 2154)]
    epsg: u32,
    /// Replace a world already in --out.
    #[arg(long)]
    force: bool,
}

#[derive(Subcommand)]
enum BenchCommand {
    /// Decode a LAS/LAZ file with the las crate alone (the baseline of the ingest benchmark).
    Decode {
        file: PathBuf,
    },
}

fn main() -> ExitCode {
    // gedisim only reads granules (and writes new ones nobody else has open): HDF5's advisory file
    // locks add nothing, and they fail on NFS/Lustre or when another process inherited the file's
    // descriptor. Set before any thread or HDF5 call exists; the user's own setting wins.
    if std::env::var_os("HDF5_USE_FILE_LOCKING").is_none() {
        std::env::set_var("HDF5_USE_FILE_LOCKING", "FALSE");
    }
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", gedisim::error::one_line(&e.to_string()));
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Ingest(IngestCommand::Als(a)) => ingest_als(a),
        Command::Ingest(IngestCommand::Gedi(a)) => ingest_gedi(a),
        Command::Ingest(IngestCommand::Strata(a)) => ingest_strata(a),
        Command::Simulate(a) => simulate(a),
        Command::Collocate(a) => collocate(a),
        Command::L2a(a) => l2a(a),
        Command::Sql(a) => sql(a),
        Command::Report(a) => report(a),
        Command::Export(ExportCommand::Geoparquet(a)) => export_geoparquet(a),
        Command::Run(a) => run_command(a),
        Command::Demo(a) => demo(a),
        Command::Scenario(a) => scenario(a),
        Command::Diagnose(a) => diagnose(a),
        Command::Bench(BenchCommand::Decode { file }) => bench_decode(file),
    }
}

fn ingest_als(a: IngestAlsArgs) -> Result<()> {
    let start = Instant::now();
    let files = als::expand_inputs(&a.inputs)?;
    if files.is_empty() {
        return Err(Error::Usage("no LAS/LAZ file found in the inputs".into()));
    }
    let mut total = 0u64;
    for f in &files {
        total += gedisim::ingest::las::TileReader::open(f)?.header().number_of_points;
    }
    let ds = Dataset::create(&a.out)?;
    let bar = progress(total, "points");
    let opts = AlsOptions { keep_all_classes: a.keep_all_classes, epsg: a.epsg };
    let outcomes = als::ingest_tiles(&ds, &files, &opts, &|n| bar.inc(n));
    bar.finish_and_clear();
    let outcomes = outcomes?;
    let mut written = 0;
    for o in &outcomes {
        match o {
            TileOutcome::Ingested { tile, points, dropped } => {
                written += points;
                eprintln!("{tile}: {points} points ({dropped} dropped by class)");
            }
            TileOutcome::AlreadyIngested { tile } => eprintln!("{tile}: already ingested (same content), skipped"),
        }
    }
    if a.stats {
        let s = start.elapsed().as_secs_f64();
        println!(
            "ingest: {} files, {total} points read, {written} written, {s:.2} s, {:.0} points/s, peak RSS {:.1} MB",
            files.len(),
            total as f64 / s,
            peak_rss_mb()
        );
    }
    Ok(())
}

fn ingest_gedi(a: IngestGediArgs) -> Result<()> {
    use gedisim::ingest::gedi::{self, GediOptions, GranuleOutcome};
    if a.l1b.is_empty() && a.l2a.is_empty() {
        return Err(Error::Usage("give --l1b and/or --l2a files".into()));
    }
    let l1b = gedi::expand_granule_inputs(&a.l1b, "GEDI01_B")?;
    let l2a = gedi::expand_granule_inputs(&a.l2a, "GEDI02_A")?;
    let ds = Dataset::create(&a.out)?;
    let epsg = match a.epsg {
        Some(e) => e,
        None => als::dataset_epsg(&ds)?.unwrap_or(2154),
    };
    let opts = GediOptions { epsg, geoid_offset: a.geoid_offset, strict_join: a.strict_join };
    let n = gedi::pair_granules(&l1b, &l2a)?.0.len() as u64;
    let bar = progress(n, "granules");
    let result = gedi::ingest_into_dataset(&ds, &l1b, &l2a, &opts, &|| bar.inc(1));
    bar.finish_and_clear();
    let (outcomes, report) = result?;
    for w in report.warnings() {
        eprintln!("warning: {w}");
    }
    for o in outcomes {
        match o {
            GranuleOutcome::Ingested { granule, shots } => eprintln!("{granule}: {shots} shots"),
            GranuleOutcome::AlreadyIngested { granule } => eprintln!("{granule}: already ingested (same content), skipped"),
        }
    }
    Ok(())
}

fn ingest_strata(a: IngestStrataArgs) -> Result<()> {
    let ds = Dataset::open(&a.dataset)?;
    let bar = progress(0, "shots");
    let report = gedisim::ingest::strata::ingest_strata(&ds, &a.landcover, &|n, total| {
        bar.set_length(total);
        bar.inc(n);
    });
    bar.finish_and_clear();
    let report = report?;
    let mut counts: Vec<_> = report.counts.iter().collect();
    counts.sort();
    let counts: Vec<String> = counts.iter().map(|(k, v)| format!("{k} {v}")).collect();
    eprintln!("{} shots → {} ({})", report.rows, report.path.display(), counts.join(", "));
    if report.outside > 0 || report.no_position > 0 {
        eprintln!("{} shots outside the raster and {} without a position: forest type `unknown`", report.outside, report.no_position);
    }
    if report.not_in_dataset > 0 {
        eprintln!("warning: {} CSV rows name shots that are not in the dataset's shots table", report.not_in_dataset);
    }
    Ok(())
}

fn simulate(a: SimulateArgs) -> Result<()> {
    use gedisim::sim::{self, Profile, PulseTiming, SimConfig};
    let profile = match a.profile {
        ProfileArg::Gedirat => Profile::Gedirat,
        ProfileArg::Default => Profile::Default,
    };
    let mut cfg = SimConfig::new(profile);
    cfg.fsigma = a.fsigma;
    cfg.normalise_density = !a.no_norm;
    if a.pulse_before {
        cfg.pulse_timing = PulseTiming::BeforeBinning;
    }
    cfg.pulse = match (a.pulse.as_str(), a.psigma) {
        ("gaussian", Some(s)) => sim::Pulse::gaussian(s, cfg.res as f32)?,
        ("gaussian", None) => cfg.pulse,
        (file, _) => {
            let path = PathBuf::from(file);
            let text = std::fs::read_to_string(&path).map_err(|e| Error::file(&path, format!("cannot read pulse file: {e}")))?;
            let pairs = sim::pulse::parse_pulse_text(&text).map_err(|e| Error::field(&path, "pulse", e))?;
            sim::Pulse::tabulated(&pairs).map_err(|e| Error::field(&path, "pulse", e))?
        }
    };
    let start = Instant::now();
    let (ok, skipped, out) = if let Some(dir) = a.dataset {
        let ds = Dataset::open(&dir)?;
        let (footprints, dest) = match &a.footprints {
            Some(csv) => {
                let stem = csv.file_stem().and_then(|s| s.to_str()).unwrap_or("footprints");
                let dest = match &a.out {
                    Some(out) => out.clone(),
                    None => ds.table_file(gedisim::dataset::tables::SIM, stem)?,
                };
                (gedisim::ingest::footprints::read_footprints_csv(csv)?.into_iter().map(|f| (f, None)).collect(), dest)
            }
            None if a.out.is_some() => return Err(Error::Usage("--out in dataset mode needs --footprints".into())),
            None => (gedisim::simulate::shot_footprints(&ds)?, ds.table_file(gedisim::dataset::tables::SIM, "shots")?),
        };
        let bar = progress(footprints.len() as u64, "footprints");
        let r = gedisim::simulate::simulate_on_dataset(&ds, footprints, &cfg, profile, &dest, &|k| bar.inc(k as u64));
        bar.finish_and_clear();
        let (ok, skipped) = r?;
        (ok, skipped, dest)
    } else {
        let (Some(als_path), Some(fp_path), Some(out)) = (a.als, a.footprints, a.out) else {
            return Err(Error::Usage("give --als, --footprints and --out (direct mode) or --dataset".into()));
        };
        let footprints = gedisim::ingest::footprints::read_footprints_csv(&fp_path)?;
        let mut points = gedisim::ingest::las::read_points(&als_path)?;
        if profile == Profile::Default && !a.keep_all_classes {
            points = gedisim::simulate::drop_ingest_classes(&points);
        }
        let (ok, skipped) = gedisim::simulate::simulate_direct(&points, &footprints, &cfg, profile, &out)?;
        (ok, skipped, out)
    };
    eprintln!("{ok} footprints simulated, {skipped} skipped (see the status column) → {}", out.display());
    if a.stats {
        let s = start.elapsed().as_secs_f64();
        println!(
            "simulate: {} footprints × {} weightings, {s:.3} s, {:.1} footprints/s, peak RSS {:.1} MB",
            ok + skipped,
            gedisim::sim::N_WEIGHTINGS,
            (ok + skipped) as f64 / s,
            peak_rss_mb()
        );
    }
    Ok(())
}

fn collocate(a: CollocateArgs) -> Result<()> {
    use gedisim::collocation::{CollocateOptions, Collocation};
    let start = Instant::now();
    let level = collocate_level(a.level);
    let ds = Dataset::open(&a.dataset)?;
    let opts = CollocateOptions { level, segment: a.segment, max_shift: a.max_shift, step: a.step, min_segment: a.min_segment };
    let plan = Collocation::plan(&ds, &opts)?;
    let bar = progress(plan.shots_to_process() as u64, "shots");
    let result = plan.run(&|| bar.inc(1));
    bar.finish_and_clear();
    let report = result?;
    for s in &report.short_runs {
        eprintln!("too short, not collocated: {s}");
    }
    let skipped: Vec<String> = report.skipped.iter().map(|(k, v)| format!("{k} {v}")).collect();
    if !skipped.is_empty() {
        eprintln!("shots not used: {}", skipped.join(", "));
    }
    eprintln!("{} shots read, {} {} offsets → {}", report.shots, report.segments, level.name(), report.table.display());
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

fn l2a(a: L2aArgs) -> Result<()> {
    use gedisim::process::l2a::AlgorithmSettings;
    let settings = a
        .algorithms
        .iter()
        .map(|&n| AlgorithmSettings::gedi(n).ok_or_else(|| Error::Usage(format!("--algorithms: {n} is not a GEDI algorithm (1..6)"))))
        .collect::<Result<Vec<_>>>()?;
    let opts = gedisim::ingest::gedi::GediOptions::default();
    let schema = gedisim::tables::l2a::l2a_schema();
    let props = gedisim::dataset::writer_properties(&Default::default(), 1 << 16);
    let mut writer = gedisim::dataset::AtomicParquet::create(&a.out, schema, props)?;
    let mut rows = 0;
    let report = gedisim::ingest::gedi::ingest_gedi(std::slice::from_ref(&a.l1b), &[], &opts, |shots| {
        let batch = gedisim::tables::l2a::l2a_batch(&shots, &settings, &a.l1b)?;
        rows += batch.num_rows();
        writer.write(&batch)
    })?;
    writer.finish()?;
    eprintln!("{} shots × {} algorithms → {rows} rows in {}", report.rows(), settings.len(), a.out.display());
    Ok(())
}

fn sql(a: SqlArgs) -> Result<()> {
    let query = match (a.query, a.file) {
        (Some(q), None) => q,
        (None, Some(f)) => std::fs::read_to_string(&f).map_err(|e| Error::file(&f, e))?,
        _ => return Err(Error::Usage("give either a SQL statement or -f <file>".into())),
    };
    let ds = Dataset::open(&a.dataset)?;
    let rt = tokio::runtime::Runtime::new().map_err(|e| Error::Usage(e.to_string()))?;
    rt.block_on(async move {
        let ctx = gedisim::sql::session(&ds).await?;
        let df = ctx.sql(&query).await.map_err(|e| Error::Usage(format!("SQL: {e}")))?;
        let batches = df.collect().await.map_err(|e| Error::Usage(format!("SQL: {e}")))?;
        match a.out {
            None => {
                let table = arrow::util::pretty::pretty_format_batches(&batches).map_err(|e| Error::Usage(e.to_string()))?;
                println!("{table}");
            }
            Some(out) => gedisim::dataset::write_result(&out, &batches)?,
        }
        Ok(())
    })
}

fn report(a: ReportArgs) -> Result<()> {
    let ds = Dataset::open(&a.dataset)?;
    let bar = ProgressBar::new_spinner();
    let s = gedisim::report::run_report(&ds, a.out.as_deref(), &|step| bar.set_message(step.to_string()));
    bar.finish_and_clear();
    let s = s?;
    for (name, rows) in &s.tables {
        eprintln!("{name}: {rows} rows");
    }
    for (name, missing) in &s.skipped {
        eprintln!("{name}: skipped (no {} table)", missing.join(", "));
    }
    for note in &s.figure_notes {
        eprintln!("figure not drawn: {note}");
    }
    eprintln!(
        "{} tables, {} figures (PNG + SVG), {} GeoParquet files → {}",
        s.tables.len(),
        s.figures.len() / 2,
        s.geoparquet.len(),
        s.html.display()
    );
    Ok(())
}

fn collocate_level(l: LevelArg) -> gedisim::collocate::segments::Level {
    use gedisim::collocate::segments::Level;
    match l {
        LevelArg::Beam => Level::Beam,
        LevelArg::Track => Level::Track,
        LevelArg::Shot => Level::Shot,
    }
}

/// Progress of `run` and `demo`: one indicatif bar per step.
struct Bars(std::sync::Mutex<Option<ProgressBar>>);

impl Bars {
    fn new() -> Self {
        Bars(std::sync::Mutex::new(None))
    }
}

impl gedisim::run::Progress for Bars {
    fn start(&self, step: gedisim::run::Step, total: u64) {
        let bar = if step.unit().is_empty() {
            let b = ProgressBar::new_spinner();
            b.set_message(step.label());
            b.enable_steady_tick(std::time::Duration::from_millis(200));
            b
        } else {
            let b = ProgressBar::new(total);
            b.set_style(
                ProgressStyle::with_template(&format!(
                    "{{prefix:>11}} {{elapsed_precise}} [{{bar:40}}] {{human_pos}}/{{human_len}} {} ({{per_sec}}, eta {{eta}})",
                    step.unit()
                ))
                .expect("valid template")
                .progress_chars("=> "),
            );
            b.set_prefix(step.label());
            b
        };
        if let Some(old) = self.0.lock().expect("progress lock").replace(bar) {
            old.finish_and_clear();
        }
    }

    fn set_total(&self, total: u64) {
        if let Some(b) = self.0.lock().expect("progress lock").as_ref() {
            b.set_length(total);
        }
    }

    fn advance(&self, n: u64) {
        if let Some(b) = self.0.lock().expect("progress lock").as_ref() {
            b.inc(n);
        }
    }

    fn finish(&self) {
        if let Some(b) = self.0.lock().expect("progress lock").take() {
            b.finish_and_clear();
        }
    }
}

fn run_command(a: RunArgs) -> Result<()> {
    use gedisim::collocation::CollocateOptions;
    use gedisim::run::RunOptions;
    let opts = RunOptions {
        als: a.als,
        l1b: a.l1b,
        l2a: a.l2a,
        landcover: a.chain.landcover,
        epsg: a.chain.epsg,
        geoid_offset: a.chain.geoid_offset,
        collocate: CollocateOptions {
            level: collocate_level(a.level),
            segment: a.segment,
            min_segment: a.min_segment,
            ..CollocateOptions::default()
        },
        rules: gedisim::study::select::StudyRules { max_days_apart: a.max_days_apart, ..Default::default() },
        ..RunOptions::new(&a.out)
    };
    let report = gedisim::run::run_study(&opts, &Bars::new())?;
    print_run(&report);
    Ok(())
}

/// What the ingest and collocation of a run did (stderr).
fn print_ingest_and_collocation(r: &gedisim::run::RunReport) {
    use gedisim::ingest::als::TileOutcome;
    use gedisim::ingest::gedi::GranuleOutcome;
    if !r.tiles.is_empty() {
        let new: Vec<u64> = r.tiles.iter().filter_map(|t| if let TileOutcome::Ingested { points, .. } = t { Some(*points) } else { None }).collect();
        eprintln!("ALS: {} tiles ingested ({} points), {} already ingested", new.len(), new.iter().sum::<u64>(), r.tiles.len() - new.len());
    }
    if !r.ingested.is_empty() {
        let new: Vec<usize> = r.ingested.iter().filter_map(|g| if let GranuleOutcome::Ingested { shots, .. } = g { Some(*shots) } else { None }).collect();
        eprintln!("GEDI: {} granules ingested ({} shots), {} already ingested", new.len(), new.iter().sum::<usize>(), r.ingested.len() - new.len());
    }
    for w in &r.warnings {
        eprintln!("warning: {w}");
    }
    if let Some(s) = &r.strata {
        let mut counts: Vec<_> = s.counts.iter().collect();
        counts.sort();
        let counts: Vec<String> = counts.iter().map(|(k, v)| format!("{k} {v}")).collect();
        eprintln!("strata: {} shots ({})", s.rows, counts.join(", "));
    }
    match &r.collocation {
        Some(c) => {
            let skipped: Vec<String> = c.skipped.iter().map(|(k, v)| format!("{k} {v}")).collect();
            let skipped = if skipped.is_empty() { String::new() } else { format!("; shots not used: {}", skipped.join(", ")) };
            eprintln!(
                "collocation: {} granules, {} shots read, {} segments solved, {} runs too short{skipped} → {}",
                r.collocated.len(),
                c.shots,
                c.segments,
                c.short_runs.len(),
                c.table.display()
            );
        }
        None => eprintln!("collocation: every granule already collocated"),
    }
}

/// What a run did (stderr), then the filters and the results (stdout).
fn print_run(r: &gedisim::run::RunReport) {
    use gedisim::study::select::Filter;
    print_ingest_and_collocation(r);
    let simulated: Vec<&gedisim::run::GranuleRun> = r.granules.iter().filter(|g| g.simulated.is_some()).collect();
    if simulated.is_empty() {
        let covered: usize = r.granules.iter().map(|g| g.covered).sum();
        if covered == 0 {
            eprintln!("simulation: no shot footprint is covered by the ALS, nothing simulated");
        } else {
            eprintln!("simulation: up to date, nothing simulated ({covered} covered shots)");
        }
    } else {
        let (ok, skipped) = simulated.iter().filter_map(|g| g.simulated).fold((0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
        eprintln!("simulation: {} shots of {} granules ({ok} simulated, {skipped} skipped by the simulator)", ok + skipped, simulated.len());
    }
    let written = r.granules_processed();
    eprintln!("results: {written} granules written, {} up to date", r.granules.len() - written);
    if r.nothing_new() {
        eprintln!("nothing new since the last run: no ingest, collocation or simulation; results unchanged");
    }
    let t = &r.totals;
    println!("Filters over the {} granules of the dataset (rows = shots × 3 weightings × 7 algorithms; a row counts at the first filter it fails):", r.granules.len());
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

fn demo(a: DemoArgs) -> Result<()> {
    let start = Instant::now();
    let opts = gedisim::demo::DemoOptions { out: a.out.clone(), effect: a.effect, seed: a.seed, passes: a.passes, force: a.force };
    let bars = Bars::new();
    let spinner = std::sync::Mutex::new(None::<ProgressBar>);
    let d = gedisim::demo::run_demo(&opts, &bars, &|step| {
        let mut s = spinner.lock().expect("spinner lock");
        let b = s.get_or_insert_with(|| {
            let b = ProgressBar::new_spinner();
            b.enable_steady_tick(std::time::Duration::from_millis(200));
            b
        });
        b.set_message(format!("report: {step}"));
    });
    if let Some(b) = spinner.lock().expect("spinner lock").take() {
        b.finish_and_clear();
    }
    let d = d?;
    match &d.world {
        Some(w) => eprintln!("world: {} tiles, {} granules, {} shots, effect {} → {}", w.tiles, w.granules, w.shots, opts.effect, d.world_dir.display()),
        None => eprintln!("world: reusing {} (effect {}, seed {})", d.world_dir.display(), opts.effect, opts.seed),
    }
    print_run(&d.run);
    for (name, missing) in &d.report.skipped {
        eprintln!("report: {name} skipped (no {} table)", missing.join(", "));
    }
    println!();
    print!("{}", d.headline.ground_table());
    println!();
    print!("{}", d.headline.msd_table());
    println!();
    println!("report: {}", d.report.html.display());
    // The diagnosis of the world, told nothing about the withheld effect.
    let ds = Dataset::open(&d.run.dataset)?;
    let dir = a.out.join("diagnosis");
    let bar = progress(0, "shots");
    let fitting = ProgressBar::new_spinner();
    let diagnosis = gedisim::diagnosis::diagnose_dataset(&ds, &dir, &[], &|| bar.inc(1), &|step| {
        bar.finish_and_clear();
        fitting.set_message(format!("diagnosis: fitting and scoring {step}"));
        fitting.tick();
    });
    bar.finish_and_clear();
    fitting.finish_and_clear();
    let diagnosis = diagnosis?;
    println!();
    println!("Diagnosis (the withheld effect is not told; truth: {}):", d.world_dir.join("truth.json").display());
    for line in gedisim::diagnosis::summary_lines(&diagnosis.diagnosis) {
        println!("  {line}");
    }
    println!("diagnosis: {}", dir.join("diagnosis.json").display());
    eprintln!("demo finished in {:.0} s", start.elapsed().as_secs_f64());
    Ok(())
}

fn scenario(a: ScenarioArgs) -> Result<()> {
    let params = a
        .params
        .iter()
        .map(|p| {
            p.split_once('=')
                .map(|(k, v)| (k.trim().to_string(), v.trim().to_string()))
                .ok_or_else(|| Error::Usage(format!("--param {p}: expected key=value")))
        })
        .collect::<Result<Vec<_>>>()?;
    let effects = gedisim::scenario::EffectSet::parse(&a.effect, a.magnitude, &params).map_err(|e| Error::Usage(e.to_string()))?;
    let inputs = if a.als.is_empty() {
        vec![PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/als")]
    } else {
        a.als.clone()
    };
    let tiles = als::expand_inputs(&inputs)?;
    let opts = gedisim::scenario_io::ScenarioOptions {
        effect_spec: a.effect.clone(),
        effects,
        magnitude: a.magnitude,
        params,
        seed: a.seed,
        tiles,
        out: a.out.clone(),
        passes_per_tile: a.passes,
        geoid_m: a.geoid,
        track_offset_sigma_m: a.offset_sigma,
        default_epsg: a.epsg,
        force: a.force,
    };
    let r = gedisim::scenario_io::make_scenario(&opts)?;
    eprintln!(
        "scenario {}: {} tiles, {} granules, {} tracks, {} shots ({} dropped) → {}",
        a.effect,
        r.tiles,
        r.granules,
        r.tracks,
        r.shots,
        r.dropped,
        r.truth.display()
    );
    Ok(())
}

fn export_geoparquet(a: ExportGeoArgs) -> Result<()> {
    let ds = Dataset::open(&a.dataset)?;
    let rt = tokio::runtime::Runtime::new().map_err(|e| Error::Usage(e.to_string()))?;
    let rows = rt.block_on(gedisim::report::geoparquet::export(&ds, &a.table, &a.out, gedisim::report::geoparquet::GeoCrs::Wgs84))?;
    eprintln!("{rows} rows → {}", a.out.display());
    Ok(())
}

fn bench_decode(file: PathBuf) -> Result<()> {
    let start = Instant::now();
    let mut reader = las::Reader::from_path(&file).map_err(|e| Error::file(&file, e))?;
    let mut pd = las::PointDataBuilder::new().for_header(reader.header()).build();
    let mut n = 0u64;
    let mut checksum = 0f64;
    loop {
        let got = reader.fill_points(1 << 20, &mut pd).map_err(|e| Error::file(&file, e))?;
        if got == 0 {
            break;
        }
        n += got;
        // Touch the coordinates so that the decode cannot be skipped.
        checksum += pd.z().sum::<f64>();
    }
    let s = start.elapsed().as_secs_f64();
    println!("decode: {n} points, {s:.2} s, {:.0} points/s, peak RSS {:.1} MB (checksum {checksum:.1})", n as f64 / s, peak_rss_mb());
    Ok(())
}

fn progress(total: u64, unit: &str) -> ProgressBar {
    let bar = ProgressBar::new(total);
    bar.set_style(
        ProgressStyle::with_template(&format!("{{elapsed_precise}} [{{bar:40}}] {{human_pos}}/{{human_len}} {unit} ({{per_sec}}, eta {{eta}})"))
            .expect("valid template")
            .progress_chars("=> "),
    );
    bar
}

/// User + system CPU time of this process, all threads (s); 0 where /proc is unavailable.
/// `/proc/self/stat` counts in USER_HZ, which Linux fixes at 100 for this interface.
fn cpu_seconds() -> f64 {
    std::fs::read_to_string("/proc/self/stat")
        .ok()
        .and_then(|s| {
            // Fields after the parenthesised command name; utime and stime are fields 14 and 15.
            let rest = s.rsplit_once(')')?.1;
            let f: Vec<&str> = rest.split_whitespace().collect();
            Some((f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?) / 100.0)
        })
        .unwrap_or(0.0)
}

/// Peak resident memory of this process (VmHWM), MB; 0 where /proc is unavailable.
fn peak_rss_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| s.lines().find(|l| l.starts_with("VmHWM:")).and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok()))
        .map(|kb| kb / 1024.0)
        .unwrap_or(0.0)
}

#[derive(Args)]
struct DiagnoseArgs {
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
}

/// Collocation of a dataset the diagnosis makes: per track (the baseline's horizontal collocation),
/// every run solved however short.
const DIAGNOSIS_COLLOCATION: gedisim::collocation::CollocateOptions =
    gedisim::collocation::CollocateOptions { level: gedisim::collocate::segments::Level::Beam, segment: 40, max_shift: 10.0, step: 1.0, min_segment: 1 };

fn diagnose(a: DiagnoseArgs) -> Result<()> {
    let start = Instant::now();
    let root = match &a.dataset {
        Some(d) => d.clone(),
        None => {
            if a.als.is_empty() {
                return Err(Error::Usage("give --dataset, or --als with --l1b and --l2a".into()));
            }
            // The first half of `gedisim run`, with the diagnosis's per-track collocation.
            let opts = gedisim::run::RunOptions {
                als: a.als.clone(),
                l1b: a.l1b.clone(),
                l2a: a.l2a.clone(),
                landcover: a.chain.landcover.clone(),
                epsg: a.chain.epsg,
                geoid_offset: a.chain.geoid_offset,
                collocate: DIAGNOSIS_COLLOCATION,
                ..gedisim::run::RunOptions::new(&a.out.join("dataset"))
            };
            print_ingest_and_collocation(&gedisim::run::ingest_and_collocate(&opts, &Bars::new())?);
            opts.out
        }
    };
    let ds = Dataset::open(&root)?;
    if !ds.has_table(gedisim::dataset::tables::OFFSETS) {
        eprintln!("no offsets table: collocating per track first (the baseline's horizontal collocation)");
        let c = DIAGNOSIS_COLLOCATION;
        collocate(CollocateArgs {
            dataset: root.clone(),
            level: LevelArg::Beam,
            segment: c.segment,
            max_shift: c.max_shift,
            step: c.step,
            min_segment: c.min_segment,
            stats: false,
        })?;
    }
    let bar = progress(0, "shots");
    bar.set_message("simulating");
    let shots = ProgressBar::new_spinner();
    let out = gedisim::diagnosis::diagnose_dataset(&ds, &a.out, &a.effects, &|| bar.inc(1), &|step| {
        bar.finish_and_clear();
        shots.set_message(format!("fitting and scoring {step}"));
        shots.tick();
    });
    bar.finish_and_clear();
    shots.finish_and_clear();
    let out = out?;
    eprintln!("shots: {} read, {} used; dropped: {}", out.cases.shots_read, out.diagnosis.n_shots, gedisim::diagnosis::dropped_text(&out.cases));
    for line in gedisim::diagnosis::summary_lines(&out.diagnosis) {
        println!("{line}");
    }
    eprintln!("{} → {} ({:.1} s)", "diagnosis.json, tables, figures", a.out.display(), start.elapsed().as_secs_f64());
    Ok(())
}
