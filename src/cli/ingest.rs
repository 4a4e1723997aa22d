//! `gedisim ingest als|gedi|strata`.

use std::path::PathBuf;
use std::time::Instant;
use tracing::{info, warn};

use clap::Args;

use gedisim::ops::collocate::CollocateOptions;
use gedisim::ops::ingest_als::{self as als, AlsOptions, TileOutcome};
use gedisim::{Error, Result};

use super::reporters::{peak_rss_mb, Bars};

#[derive(Args)]
pub struct IngestAlsArgs {
    /// LAS/LAZ/COPC files or folders holding them (local, https:// or s3://).
    #[arg(long, num_args = 1.., required_unless_present = "inputs")]
    als: Vec<PathBuf>,
    /// The same as --als (the form of earlier versions).
    #[arg(hide = true)]
    inputs: Vec<PathBuf>,
    /// Dataset directory (created if needed).
    #[arg(long, alias = "out")]
    dataset: PathBuf,
    /// Keep noise (7, 18) and IGN artefact/virtual classes (64–67).
    #[arg(long)]
    keep_all_classes: bool,
    /// EPSG code of tiles that carry no CRS record.
    #[arg(long)]
    epsg: Option<u32>,
    /// Read COPC tiles whole. By default, once the dataset holds shots, a COPC tile is read only
    /// around them (docs/copc.md).
    #[arg(long)]
    whole_tiles: bool,
    /// Print wall time, points/s and peak memory at the end.
    #[arg(long)]
    stats: bool,
    /// Read the tiles on the Ballista cluster whose scheduler is at this address (`gedisim
    /// cluster`): one plan, a partition per tile, each executor writing its tile's files; this
    /// process commits them. Every node must see the tiles and the dataset at the same paths.
    #[arg(long, value_name = "df://HOST:PORT")]
    cluster: Option<String>,
}

#[derive(Args)]
pub struct IngestGediArgs {
    /// L1B files or folders holding them.
    #[arg(long, num_args = 1..)]
    l1b: Vec<PathBuf>,
    /// L2A files or folders holding them.
    #[arg(long, num_args = 1..)]
    l2a: Vec<PathBuf>,
    /// Dataset directory (created if needed).
    #[arg(long, alias = "out")]
    dataset: PathBuf,
    /// Projected CRS of the shots' x, y (default: the dataset's ALS CRS, else 2154).
    #[arg(long)]
    epsg: Option<u32>,
    /// Geoid offset N (m, ellipsoid − orthometric) for every shot, instead of each shot's L1B geoid.
    #[arg(long, allow_hyphen_values = true, value_parser = super::values::geoid_offset)]
    geoid_offset: Option<f64>,
    /// Fail when a shot of a paired granule is in only one of L1B and L2A (default: keep it, warn).
    #[arg(long)]
    strict_join: bool,
    #[command(flatten)]
    shots: ShotArgs,
    /// Read the granules on the Ballista cluster whose scheduler is at this address (`gedisim
    /// cluster`): one plan, a partition per granule, each executor writing its granule's shots; this
    /// process checks and commits them. Every node must see the granules and the dataset at the same
    /// paths.
    #[arg(long, value_name = "df://HOST:PORT")]
    cluster: Option<String>,
}

/// Which shots of the granules an ingest keeps (docs/gedi-products.md, "Shots kept").
#[derive(Args, Clone, Default)]
pub struct ShotArgs {
    /// Keep the shots within this box, degrees WGS84: west,south,east,north (default: the shots over
    /// the dataset's ALS tiles, grown by the collocation's search and the footprint's reach).
    #[arg(long, value_name = "W,S,E,N", allow_hyphen_values = true, conflicts_with_all = ["within", "all_shots"])]
    pub bbox: Option<String>,
    /// Keep the shots within the polygons of this GeoJSON file (WGS84 longitude, latitude) or GeoPackage
    /// (`.gpkg`: every feature table, in the EPSG CRS it declares).
    #[arg(long, value_name = "FILE", conflicts_with = "all_shots")]
    pub within: Option<PathBuf>,
    /// Keep every shot of every granule.
    #[arg(long)]
    pub all_shots: bool,
}

impl ShotArgs {
    pub fn choice(&self) -> Result<gedisim::ops::ingest_gedi::ShotChoice> {
        use gedisim::ops::ingest_gedi::ShotChoice;
        Ok(match (&self.bbox, &self.within, self.all_shots) {
            (Some(b), _, _) => ShotChoice::Area(
                gedisim::kernels::geo::area::ShotArea::lon_lat_box(b)
                    .map_err(|e| Error::Usage(format!("--bbox {b}: {e}")))?,
            ),
            (None, Some(f), _) => ShotChoice::Within(f.clone()),
            (None, None, true) => ShotChoice::All,
            (None, None, false) => ShotChoice::AlsCoverage,
        })
    }
}

#[derive(Args)]
pub struct IngestStrataArgs {
    /// Corine Land Cover GeoTIFF in EPSG:3035 (.tif), or a CSV with columns shot_number, forest_type (.csv).
    #[arg(long)]
    landcover: PathBuf,
    /// Dataset directory (with a shots table for a raster).
    #[arg(long)]
    dataset: PathBuf,
}

pub fn ingest_als(a: IngestAlsArgs) -> Result<()> {
    let start = Instant::now();
    let inputs: Vec<PathBuf> = a.als.into_iter().chain(a.inputs).collect();
    let ds = gedisim::dataset::Dataset::create(&a.dataset)?;
    let windows = match a.whole_tiles {
        true => None,
        false => als::shot_windows(&ds, als::run_window_half(CollocateOptions::default().max_shift))?,
    };
    if let Some(w) = &windows {
        info!(
            "COPC tiles are read within {:.1} m of the dataset's {} shots (--whole-tiles reads them whole)",
            w.half(),
            w.len()
        );
    }
    let engine = a.cluster.map(als::Engine::Cluster).unwrap_or_default();
    let opts = AlsOptions { keep_all_classes: a.keep_all_classes, epsg: a.epsg, windows, engine };
    let outcomes = als::ingest(&ds, &inputs, &opts, &Bars::new())?;
    super::reporters::print_fetched(&inputs);
    let (mut read, mut written) = (0, 0);
    for o in &outcomes {
        match o {
            TileOutcome::Ingested { tile, points, dropped, odd_returns, window } => {
                (read, written) = (read + points + dropped, written + points);
                if *odd_returns > 0 {
                    warn!(
                        "{tile}: return_number: {odd_returns} points have a return number of 0 or above their \
                         number_of_returns; the simulation takes each as the last return of its pulse"
                    );
                }
                match window {
                    None => info!("{tile}: {points} points ({dropped} dropped by class)"),
                    Some(w) => info!(
                        "{tile}: {points} points ({dropped} dropped by class) in {} new cells of {} m, {} read so \
                         far; COPC: {}",
                        w.cells_new,
                        gedisim::kernels::geo::cells::READ_CELL_M,
                        w.cells_read,
                        w.copc
                    ),
                }
            }
            TileOutcome::AlreadyIngested { tile } => info!("{tile}: already ingested (same content), skipped"),
        }
    }
    if a.stats {
        let s = start.elapsed().as_secs_f64();
        println!(
            "ingest: {} files, {read} points read, {written} written, {s:.2} s, {:.0} points/s, peak RSS {:.1} MB",
            outcomes.len(),
            read as f64 / s,
            peak_rss_mb()
        );
    }
    Ok(())
}

pub fn ingest_gedi(a: IngestGediArgs) -> Result<()> {
    use gedisim::ops::ingest_gedi::GranuleOutcome;
    if a.l1b.is_empty() && a.l2a.is_empty() {
        return Err(Error::Usage("give --l1b and/or --l2a files".into()));
    }
    let ds = gedisim::dataset::Dataset::create(&a.dataset)?;
    let request = gedisim::ops::ingest_gedi::IngestRequest {
        epsg: a.epsg,
        geoid_offset: a.geoid_offset,
        strict_join: a.strict_join,
        shots: a.shots.choice()?,
        als_inputs: Vec::new(),
        margin_m: als::run_window_half(CollocateOptions::default().max_shift),
        engine: a.cluster.map(gedisim::ops::ingest_gedi::Engine::Cluster).unwrap_or_default(),
    };
    let (outcomes, report) = gedisim::ops::ingest_gedi::ingest(&ds, &a.l1b, &a.l2a, &request, &Bars::new())?;
    for w in report.warnings() {
        warn!("{w}");
    }
    if let Some(line) = report.kept_line() {
        info!("{line}");
    }
    for o in outcomes {
        match o {
            GranuleOutcome::Ingested { granule, shots } => info!("{granule}: {shots} shots"),
            GranuleOutcome::AlreadyIngested { granule } => {
                info!("{granule}: already ingested (same content), skipped")
            }
        }
    }
    Ok(())
}

pub fn ingest_strata(a: IngestStrataArgs) -> Result<()> {
    let ds = gedisim::dataset::Dataset::create(&a.dataset)?;
    let report = gedisim::ops::ingest_strata::ingest_strata(&ds, &a.landcover, &Bars::new())?;
    let mut counts: Vec<_> = report.counts.iter().collect();
    counts.sort();
    let counts: Vec<String> = counts.iter().map(|(k, v)| format!("{k} {v}")).collect();
    info!("{} shots → {} ({})", report.rows, report.path.display(), counts.join(", "));
    if report.outside > 0 || report.no_position > 0 {
        info!(
            "{} shots outside the raster and {} without a position: forest type `unknown`",
            report.outside, report.no_position
        );
    }
    if report.not_in_dataset > 0 {
        warn!("{} CSV rows name shots that are not in the dataset's shots table", report.not_in_dataset);
    }
    Ok(())
}
