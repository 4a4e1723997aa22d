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
//! The pure decisions live in `study::select`; this module reads and writes files.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::path::{Path, PathBuf};

use arrow::array::{AsArray, BooleanArray, RecordBatch};
use sha2::{Digest, Sha256};

use crate::dataset::als::AlsTable;
use crate::dataset::offsets::{offsets_schema, read_offsets, read_r_after, AppliedOffset};
use crate::dataset::results::{results_batch, results_metadata, results_schema};
use crate::dataset::sim::{sim_metadata, sim_schema};
use crate::dataset::{self, read, tables, Dataset};
use crate::error::{Error, Result};
use crate::kernels::sim::{Footprint, Profile, SimConfig};
use crate::kernels::study::select::{
    als_window, select_rows, AlgorithmFacts, Filter, FilterCounts, SegmentFacts, ShotContext, ShotFacts, SimFacts,
    StudyRules, TileWindow, WEIGHTINGS,
};
use crate::ops::collocate::{solve_granules, CollocateOptions, CollocateReport};
use crate::ops::ingest_als::{self as als, AlsOptions, TileOutcome};
use crate::ops::ingest_gedi::{self as gedi, GranuleOutcome};
use crate::ops::ingest_strata::StrataReport;
use crate::ops::progress::{Progress, Step};
use crate::ops::simulate::{simulate_groups, status_counts};
pub use crate::sql::Engine;

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
        Engine::Local => simulate(&ds, &mut plans, &inputs, progress)?,
        engine => simulate_on(engine, &ds, &mut plans, progress)?,
    }
    results(&mut plans, &inputs, &opts.rules, progress)?;
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
    collocate(&ds, opts, &granules, progress, &mut report)?;
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
    report.tiles =
        als::ingest(ds, &opts.als, &AlsOptions { keep_all_classes: false, epsg: opts.epsg, windows }, progress)?;
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
    };
    let (outcomes, ingest) = gedi::ingest(ds, &opts.l1b, &opts.l2a, &request, progress)?;
    report.shots_kept = ingest.kept_line();
    report.shots_outside_area = ingest.outside_area();
    report.warnings.extend(ingest.warnings());
    report.ingested = outcomes;
    Ok(())
}

/// One file of `shots/`.
#[derive(Debug, Clone)]
struct GranuleFile {
    key: String,
    path: PathBuf,
    /// The `granule` column.
    name: String,
    /// The content hashes it was ingested from (`granules/`), as one string.
    inputs: String,
}

fn list_granules(ds: &Dataset) -> Result<Vec<GranuleFile>> {
    let dir = ds.root().join(tables::SHOTS);
    let files =
        dataset::table_files(&dir).map_err(|e| Error::file(&dir, format!("no shots table ({e}): give --l1b/--l2a")))?;
    let mut out = Vec::new();
    for path in files {
        let (key, inputs) = granule_inputs(ds, &path)?;
        let name = first_string(&path, "granule")?.unwrap_or_else(|| key.clone());
        out.push(GranuleFile { key, path, name, inputs });
    }
    Ok(out)
}

/// The granule key of a `shots/` file and what its shots were ingested from, as one string: the
/// content hashes of its L1B and L2A and the area its shots were kept by (its `granules/`
/// record); for a file without a record, its size and time. What `run` (and the diagnosis's
/// re-use key) treat as the granule's identity.
pub(crate) fn granule_inputs(ds: &Dataset, shots_file: &Path) -> Result<(String, String)> {
    let key = shots_file.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let record = ds.root().join(tables::GRANULES).join(format!("{key}.parquet"));
    let inputs = match gedi::previous_record(&record)? {
        Some(((a, b), area)) => {
            let area = if area == "all" { String::new() } else { format!(" area={area}") };
            format!("l1b={} l2a={}{area}", a.unwrap_or_default(), b.unwrap_or_default())
        }
        None => {
            let m = std::fs::metadata(shots_file).map_err(|e| Error::file(shots_file, e))?;
            let t = m
                .modified()
                .ok()
                .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
                .map_or(0, |d| d.as_nanos());
            format!("size={} mtime={t}", m.len())
        }
    };
    Ok((key, inputs))
}

/// The first value of string column `column` of a Parquet file.
fn first_string(path: &Path, column: &str) -> Result<Option<String>> {
    // One row of one column: the file's first batch of one row, not the whole column.
    let builder = read::open(path)?;
    let mask = parquet::arrow::ProjectionMask::columns(builder.parquet_schema(), [column]);
    let reader =
        builder.with_projection(mask).with_batch_size(1).with_limit(1).build().map_err(|e| Error::table(path, e))?;
    for b in reader {
        let b = b.map_err(|e| Error::table(path, e))?;
        if b.num_rows() > 0 {
            return read::Columns::new(path, &b).string(column, 0);
        }
    }
    Ok(None)
}

/// Collocate the granules never collocated (or re-ingested since), merging their segments into
/// `offsets/offsets.parquet`.
fn collocate(
    ds: &Dataset,
    opts: &RunOptions,
    granules: &[GranuleFile],
    progress: &dyn Progress,
    report: &mut RunReport,
) -> Result<()> {
    let dest = ds.table_file(tables::OFFSETS, "offsets")?;
    let mut existing: Vec<RecordBatch> = Vec::new();
    let mut meta = HashMap::new();
    if dest.exists() {
        meta = read::key_value_metadata(&dest).unwrap_or_default();
        read::for_each_batch(&dest, None, None, |c| {
            let b = RecordBatch::try_new(offsets_schema(), c.batch().columns().to_vec());
            existing.push(b.map_err(|e| Error::table(&dest, e))?);
            Ok(())
        })?;
    }
    let granule_col = |b: &RecordBatch| b.column_by_name("granule").and_then(|c| c.as_string_opt::<i32>().cloned());
    let mut present = HashSet::new();
    for b in &existing {
        let g = granule_col(b).ok_or_else(|| Error::field(&dest, "granule", "missing or not a string"))?;
        present.extend(g.iter().flatten().map(str::to_string));
    }
    let recorded: Option<BTreeMap<String, String>> = meta.get(META_GRANULES).and_then(|s| serde_json::from_str(s).ok());
    let needed: Vec<&GranuleFile> = granules
        .iter()
        .filter(|g| match &recorded {
            Some(map) => map.get(&g.key) != Some(&g.inputs),
            // A table made by `gedisim collocate`: its granules are current.
            None => !present.contains(&g.name),
        })
        .collect();
    if needed.is_empty() {
        return Ok(());
    }
    let files = needed.iter().map(|g| g.path.clone()).collect();
    let (offsets, collocation) = solve_granules(&opts.engine, ds, &opts.collocate, files, progress)?;
    // Keep the other granules' segments; replace those of the granules just collocated, and drop
    // those of granules no longer in `shots/` (a granule renamed when its L1B file arrived).
    let replaced: HashSet<&str> = needed.iter().map(|g| g.name.as_str()).collect();
    let current: HashSet<&str> = granules.iter().map(|g| g.name.as_str()).collect();
    let mut batches = Vec::new();
    let mut kept_levels = HashSet::new();
    for b in existing {
        let g = granule_col(&b).ok_or_else(|| Error::field(&dest, "granule", "missing or not a string"))?;
        let keep: BooleanArray =
            g.iter().map(|v| Some(v.is_some_and(|v| current.contains(v) && !replaced.contains(v)))).collect();
        let b = arrow::compute::filter_record_batch(&b, &keep).map_err(|e| Error::table(&dest, e))?;
        if let Some(l) = b.column_by_name("level").and_then(|c| c.as_string_opt::<i32>().cloned()) {
            kept_levels.extend(l.iter().flatten().map(str::to_string));
        }
        batches.push(b);
    }
    batches.extend(offsets);
    let mut map = recorded.unwrap_or_else(|| {
        granules.iter().filter(|g| present.contains(&g.name)).map(|g| (g.key.clone(), g.inputs.clone())).collect()
    });
    for g in &needed {
        map.insert(g.key.clone(), g.inputs.clone());
    }
    let level = opts.collocate.level.name();
    kept_levels.insert(level.to_string());
    let mut out_meta = HashMap::new();
    out_meta.insert(
        "gedisim:collocate_level".to_string(),
        if kept_levels.len() > 1 { "mixed".to_string() } else { level.to_string() },
    );
    out_meta.insert("gedisim:max_shift_m".to_string(), opts.collocate.max_shift.to_string());
    out_meta.insert("gedisim:step_m".to_string(), opts.collocate.step.to_string());
    out_meta.insert(META_GRANULES.to_string(), serde_json::to_string(&map).map_err(|e| Error::table(&dest, e))?);
    dataset::write_parquet(&dest, offsets_schema(), &batches, &out_meta)?;
    report.collocation = Some(CollocateReport { table: dest, ..collocation });
    report.collocated = needed.iter().map(|g| g.key.clone()).collect();
    Ok(())
}

/// What every granule's planning and results read once.
struct StudyInputs {
    als: AlsTable,
    cfg: SimConfig,
    /// Radius (m) the ALS extents must cover around a footprint centre: 2 σ_f.
    cover_radius: f64,
    /// Half-width (m) of the ALS read around a footprint (the simulator's cut-off).
    read_radius: f64,
    offsets: HashMap<u64, AppliedOffset>,
    r_after: HashMap<String, f64>,
    /// Every tile's extent and acquisition window, and its content hash (same order).
    tiles: Vec<TileWindow>,
    tile_hashes: Vec<String>,
    strata: HashMap<u64, String>,
}

impl StudyInputs {
    fn read(ds: &Dataset) -> Result<Self> {
        let cfg = SimConfig::new(Profile::Default);
        let (tiles, tile_hashes) = read_tiles(ds)?.into_iter().unzip();
        Ok(StudyInputs {
            als: AlsTable::open(ds)?,
            cover_radius: 2.0 * cfg.fsigma as f64,
            read_radius: crate::kernels::sim::footprint::read_radius(cfg.fsigma),
            cfg,
            offsets: read_offsets(ds)?,
            r_after: read_r_after(ds)?,
            tiles,
            tile_hashes,
            strata: crate::dataset::strata::read_forest_types(ds)?,
        })
    }
}

/// Extent, acquisition window and content hash of every ingested tile.
fn read_tiles(ds: &Dataset) -> Result<Vec<(TileWindow, String)>> {
    let dir = ds.root().join(tables::TILES);
    let mut out = Vec::new();
    for path in dataset::table_files(&dir).map_err(|e| Error::file(&dir, e))? {
        read::for_each_batch(&path, None, None, |c| {
            for i in 0..c.num_rows() {
                let w = TileWindow {
                    xmin: c.f64("xmin", i)?.unwrap_or(f64::NAN),
                    ymin: c.f64("ymin", i)?.unwrap_or(f64::NAN),
                    xmax: c.f64("xmax", i)?.unwrap_or(f64::NAN),
                    ymax: c.f64("ymax", i)?.unwrap_or(f64::NAN),
                    start_us: c.timestamp("acquisition_start", i)?,
                    end_us: c.timestamp("acquisition_end", i)?,
                };
                out.push((w, c.string("content_hash", i)?.unwrap_or_default()));
            }
            Ok(())
        })?;
    }
    Ok(out)
}

/// A shot whose footprint the ALS covers: simulated at its collocated position.
#[derive(Debug, Clone)]
struct CoveredShot {
    /// Row in its `shots/` file.
    row: usize,
    footprint: Footprint,
    offset: Option<AppliedOffset>,
}

/// One granule after planning.
struct GranulePlan {
    file: GranuleFile,
    covered: Vec<CoveredShot>,
    sim_path: PathBuf,
    results_path: PathBuf,
    sim_input: String,
    results_input: String,
    needs_sim: bool,
    needs_results: bool,
    run: GranuleRun,
}

/// Pass A of a granule: positions, coverage, and whether its simulation and results are current.
fn plan_granule(ds: &Dataset, file: GranuleFile, inputs: &StudyInputs, rules: &StudyRules) -> Result<GranulePlan> {
    let mut covered = Vec::new();
    let mut n = 0;
    read::for_each_batch(&file.path, Some(&["shot_number", "x", "y"]), None, |c| {
        for i in 0..c.num_rows() {
            let row = n + i;
            let Some(sn) = c.u64("shot_number", i)? else { continue };
            let (Some(x), Some(y)) = (c.f64("x", i)?, c.f64("y", i)?) else { continue };
            let offset = inputs.offsets.get(&sn).cloned();
            let (dx, dy) = offset.as_ref().map_or((0.0, 0.0), |o| (o.dx, o.dy));
            let (x, y) = (x + dx, y + dy);
            // Where a COPC tile was read only in windows, its points must all have been read.
            let als = &inputs.als;
            if als.covers(x, y, inputs.cover_radius) && als.unread_window(x, y, inputs.read_radius).is_none() {
                covered.push(CoveredShot { row, footprint: Footprint::at(sn.to_string(), x, y), offset });
            }
        }
        n += c.num_rows();
        Ok(())
    })?;
    // What the simulation depends on: the granule's content, the simulated positions and
    // offsets, the tiles under them, the simulator.
    let mut h = Sha256::new();
    let mut line = |s: String| {
        h.update(s.as_bytes());
        h.update(b"\n");
    };
    line(format!("{RUN_FORMAT} sim {} {:?}", file.inputs, inputs.cfg));
    let r = inputs.read_radius;
    let mut tiles: Vec<&str> = inputs
        .tiles
        .iter()
        .zip(&inputs.tile_hashes)
        .filter(|(t, _)| {
            covered.iter().any(|c| {
                c.footprint.x + r >= t.xmin
                    && c.footprint.x - r <= t.xmax
                    && c.footprint.y + r >= t.ymin
                    && c.footprint.y - r <= t.ymax
            })
        })
        .map(|(_, hash)| hash.as_str())
        .collect();
    tiles.sort_unstable();
    line(format!("tiles {}", tiles.join(",")));
    for c in &covered {
        let o = c.offset.as_ref().map_or("-".to_string(), |o| format!("{} {:?}", o.segment_id, o.dz.to_bits()));
        line(format!("{} {} {} {o}", c.footprint.id, c.footprint.x.to_bits(), c.footprint.y.to_bits()));
    }
    let sim_input = hex::encode(h.finalize());
    // What the results add: strata, collocation quality, the filters' bounds.
    let mut h = Sha256::new();
    h.update(format!("{RUN_FORMAT} results {sim_input} {rules:?}\n").as_bytes());
    for c in &covered {
        let sn: u64 = c.footprint.id.parse().unwrap_or_default();
        let forest = inputs.strata.get(&sn).map_or("-", String::as_str);
        let r = c.offset.as_ref().and_then(|o| inputs.r_after.get(&o.segment_id)).map_or(0, |r| r.to_bits());
        h.update(format!("{sn} {forest} {r}\n").as_bytes());
    }
    let results_input = hex::encode(h.finalize());

    let sim_path = ds.table_file(tables::SIM, &file.key)?;
    let results_path = ds.table_file(tables::RESULTS, &file.key)?;
    let sim_meta = read::key_value_metadata(&sim_path);
    let needs_sim = !covered.is_empty() && sim_meta.as_ref().and_then(|m| m.get(META_INPUT)) != Some(&sim_input);
    if covered.is_empty() && sim_meta.is_some_and(|m| m.contains_key(META_INPUT)) {
        // This run's own simulation of shots no longer covered: stale.
        std::fs::remove_file(&sim_path)
            .map_err(|e| Error::file(&sim_path, format!("cannot remove a stale simulation: {e}")))?;
    }
    let results_meta = read::key_value_metadata(&results_path);
    let previous = results_meta
        .filter(|m| m.get(META_INPUT) == Some(&results_input))
        .and_then(|m| FilterCounts::from_json(&serde_json::from_str(m.get(META_COUNTS)?).ok()?));
    let needs_results = needs_sim || previous.is_none();
    let run = GranuleRun {
        key: file.key.clone(),
        granule: file.name.clone(),
        shots: n,
        covered: covered.len(),
        simulated: None,
        results_written: false,
        counts: previous.unwrap_or_default(),
    };
    Ok(GranulePlan { file, covered, sim_path, results_path, sim_input, results_input, needs_sim, needs_results, run })
}

/// Simulate the covered shots of every granule whose simulation is not current.
fn simulate(ds: &Dataset, plans: &mut [GranulePlan], inputs: &StudyInputs, progress: &dyn Progress) -> Result<()> {
    let total: usize = plans.iter().filter(|p| p.needs_sim).map(|p| p.covered.len()).sum();
    if total == 0 {
        return Ok(());
    }
    progress.start(Step::Simulate, total as u64);
    for p in plans.iter_mut().filter(|p| p.needs_sim) {
        let footprints = p.covered.iter().map(|c| (c.footprint.clone(), c.offset.clone())).collect();
        let extra = HashMap::from([(META_INPUT.to_string(), p.sim_input.clone())]);
        let r = crate::ops::simulate::simulate_on_dataset_with(
            ds,
            footprints,
            &inputs.cfg,
            Profile::Default,
            &p.sim_path,
            &extra,
            progress,
        );
        if r.is_err() {
            progress.finish();
        }
        p.run.simulated = Some(r?);
    }
    progress.finish();
    Ok(())
}

/// Footprints per job a cluster run submits: the client holds one job's rows at a time.
const CLUSTER_JOB_FOOTPRINTS: usize = 20_000;

/// [`simulate`] as plans on `engine`: each job covers whole granules, each of its partitions a run of
/// one granule's blocks ([`crate::ops::simulate::simulate_groups`]); every `sim/` file gets the rows
/// and metadata a local run writes.
fn simulate_on(engine: &Engine, ds: &Dataset, plans: &mut [GranulePlan], progress: &dyn Progress) -> Result<()> {
    let total: usize = plans.iter().filter(|p| p.needs_sim).map(|p| p.covered.len()).sum();
    if total == 0 {
        return Ok(());
    }
    progress.start(Step::Simulate, total as u64);
    let rt = crate::sql::runtime()?;
    let r = rt.block_on(async {
        let ctx = crate::sql::session_on(ds, &Default::default(), engine).await?;
        // Jobs of whole granules, each closed once it holds CLUSTER_JOB_FOOTPRINTS footprints.
        let mut jobs: Vec<(usize, Vec<&mut GranulePlan>)> = Vec::new();
        for p in plans.iter_mut().filter(|p| p.needs_sim) {
            match jobs.last_mut() {
                Some((size, job)) if *size < CLUSTER_JOB_FOOTPRINTS => {
                    *size += p.covered.len();
                    job.push(p);
                }
                _ => jobs.push((p.covered.len(), vec![p])),
            }
        }
        for (_, job) in jobs {
            let groups =
                job.iter().map(|p| p.covered.iter().map(|c| (c.footprint.clone(), c.offset.clone())).collect());
            let batches = simulate_groups(&ctx, ds, groups.collect(), Profile::Default).await?;
            for (p, batch) in job.into_iter().zip(batches) {
                let mut metadata = sim_metadata(Profile::Default);
                metadata.insert(META_INPUT.to_string(), p.sim_input.clone());
                dataset::write_parquet(&p.sim_path, sim_schema(), std::slice::from_ref(&batch), &metadata)?;
                let (ok, skipped) = status_counts(&p.sim_path, &batch)?;
                p.run.simulated = Some((ok, skipped));
                progress.advance((ok + skipped) as u64);
            }
        }
        Ok(())
    });
    progress.finish();
    r
}

/// Apply the filters and write `results/<key>.parquet` for every granule whose results are not current.
fn results(plans: &mut [GranulePlan], inputs: &StudyInputs, rules: &StudyRules, progress: &dyn Progress) -> Result<()> {
    let todo = plans.iter().filter(|p| p.needs_results).count();
    if todo == 0 {
        return Ok(());
    }
    progress.start(Step::Results, todo as u64);
    let r = plans.iter_mut().filter(|p| p.needs_results).try_for_each(|p| {
        granule_results(p, inputs, rules)?;
        progress.advance(1);
        Ok(())
    });
    progress.finish();
    r
}

fn granule_results(p: &mut GranulePlan, inputs: &StudyInputs, rules: &StudyRules) -> Result<()> {
    let sims = if p.covered.is_empty() { HashMap::new() } else { read_sim_facts(&p.sim_path)? };
    let shots = read_shot_facts(&p.file.path, p.covered.iter().map(|c| c.row))?;
    let mut counts = FilterCounts::default();
    counts.remove_shots((p.run.shots - p.covered.len()) as u64, Filter::AlsCoverage);
    let mut rows = Vec::new();
    for (c, shot) in p.covered.iter().zip(&shots) {
        let segment =
            c.offset.as_ref().map(|o| SegmentFacts { dz: o.dz, r_after: inputs.r_after.get(&o.segment_id).copied() });
        let ctx = ShotContext {
            sim: sims.get(&shot.shot_number),
            window: als_window(&inputs.tiles, c.footprint.x, c.footprint.y),
            segment,
            forest_type: inputs.strata.get(&shot.shot_number).map(String::as_str),
        };
        select_rows(shot, &ctx, rules, &mut counts, &mut rows);
    }
    let batch = results_batch(&rows)?;
    let mut meta = results_metadata();
    meta.insert(META_INPUT.to_string(), p.results_input.clone());
    meta.insert(META_COUNTS.to_string(), counts.to_json().to_string());
    dataset::write_parquet(&p.results_path, results_schema(), &[batch], &meta)?;
    p.run.results_written = true;
    p.run.counts = counts;
    Ok(())
}

/// The facts of the `shots/` rows `rows` (ascending) of one file, in that order.
fn read_shot_facts(path: &Path, rows: impl Iterator<Item = usize>) -> Result<Vec<ShotFacts>> {
    let rows: Vec<usize> = rows.collect();
    if rows.is_empty() {
        return Ok(Vec::new());
    }
    let mut names: Vec<String> = [
        "shot_number",
        "granule",
        "beam",
        "beam_type",
        "delta_time",
        "degrade_flag",
        "leaf_off_flag",
        "selected_algorithm",
        "geoid_offset_used",
        "quality_flag",
        "sensitivity",
        "elev_lowestmode",
        "rh",
    ]
    .map(String::from)
    .to_vec();
    for n in 1..=6 {
        names.extend([
            format!("quality_flag_a{n}"),
            format!("sensitivity_a{n}"),
            format!("elev_lowestmode_a{n}"),
            format!("rh_a{n}"),
        ]);
    }
    let names: Vec<&str> = names.iter().map(String::as_str).collect();
    let mut out = Vec::with_capacity(rows.len());
    read::for_each_batch(path, Some(&names), Some(&rows), |c| {
        for i in 0..c.num_rows() {
            let alg = |suffix: &str| -> Result<AlgorithmFacts> {
                Ok(AlgorithmFacts {
                    quality_flag: c.u8(&format!("quality_flag{suffix}"), i)?,
                    sensitivity: c.f64(&format!("sensitivity{suffix}"), i)?,
                    elev_lowestmode: c.f64(&format!("elev_lowestmode{suffix}"), i)?,
                    rh: c.f32_list(&format!("rh{suffix}"), i)?,
                })
            };
            let algorithms = [alg("")?, alg("_a1")?, alg("_a2")?, alg("_a3")?, alg("_a4")?, alg("_a5")?, alg("_a6")?];
            out.push(ShotFacts {
                shot_number: c.u64("shot_number", i)?.ok_or_else(|| Error::field(path, "shot_number", "null"))?,
                granule: c.string("granule", i)?.unwrap_or_default(),
                beam: c.string("beam", i)?.unwrap_or_default(),
                beam_type: c.string("beam_type", i)?.unwrap_or_default(),
                delta_time: c.f64("delta_time", i)?,
                degrade_flag: c.u8("degrade_flag", i)?,
                leaf_off_flag: c.u8("leaf_off_flag", i)?,
                selected_algorithm: c.u8("selected_algorithm", i)?,
                geoid_offset: c.f64("geoid_offset_used", i)?,
                algorithms,
            });
        }
        Ok(())
    })?;
    if out.len() != rows.len() {
        return Err(Error::table(path, format!("read {} shots for {} rows", out.len(), rows.len())));
    }
    Ok(out)
}

/// Shot → the three weightings' simulation facts of a `sim/` file.
fn read_sim_facts(path: &Path) -> Result<HashMap<u64, [SimFacts; 3]>> {
    let columns = ["footprint_id", "weighting", "status", "als_ground", "slope_deg", "als_cover", "rh"];
    let mut out: HashMap<u64, [SimFacts; 3]> = HashMap::new();
    read::for_each_batch(path, Some(&columns), None, |c| {
        for i in 0..c.num_rows() {
            let id = c.string("footprint_id", i)?.unwrap_or_default();
            let sn: u64 =
                id.parse().map_err(|_| Error::field(path, "footprint_id", format!("`{id}` is not a shot number")))?;
            let w = c.string("weighting", i)?.unwrap_or_default();
            let Some(k) = WEIGHTINGS.iter().position(|x| *x == w) else {
                return Err(Error::field(path, "weighting", format!("`{w}` is not count, frac or int")));
            };
            out.entry(sn).or_default()[k] = SimFacts {
                ok: c.string("status", i)?.as_deref() == Some("ok"),
                als_ground: c.f64("als_ground", i)?,
                slope_deg: c.f64("slope_deg", i)?,
                als_cover: c.f64("als_cover", i)?,
                rh: c.f32_list("rh", i)?,
            };
        }
        Ok(())
    })?;
    Ok(out)
}
