//! `run`: the study end to end on one dataset — ingest (ALS tiles, GEDI granules, strata) →
//! collocate → simulate count, frac and int at the collocated positions → the study's filters →
//! `results/` (one row per shot × weighting × algorithm) — processing only what is new.
//!
//! Work is done per granule (one file of `shots/`, named by its granule key):
//! - `offsets/offsets.parquet` stays one file; only granules never collocated (or re-ingested
//!   with other content) are collocated, their rows merged with the others' (key-value metadata
//!   `gedisim:run_granules` records which inputs each granule was collocated from). Adding ALS
//!   tiles does not re-collocate granules already done (`gedisim collocate` redoes them all).
//! - `sim/<granule key>.parquet`: the shots whose footprint the ALS covers, simulated; skipped when
//!   the file records the same inputs (`gedisim:run_input`: the granule's content hashes, the
//!   simulated positions and offsets, the tiles under them, the simulator settings).
//! - `results/<granule key>.parquet`: the rows that pass the filters ([`crate::kernels::study::select`]),
//!   with the filter counts of the granule in its metadata (`gedisim:filter_counts`); skipped when
//!   its inputs (the simulation's, strata, collocation quality, filter settings) are unchanged.
//!   A granule without any kept row still gets a (0-row) file: it records that it was done.
//!
//! The pure decisions live in `study::select`; this module reads and writes files. By step: the
//! ingests (here), [`collocate`], [`plan`] (each granule's pass A), [`simulate`], [`results`];
//! [`granules`] names each granule by its inputs.

mod collocate;
mod granules;
mod plan;
mod results;
mod simulate;

pub use results::results_batch;

use std::path::{Path, PathBuf};

use crate::dataset::{self, tables, Dataset};
use crate::error::{Error, Result};
use crate::kernels::study::select::{FilterCounts, StudyRules};
use crate::ops::collocate::{CollocateOptions, CollocateReport};
use crate::ops::ingest_als::{self as als, AlsOptions, TileOutcome};
use crate::ops::ingest_gedi::{self as gedi, GranuleOutcome};
use crate::ops::ingest_strata::StrataReport;
use crate::ops::progress::Progress;
pub use crate::sql::Engine;
pub(crate) use granules::granule_inputs;
use granules::{list_granules, GranuleFile};
use plan::{plan_granule, StudyInputs};
use simulate::simulate_on;

/// Version of what `run` writes: a change of the selection or the simulation logic bumps it, so
/// that every granule is redone.
pub const RUN_FORMAT: &str = "gedisim-run-1";
/// Metadata key of `sim/` and `results/` files written by `run`: the hash of their inputs.
pub const META_INPUT: &str = "gedisim:run_input";
/// Metadata key of `results/` files: the granule's [`FilterCounts`] as JSON.
pub const META_COUNTS: &str = "gedisim:filter_counts";
/// Metadata key of `offsets/offsets.parquet`: granule key → inputs it was collocated from.
pub const META_GRANULES: &str = "gedisim:run_granules";

/// Options of `gedisim run`.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// Dataset directory (created if needed).
    pub out: PathBuf,
    /// LAS/LAZ files or folders; empty: use the tiles the dataset already holds.
    pub als: Vec<PathBuf>,
    /// GEDI L1B and L2A files or folders; both empty: use the shots the dataset already holds.
    pub l1b: Vec<PathBuf>,
    pub l2a: Vec<PathBuf>,
    /// Corine Land Cover GeoTIFF or `shot_number,forest_type` CSV (replaces `strata/`).
    pub landcover: Option<PathBuf>,
    /// Projected CRS (default: the dataset's ALS CRS, else 2154).
    pub epsg: Option<u32>,
    /// Geoid offset N (m) for every newly ingested shot instead of its L1B geoid.
    pub geoid_offset: Option<f64>,
    /// Collocation of the new granules.
    pub collocate: CollocateOptions,
    /// Half-width (m) of the window read around each shot from COPC tiles; `None`:
    /// [`als::run_window_half`] of the collocation's largest shift.
    pub als_window: Option<f64>,
    /// The study's bounds.
    pub rules: StudyRules,
    /// The shots of new granules kept (default: those over the dataset's and `als`'s tiles).
    pub shots: gedi::ShotChoice,
    /// Where the collocation and the simulation run: here, or each as one plan on a Ballista cluster
    /// (a partition per granule to collocate, per group of a granule's blocks to simulate).
    pub engine: Engine,
}

impl RunOptions {
    /// Defaults (beam-level collocation, the study's bounds) for the dataset `out`.
    pub fn new(out: &Path) -> Self {
        RunOptions {
            out: out.to_path_buf(),
            als: Vec::new(),
            l1b: Vec::new(),
            l2a: Vec::new(),
            landcover: None,
            epsg: None,
            geoid_offset: None,
            collocate: CollocateOptions::default(),
            als_window: None,
            rules: StudyRules::default(),
            shots: gedi::ShotChoice::AlsCoverage,
            engine: Engine::Local,
        }
    }
}

/// What happened to one granule.
#[derive(Debug, Clone, PartialEq)]
pub struct GranuleRun {
    /// Granule key (the `shots/`, `sim/` and `results/` file stem).
    pub key: String,
    /// The shots' `granule` column.
    pub granule: String,
    /// Shots in the granule.
    pub shots: usize,
    /// Shots whose footprint the ALS covers (simulated).
    pub covered: usize,
    /// (simulated, skipped by the simulator) when simulated by this run; `None` when the
    /// simulation was up to date (or nothing to simulate).
    pub simulated: Option<(usize, usize)>,
    /// The results file was (re)written by this run.
    pub results_written: bool,
    /// Filter counts of the granule (from its results file when up to date).
    pub counts: FilterCounts,
}

/// What a run did.
#[derive(Debug, Clone, Default)]
pub struct RunReport {
    pub dataset: PathBuf,
    /// ALS files given, ingested or skipped.
    pub tiles: Vec<TileOutcome>,
    /// The ALS inputs given (files, folders or URLs).
    pub als_inputs: Vec<PathBuf>,
    /// GEDI granules given, ingested or skipped.
    pub ingested: Vec<GranuleOutcome>,
    /// Warnings (GEDI joins, foreign files in `sim/`).
    pub warnings: Vec<String>,
    /// What the GEDI ingest kept and left out ([`gedi::IngestReport::kept_line`]), and how many
    /// shots it left out.
    pub shots_kept: Option<String>,
    pub shots_outside_area: usize,
    pub strata: Option<StrataReport>,
    /// The collocation of the granules that needed one (`None`: none did).
    pub collocation: Option<CollocateReport>,
    /// Keys of the granules collocated by this run.
    pub collocated: Vec<String>,
    /// Every granule of the dataset, in key order.
    pub granules: Vec<GranuleRun>,
    /// Counts over every granule of the dataset.
    pub totals: FilterCounts,
    /// The bounds used.
    pub rules: StudyRules,
}

impl RunReport {
    /// Footprints simulated by this run.
    pub fn shots_simulated(&self) -> usize {
        self.granules.iter().filter_map(|g| g.simulated).map(|(a, b)| a + b).sum()
    }

    /// Granules whose results this run wrote.
    pub fn granules_processed(&self) -> usize {
        self.granules.iter().filter(|g| g.results_written).count()
    }

    /// Rows of the results table (every granule).
    pub fn rows(&self) -> u64 {
        self.totals.kept
    }

    /// Nothing was ingested, collocated, simulated or written.
    pub fn nothing_new(&self) -> bool {
        self.collocated.is_empty()
            && self.granules_processed() == 0
            && self.tiles.iter().all(|t| matches!(t, TileOutcome::AlreadyIngested { .. }))
            && self.ingested.iter().all(|g| matches!(g, GranuleOutcome::AlreadyIngested { .. }))
    }

    /// What this run ingested and simulated.
    pub fn counts(&self) -> RunCounts {
        let shots: Vec<usize> = self
            .ingested
            .iter()
            .filter_map(|g| if let GranuleOutcome::Ingested { shots, .. } = g { Some(*shots) } else { None })
            .collect();
        let points: Vec<u64> = self
            .tiles
            .iter()
            .filter_map(|t| if let TileOutcome::Ingested { points, .. } = t { Some(*points) } else { None })
            .collect();
        let simulated: Vec<(usize, usize)> = self.granules.iter().filter_map(|g| g.simulated).collect();
        RunCounts {
            granules_new: shots.len(),
            granules_already: self.ingested.len() - shots.len(),
            shots_ingested: shots.iter().sum(),
            tiles_new: points.len(),
            tiles_already: self.tiles.len() - points.len(),
            points_ingested: points.iter().sum(),
            simulated: simulated.iter().fold((0, 0), |a, b| (a.0 + b.0, a.1 + b.1)),
            granules_simulated: simulated.len(),
        }
    }

    /// What the run did, for scripts (`run --json`, the Python API's `Dataset.run`).
    pub fn json(&self) -> serde_json::Value {
        let (t, c) = (&self.totals, self.counts());
        let filters: Vec<serde_json::Value> = crate::kernels::study::select::Filter::ALL
            .iter()
            .map(|&f| {
                let rule = f.describe(&self.rules);
                serde_json::json!({"filter": f.name(), "rule": rule, "rows_removed": t.removed_by(f)})
            })
            .collect();
        serde_json::json!({
            "dataset": self.dataset,
            "results": self.dataset.join("results"),
            "nothing_new": self.nothing_new(),
            "als": {
                "tiles_ingested": c.tiles_new,
                "points_ingested": c.points_ingested,
                "tiles_already_ingested": c.tiles_already
            },
            "gedi": {
                "granules_ingested": c.granules_new,
                "shots_ingested": c.shots_ingested,
                "shots_outside_area": self.shots_outside_area,
                "granules_already_ingested": c.granules_already
            },
            "collocation": self.collocation.as_ref().map(|c| serde_json::json!({
                "granules": self.collocated.len(), "shots_read": c.shots, "segments": c.segments,
                "short_runs": c.short_runs.len(), "table": c.table
            })),
            "simulation": {"shots_simulated": c.simulated.0, "shots_skipped_by_simulator": c.simulated.1},
            "granules": {"in_dataset": self.granules.len(), "results_written": self.granules_processed()},
            "rows": {
                "candidates": t.candidates, "kept": t.kept, "shots": t.shots, "shots_kept": t.shots_kept,
                "acquisition_window_not_applied": t.window_unknown
            },
            "filters": filters,
            "warnings": self.warnings,
        })
    }
}

/// What a run ingested and simulated, counted once for the text and JSON summaries.
#[derive(Debug, Clone, PartialEq)]
pub struct RunCounts {
    pub granules_new: usize,
    pub granules_already: usize,
    pub shots_ingested: usize,
    pub tiles_new: usize,
    pub tiles_already: usize,
    pub points_ingested: u64,
    /// (simulated, skipped by the simulator) and the granules simulated.
    pub simulated: (usize, usize),
    pub granules_simulated: usize,
}

/// The whole chain on `opts.out`; `progress` follows every long step.
pub fn run_study(opts: &RunOptions, progress: &dyn Progress) -> Result<RunReport> {
    let r = &opts.rules;
    if !(r.max_days_apart.is_finite() && r.max_days_apart >= 0.0) {
        return Err(Error::Usage(format!("--max-days-apart: {} is not a number of days ≥ 0", r.max_days_apart)));
    }
    if !(r.min_rh100.is_finite() && r.max_rh100.is_finite() && r.min_rh100 <= r.max_rh100) {
        return Err(Error::Usage(format!("RH100 bounds {}..{} m are not an interval", r.min_rh100, r.max_rh100)));
    }
    let (ds, mut report, granules) = ingest_and_collocate_granules(opts, progress)?;
    let inputs = StudyInputs::read(&ds)?;
    let mut plans =
        granules.into_iter().map(|g| plan_granule(&ds, g, &inputs, &opts.rules)).collect::<Result<Vec<_>>>()?;
    let foreign = ds.root().join(tables::SIM).join("shots.parquet");
    if foreign.exists() {
        report.warnings.push(format!(
            "{}: written by `gedisim simulate --dataset`, it repeats shots that run simulates into \
                sim/<granule>.parquet; remove it so that each shot is in sim/ once",
            foreign.display()
        ));
    }
    match &opts.engine {
        Engine::Local => simulate::simulate(&ds, &mut plans, &inputs, progress)?,
        engine => simulate_on(engine, &ds, &mut plans, progress)?,
    }
    results::results(&mut plans, &inputs, &opts.rules, progress)?;
    for p in plans {
        report.totals.add(&p.run.counts);
        report.granules.push(p.run);
    }
    Ok(report)
}

/// The first half of a run: ingest what is new of the tiles, the granules and the land cover, then
/// collocate the granules that need it (`opts.rules` is not used). `gedisim diagnose --als` stops
/// here. The dataset is returned as its writer: the lock held until the caller drops it.
pub fn ingest_and_collocate(opts: &RunOptions, progress: &dyn Progress) -> Result<(Dataset, RunReport)> {
    ingest_and_collocate_granules(opts, progress).map(|(ds, report, _)| (ds, report))
}

fn ingest_and_collocate_granules(
    opts: &RunOptions,
    progress: &dyn Progress,
) -> Result<(Dataset, RunReport, Vec<GranuleFile>)> {
    // The writer lock held until the run ends (the dataset is returned to `run_study`).
    let ds = Dataset::create(&opts.out)?.as_writer()?;
    let mut report = RunReport { dataset: opts.out.clone(), rules: opts.rules, ..Default::default() };
    require_inputs(&ds, opts)?;
    // The shots first, so that COPC tiles are read only around them; their CRS is then the
    // dataset's, else the tiles'.
    let epsg = match (opts.epsg, dataset::dataset_epsg(&ds)?) {
        (Some(e), _) | (None, Some(e)) => Some(e),
        (None, None) => als::inputs_epsg(&opts.als)?,
    };
    ingest_gedi(&ds, opts, epsg, progress, &mut report)?;
    ingest_als(&ds, opts, progress, &mut report)?;
    if let Some(landcover) = &opts.landcover {
        report.strata = Some(crate::ops::ingest_strata::ingest_strata(&ds, landcover, progress)?);
    }
    let granules = list_granules(&ds)?;
    collocate::collocate(&ds, opts, &granules, progress, &mut report)?;
    Ok((ds, report, granules))
}

/// Tiles and granules given, or already in the dataset; the tiles given readable (their headers).
fn require_inputs(ds: &Dataset, opts: &RunOptions) -> Result<()> {
    for f in als::expand_inputs(&opts.als)? {
        crate::io::las::read_header(&f)?;
    }
    if opts.als.is_empty() && !ds.has_table(tables::ALS) {
        return Err(Error::Usage(format!(
            "--als: {} has no ALS table yet; give the LAS/LAZ tiles",
            opts.out.display()
        )));
    }
    if opts.l1b.is_empty() && opts.l2a.is_empty() && !ds.has_table(tables::SHOTS) {
        return Err(Error::Usage(format!(
            "--l1b/--l2a: {} has no shots table yet; give the GEDI granules",
            opts.out.display()
        )));
    }
    Ok(())
}

fn ingest_als(ds: &Dataset, opts: &RunOptions, progress: &dyn Progress, report: &mut RunReport) -> Result<()> {
    if opts.als.is_empty() {
        return Ok(());
    }
    let half = opts.als_window.unwrap_or_else(|| als::run_window_half(opts.collocate.max_shift));
    let windows = als::shot_windows(ds, half)?;
    report.als_inputs = opts.als.clone();
    let als_opts = AlsOptions { keep_all_classes: false, epsg: opts.epsg, windows, engine: opts.engine.clone() };
    report.tiles = als::ingest(ds, &opts.als, &als_opts, progress)?;
    Ok(())
}

fn ingest_gedi(
    ds: &Dataset,
    opts: &RunOptions,
    epsg: Option<u32>,
    progress: &dyn Progress,
    report: &mut RunReport,
) -> Result<()> {
    if opts.l1b.is_empty() && opts.l2a.is_empty() {
        return Ok(());
    }
    let request = gedi::IngestRequest {
        epsg,
        geoid_offset: opts.geoid_offset,
        strict_join: false,
        shots: opts.shots.clone(),
        als_inputs: opts.als.clone(),
        margin_m: opts.als_window.unwrap_or_else(|| als::run_window_half(opts.collocate.max_shift)),
        engine: opts.engine.clone(),
    };
    let (outcomes, ingest) = gedi::ingest(ds, &opts.l1b, &opts.l2a, &request, progress)?;
    report.shots_kept = ingest.kept_line();
    report.shots_outside_area = ingest.outside_area();
    report.warnings.extend(ingest.warnings());
    report.ingested = outcomes;
    Ok(())
}
