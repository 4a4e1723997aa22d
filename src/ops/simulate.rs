//! `gedisim simulate`: the simulation kernels driven from files — direct mode (LAS/LAZ files and
//! a footprint CSV) and dataset mode (every ingested shot, or a footprint CSV such as inventory
//! plots, against the `als/` table) — or from points already in memory (the Python API).

use std::borrow::Cow;
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow::record_batch::RecordBatch;
use datafusion::prelude::SessionContext;

use crate::dataset::als::DROPPED_CLASSES;
use crate::dataset::offsets::AppliedOffset;
use crate::dataset::sim::{col as sim_col, sim_batch, sim_metadata, sim_schema, STATUS_OK};
use crate::dataset::{self, tables, AtomicParquet, Dataset};
use crate::error::{Error, Result};
use crate::io::copc::{Attributes, CopcRead, CopcTile};
use crate::io::footprints::{Coordinates, FootprintTable};
use crate::kernels::geo::cells::Cells;
use crate::kernels::geo::projection::Projector;
use crate::kernels::sim::{
    self, AlsPoints, DensityCount, Footprint, Profile, PulseModel, PulseTiming, SimConfig, Weighting,
};
use crate::ops::progress::{Progress, Step};
use crate::sql::blocks::{blocks, BlockSimulation};
use crate::sql::simulate::{FootprintPartition, SimulatedShots};
pub use crate::sql::Engine;

/// What `gedisim simulate` reads and where it writes.
#[derive(Debug, Clone)]
pub enum Source {
    /// Direct mode: LAS/LAZ files (folders expanded) and a footprint CSV, into `out`. With the
    /// `default` profile the classes the ingest drops are dropped too, unless `keep_all_classes`.
    /// A COPC file is read only around the footprints ([`read_around`]).
    Direct { als: Vec<PathBuf>, footprints: PathBuf, out: PathBuf, keep_all_classes: bool },
    /// Dataset mode: every ingested shot (moved by its collocation offset) into
    /// `<dataset>/simulated/shots.parquet`, or the `footprints` CSV into `out` (default
    /// `<dataset>/simulated/<CSV name>.parquet`). Never into `sim/`, which `run` writes.
    Dataset { dataset: PathBuf, footprints: Option<PathBuf>, out: Option<PathBuf> },
    /// Points already in memory (the Python API's points table, `dataset::als::points_from_batches`)
    /// in EPSG `epsg` (`None`: a frame of their own), and a footprint CSV, into `out`; the classes
    /// the ingest drops are dropped as in direct mode.
    Points { points: Arc<AlsPoints>, epsg: Option<u32>, footprints: PathBuf, out: PathBuf, keep_all_classes: bool },
}

/// Options of `gedisim simulate`.
#[derive(Debug, Clone)]
pub struct SimulateOptions {
    pub source: Source,
    pub profile: Profile,
    /// Footprint Gaussian σ (m).
    pub fsigma: f32,
    pub normalise_density: bool,
    /// What the density normalisation counts (gediRat's last returns, or pulses).
    pub density_count: DensityCount,
    /// Convolve each return with the pulse while binning instead of after.
    pub pulse_before: bool,
    pub pulse: PulseModel,
    /// Dataset mode: where the simulation runs (here, or as one plan on a cluster).
    pub engine: Engine,
    /// EPSG code of a footprint CSV's x, y (`--crs`; lon, lat columns are EPSG:4326 by name).
    pub footprints_crs: Option<u32>,
}

impl SimulateOptions {
    /// The command line's defaults for `source`: the `default` profile, GEDI's σ_f 5.5 m, the
    /// density normalised by last returns, the study's 15 ns Gaussian pulse after binning, here.
    pub fn new(source: Source) -> Self {
        let cfg = SimConfig::new(Profile::Default);
        SimulateOptions {
            source,
            profile: Profile::Default,
            fsigma: cfg.fsigma,
            normalise_density: cfg.normalise_density,
            density_count: cfg.density_count,
            pulse_before: false,
            pulse: PulseModel::Gaussian(None),
            engine: Engine::Local,
            footprints_crs: None,
        }
    }
}

/// What `gedisim simulate` did.
#[derive(Debug, Clone)]
pub struct SimulateReport {
    pub simulated: usize,
    pub skipped: usize,
    pub out: PathBuf,
    /// How a footprint CSV's positions were put in the ALS CRS ([`place_footprints`]).
    pub placement: Option<String>,
    /// Direct mode from COPC tiles: what their reads decoded, summed.
    pub copc: Option<CopcRead>,
    /// Direct mode: footprints whose centre no file's header bounds hold (their status is
    /// `no_points`, or the points of a neighbouring file).
    pub outside_files: usize,
}

/// The LAS/LAZ files of direct mode (folders expanded), each opened once: its header facts and, for
/// a COPC tile, its octree. Files that record a CRS must record the same.
pub struct AlsInputs {
    files: Vec<(PathBuf, Option<CopcTile>, crate::io::las::TileHeader)>,
    /// The CRS the files record (all the same), if any does.
    epsg: Option<u32>,
}

impl AlsInputs {
    pub fn open(als: &[PathBuf]) -> Result<Self> {
        let paths = crate::ops::ingest_als::expand_inputs(als)?;
        if paths.is_empty() {
            return Err(Error::Usage("--als: no LAS/LAZ file found in the inputs".into()));
        }
        let mut crs: Option<(u32, &Path)> = None;
        let mut files = Vec::with_capacity(paths.len());
        for f in &paths {
            let tile = CopcTile::open_if_copc(f)?;
            let header = match &tile {
                Some(t) => t.header().clone(),
                None => crate::io::las::read_header(f)?,
            };
            match (header.epsg, crs) {
                (Some(e), Some((first, at))) if e != first => {
                    let why = format!("EPSG:{e} differs from EPSG:{first} of {}", at.display());
                    return Err(Error::field(f, "CRS", why));
                }
                (Some(e), None) => crs = Some((e, f)),
                _ => {}
            }
            files.push((f.clone(), tile, header));
        }
        Ok(AlsInputs { files, epsg: crs.map(|c| c.0) })
    }

    /// Whether every file is a COPC tile (read in windows, so that footprints can be taken a tile
    /// at a time without reading a file whole more than once).
    fn all_copc(&self) -> bool {
        self.files.iter().all(|(_, t, _)| t.is_some())
    }

    /// The first file whose header bounds hold (x, y).
    fn file_holding(&self, x: f64, y: f64) -> Option<usize> {
        let holds = |b: &[f64; 6]| (b[0]..=b[3]).contains(&x) && (b[1]..=b[4]).contains(&y);
        self.files.iter().position(|(_, _, h)| holds(&h.bounds))
    }

    /// How many of `footprints` no file's header bounds hold.
    pub fn outside(&self, footprints: &[Footprint]) -> usize {
        footprints.iter().filter(|f| self.file_holding(f.x, f.y).is_none()).count()
    }

    /// Footprint indices grouped by the first file whose extent holds their centre (then those
    /// no file holds), in footprint order within a group.
    fn group_by_tile(&self, footprints: &[Footprint]) -> Vec<Vec<usize>> {
        let mut groups = vec![Vec::new(); self.files.len() + 1];
        for (i, f) in footprints.iter().enumerate() {
            groups[self.file_holding(f.x, f.y).unwrap_or(self.files.len())].push(i);
        }
        groups.retain(|g| !g.is_empty());
        groups
    }

    /// The points that `footprints` need under `cfg`: a COPC tile is read only in the cells within
    /// the read radius of a footprint, without the pulse identity unless the density is counted by
    /// pulse (`read` adds what it decoded); any other file is read whole, if a footprint's cells
    /// meet its extent. With `drop_classes`, the classes the ingest drops are dropped file by file.
    fn read_around(
        &self,
        footprints: &[Footprint],
        cfg: &SimConfig,
        drop_classes: bool,
        read: &mut CopcRead,
    ) -> Result<AlsPoints> {
        let cells = Cells::around(footprints.iter().map(|f| (f.x, f.y)), sim::footprint::read_radius(cfg.fsigma));
        let attributes = if cfg.counts_pulses() { Attributes::All } else { Attributes::WithoutPulseIdentity };
        let mut points = AlsPoints::default();
        for (f, tile, header) in &self.files {
            let b = header.bounds;
            let mine = cells.within([b[0], b[1], b[3], b[4]]);
            if mine.is_empty() {
                continue;
            }
            let mut p = match tile {
                Some(t) => {
                    let (p, r) = t.read(Some(&mine), attributes)?;
                    // The tile's totals are counted once, by `copc_totals`.
                    read.add(&CopcRead { nodes_in_tile: 0, points_in_tile: 0, ..r });
                    p
                }
                None => {
                    let p = crate::io::las::read_points(f)?;
                    warn_beyond_bounds(f, &p, &b);
                    p
                }
            };
            if drop_classes {
                p.permute(&kept_by_ingest(&p));
            }
            if points.is_empty() {
                points = p;
            } else {
                points.extend_from(&p);
            }
        }
        Ok(points)
    }

    /// What the COPC tiles hold (nodes and points), with nothing decoded yet; `None` without one.
    fn copc_totals(&self) -> Option<CopcRead> {
        let mut total = None::<CopcRead>;
        for (_, tile, header) in &self.files {
            if let Some(t) = tile {
                let r = CopcRead {
                    nodes_in_tile: t.node_count(),
                    points_in_tile: header.number_of_points,
                    ..Default::default()
                };
                total.get_or_insert_default().add(&r);
            }
        }
        total
    }
}

/// How far (m) points may lie outside their file's header bounds before it is said.
const BOUNDS_SLACK_M: f64 = 1.0;

/// Warn when the points of `file` reach beyond its header `bounds` (a header that was not
/// rewritten after its points were moved): direct mode finds a file's points by its header, so
/// footprints there would come out `no_points`; `ingest als` takes the points' own extent.
fn warn_beyond_bounds(file: &Path, p: &AlsPoints, bounds: &[f64; 6]) {
    let extent = |v: &[f64]| v.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| (lo.min(x), hi.max(x)));
    let ((x0, x1), (y0, y1)) = (extent(&p.x), extent(&p.y));
    let beyond = [bounds[0] - x0, x1 - bounds[3], bounds[1] - y0, y1 - bounds[4]].into_iter().fold(0f64, f64::max);
    if beyond > BOUNDS_SLACK_M {
        tracing::warn!(
            "{}: bounds: points reach {beyond:.1} m beyond the header's bounds (x {x0:.1}–{x1:.1}, y {y0:.1}–{y1:.1}; \
             header x {:.1}–{:.1}, y {:.1}–{:.1}): footprints there may come out no_points; rewrite the header, or \
             `gedisim ingest als` (it takes the points' extent)",
            file.display(),
            bounds[0],
            bounds[3],
            bounds[1],
            bounds[4]
        );
    }
}

/// The simulator settings of `opts` (profile, footprint, density normalisation, pulse).
pub fn sim_config(opts: &SimulateOptions) -> Result<SimConfig> {
    let max = sim::footprint::MAX_SIGMA_M;
    if !(opts.fsigma.is_finite() && opts.fsigma > 0.0 && opts.fsigma <= max) {
        let why = format!("{} m: give a finite σ above 0 and at most {max} m", opts.fsigma);
        return Err(Error::Usage(format!("--fsigma: {why}")));
    }
    if opts.profile == Profile::Gedirat && opts.normalise_density && opts.density_count == DensityCount::Pulses {
        return Err(Error::Usage(
            "--density pulses is not gediRat's normalisation: use it with --profile default".into(),
        ));
    }
    let mut cfg = SimConfig::new(opts.profile);
    cfg.fsigma = opts.fsigma;
    cfg.normalise_density = opts.normalise_density;
    cfg.density_count = opts.density_count;
    if opts.pulse_before {
        cfg.pulse_timing = PulseTiming::BeforeBinning;
    }
    // Recorded pulses are attached to each footprint (`attach_recorded_pulses`); the Gaussian
    // stays for a footprint that gets none.
    if let Some(p) = crate::io::pulse::fixed_pulse(&opts.pulse, cfg.res)? {
        cfg.pulse = p;
    }
    Ok(cfg)
}

/// A footprint CSV's positions in the ALS CRS `als_epsg`, and one line saying how they were
/// placed. lon, lat columns (or x, y with `crs` 4326) are WGS84 degrees and projected; x, y are in `crs` when given
/// (reprojected when it differs), else taken in the ALS CRS — and the line says so. A position
/// whose CRS cannot be known (lon, lat or `crs` over tiles that record no CRS) is an error.
pub fn place_footprints(
    table: &FootprintTable,
    crs: Option<u32>,
    als_epsg: Option<u32>,
    csv: &Path,
) -> Result<(Vec<Footprint>, String)> {
    let n = table.rows.len();
    let at = |rows: Vec<(String, f64, f64)>| rows.into_iter().map(|(id, x, y)| Footprint::at(id, x, y)).collect();
    let reproject = |from: Option<u32>, to: u32| -> Result<Vec<Footprint>> {
        let target = Projector::new(to).map_err(|e| Error::field(csv, "CRS", format!("the ALS tiles' CRS: {e}")))?;
        let source = from.map(Projector::new).transpose().map_err(|e| Error::field(csv, "--crs", e))?;
        let mut out = Vec::with_capacity(n);
        for (id, a, b) in &table.rows {
            let lonlat = match &source {
                Some(s) => s.unproject(*a, *b),
                None => Ok((*a, *b)),
            };
            let (x, y) = lonlat
                .and_then(|(lon, lat)| target.project(lon, lat))
                .map_err(|e| Error::field(csv, format!("footprint `{id}`"), e))?;
            out.push(Footprint::at(id.clone(), x, y));
        }
        Ok(out)
    };
    let unknown = |what: &str| {
        Error::field(csv, "CRS", format!("{what}, but the ALS tiles record no CRS: give x, y in the tiles' own frame"))
    };
    // x, y said to be WGS84 degrees (--crs 4326) are lon, lat.
    let coordinates = if crs == Some(4326) { Coordinates::LonLat } else { table.coordinates };
    match (coordinates, crs, als_epsg) {
        (Coordinates::LonLat, Some(c), _) if c != 4326 => {
            Err(Error::field(csv, "CRS", format!("lon, lat columns are WGS84 degrees (EPSG:4326), not EPSG:{c}")))
        }
        (Coordinates::LonLat, _, Some(to)) => {
            Ok((reproject(None, to)?, format!("{n} footprints: lon, lat (WGS84) projected to the ALS CRS EPSG:{to}")))
        }
        (Coordinates::LonLat, _, None) => Err(unknown("lon, lat (WGS84) positions")),
        (Coordinates::Projected, Some(c), Some(to)) if c != to => Ok((
            reproject(Some(c), to)?,
            format!("{n} footprints: x, y in EPSG:{c} reprojected to the ALS CRS EPSG:{to}"),
        )),
        (Coordinates::Projected, Some(c), None) => Err(unknown(&format!("--crs {c}"))),
        (Coordinates::Projected, Some(_), Some(to)) => {
            Ok((at(table.rows.clone()), format!("{n} footprints: x, y in EPSG:{to}, the ALS CRS")))
        }
        (Coordinates::Projected, None, Some(to)) => Ok((
            at(table.rows.clone()),
            format!("{n} footprints: x, y taken in the ALS CRS EPSG:{to} (the CSV does not say; --crs to give theirs)"),
        )),
        (Coordinates::Projected, None, None) => Ok((
            at(table.rows.clone()),
            format!(
                "{n} footprints: x, y taken in the ALS tiles' own frame (neither the CSV nor the tiles name a CRS)"
            ),
        )),
    }
}

/// `gedisim simulate`: direct or dataset mode (see [`Source`]); dataset mode streams in blocks
/// as one [`Step::Simulate`].
pub fn simulate(opts: &SimulateOptions, progress: &dyn Progress) -> Result<SimulateReport> {
    let cfg = sim_config(opts)?;
    let profile = opts.profile;
    let mut copc = None;
    let mut placement = None;
    let mut outside_files = 0;
    let ((simulated, skipped), out) = match &opts.source {
        Source::Dataset { dataset, footprints, out } => {
            // Dataset mode writes sim/ (or a table of footprints) into the dataset.
            let ds = Dataset::open(dataset)?.as_writer()?;
            let from_csv = footprints.is_some();
            let (mut footprints, dest) = match footprints {
                Some(csv) => {
                    let stem = csv.file_stem().and_then(|s| s.to_str()).unwrap_or("footprints");
                    let dest = match out {
                        Some(out) => {
                            crate::dataset::outside_tables(out)?;
                            out.clone()
                        }
                        None => ds.table_file(tables::SIMULATED, stem)?,
                    };
                    let table = crate::io::footprints::read_footprints_csv(csv)?;
                    let (placed, how) =
                        place_footprints(&table, opts.footprints_crs, crate::dataset::dataset_epsg(&ds)?, csv)?;
                    placement = Some(how);
                    (placed.into_iter().map(|f| (f, None)).collect(), dest)
                }
                None if out.is_some() => return Err(Error::Usage("--out in dataset mode needs --footprints".into())),
                None => (crate::dataset::shots::shot_footprints(&ds)?, ds.table_file(tables::SIMULATED, "shots")?),
            };
            if let PulseModel::Recorded(reference) = opts.pulse {
                let pulses = crate::sql::pulses::shot_pulses(&ds, reference, cfg.res)?;
                let mean = attach_recorded_pulses(&mut footprints, &pulses).ok_or_else(|| {
                    Error::file(
                        ds.root(),
                        "--pulse recorded: no shot of the dataset has a usable transmit waveform (tx_waveform)",
                    )
                })?;
                if let Some(note) = pulses.note() {
                    progress.note(&note);
                }
                // Positions without a shot (a footprint CSV) use the mean pulse: written beside the output.
                if from_csv {
                    let file = dest.with_extension("pulse.txt");
                    let text = mean.to_text(&format!(
                        "mean recorded GEDI transmit pulse of {} shots, reference {reference}; \
                         x = range (m) after the reference point, y = weight",
                        pulses.by_shot.len()
                    ));
                    dataset::write_atomic(&file, text.as_bytes())?;
                    progress.note(&format!("mean recorded pulse written to {}", file.display()));
                }
            }
            progress.start(Step::Simulate, footprints.len() as u64);
            let r = match &opts.engine {
                Engine::Local => simulate_on_dataset(&ds, footprints, &cfg, profile, &dest, progress),
                engine => simulate_dataset_on(engine, &ds, footprints, &cfg, profile, &dest),
            };
            progress.finish();
            (r?, dest)
        }
        Source::Direct { .. } | Source::Points { .. } if matches!(opts.pulse, PulseModel::Recorded(_)) => {
            return Err(Error::Usage(
            "--pulse recorded needs the shots of a dataset (--dataset); in direct mode give a pulse file, e.g. the \
                 mean recorded pulse that `simulate --dataset … --footprints … --pulse recorded` writes"
                .into(),
            ))
        }
        Source::Direct { .. } | Source::Points { .. } if opts.engine != Engine::Local => {
            return Err(Error::Usage("--cluster: a cluster simulates from a dataset (--dataset)".into()))
        }
        Source::Direct { als, footprints, out, keep_all_classes } => {
            crate::dataset::outside_tables(out)?;
            let table = crate::io::footprints::read_footprints_csv(footprints)?;
            let inputs = AlsInputs::open(als)?;
            let (footprints, how) = place_footprints(&table, opts.footprints_crs, inputs.epsg, footprints)?;
            placement = Some(how);
            let drop_classes = profile == Profile::Default && !keep_all_classes;
            outside_files = inputs.outside(&footprints);
            let (counts, read) = simulate_direct(&inputs, &footprints, &cfg, profile, drop_classes, out, progress)?;
            copc = read;
            (counts, out.clone())
        }
        Source::Points { points, epsg, footprints, out, keep_all_classes } => {
            crate::dataset::outside_tables(out)?;
            let table = crate::io::footprints::read_footprints_csv(footprints)?;
            let (footprints, how) = place_footprints(&table, opts.footprints_crs, *epsg, footprints)?;
            placement = Some(how);
            let points = if profile == Profile::Default && !keep_all_classes {
                Cow::Owned(drop_ingest_classes(points))
            } else {
                Cow::Borrowed(points.as_ref())
            };
            let props = dataset::writer_properties(&sim_metadata(profile), SIM_ROW_GROUP_ROWS);
            let mut writer = AtomicParquet::create(out, sim_schema(), props)?;
            progress.start(Step::Simulate, footprints.len() as u64);
            let counts = write_simulated(points, &footprints, &cfg, &mut writer, progress)?;
            progress.finish();
            writer.finish()?;
            (counts, out.clone())
        }
    };
    Ok(SimulateReport { simulated, skipped, out, placement, copc, outside_files })
}

/// Give every shot footprint its recorded pulse and every other footprint (no shot, or a shot
/// without a usable record) the mean of them; returns that mean, `None` when no shot has a pulse.
pub fn attach_recorded_pulses(
    footprints: &mut [(Footprint, Option<AppliedOffset>)],
    pulses: &crate::sql::pulses::ShotPulses,
) -> Option<std::sync::Arc<sim::Pulse>> {
    let mean = std::sync::Arc::new(pulses.mean()?);
    for (f, _) in footprints.iter_mut() {
        let own = f.id.parse::<u64>().ok().and_then(|sn| pulses.by_shot.get(&sn));
        f.pulse = Some(own.cloned().unwrap_or_else(|| mean.clone()));
    }
    Some(mean)
}

/// Keep only the points whose class the ingest keeps (so that direct mode with the `default`
/// profile sees the same points as the dataset path).
pub fn drop_ingest_classes(p: &AlsPoints) -> AlsPoints {
    p.permuted(&kept_by_ingest(p))
}

/// Indices of the points whose class the ingest keeps.
fn kept_by_ingest(p: &AlsPoints) -> Vec<u32> {
    (0..p.len() as u32).filter(|&i| !DROPPED_CLASSES.contains(&p.classification[i as usize])).collect()
}

/// Footprints simulated at a time in direct mode: their rows are written before the next are
/// simulated, so memory holds one chunk's waveforms (≈ 70 KB a footprint), not every footprint's.
const DIRECT_CHUNK: usize = 1024;

/// Rows of a `sim` file's row group (three per footprint): what the Parquet writer holds.
const SIM_ROW_GROUP_ROWS: usize = 1 << 14;

/// Direct mode: simulate `footprints` on the points of `inputs` (without the classes the ingest
/// drops if `drop_classes`) and write the `sim` rows to `out` (atomically) as they come, a chunk of
/// footprints at a time. COPC tiles are taken a tile at a time (the footprints whose centre a tile
/// holds, with the points of every tile around them), so that memory holds one tile's windows, not
/// all of them: the rows come tile after tile, in footprint order within a tile. Other files are
/// read once, whole, and the rows come in footprint order. Returns the numbers of footprints
/// simulated and skipped, and what the COPC reads decoded.
pub fn simulate_direct(
    inputs: &AlsInputs,
    footprints: &[Footprint],
    cfg: &SimConfig,
    profile: Profile,
    drop_classes: bool,
    out: &Path,
    progress: &dyn Progress,
) -> Result<((usize, usize), Option<CopcRead>)> {
    let groups =
        if inputs.all_copc() { inputs.group_by_tile(footprints) } else { vec![(0..footprints.len()).collect()] };
    let mut read = CopcRead::default();
    let props = dataset::writer_properties(&sim_metadata(profile), SIM_ROW_GROUP_ROWS);
    let mut writer = AtomicParquet::create(out, sim_schema(), props)?;
    let (mut ok, mut skipped) = (0, 0);
    progress.start(Step::Simulate, footprints.len() as u64);
    for group in groups {
        let fps: Vec<Footprint> = group.iter().map(|&i| footprints[i].clone()).collect();
        let points = inputs.read_around(&fps, cfg, drop_classes, &mut read)?;
        let (o, s) = write_simulated(Cow::Owned(points), &fps, cfg, &mut writer, progress)?;
        ok += o;
        skipped += s;
    }
    progress.finish();
    writer.finish()?;
    let copc = inputs.copc_totals().map(|mut t| {
        t.add(&read);
        t
    });
    Ok(((ok, skipped), copc))
}

/// Simulate `footprints` on `points` a chunk of [`DIRECT_CHUNK`] at a time, each chunk's `sim`
/// rows written to `writer` before the next is simulated; returns the numbers of footprints
/// simulated and skipped. `progress` advances by each chunk's footprints.
fn write_simulated(
    points: Cow<AlsPoints>,
    footprints: &[Footprint],
    cfg: &SimConfig,
    writer: &mut AtomicParquet,
    progress: &dyn Progress,
) -> Result<(usize, usize)> {
    let (mut ok, mut skipped) = (0, 0);
    sim::simulate_in_chunks::<crate::Error>(points, footprints, cfg, DIRECT_CHUNK, &mut |start, results| {
        let n_ok = results.iter().filter(|r| r.is_ok()).count();
        ok += n_ok;
        skipped += results.len() - n_ok;
        writer.write(&sim_batch(&footprints[start..start + results.len()], &results, &Weighting::STUDY, &[])?)?;
        progress.advance(results.len() as u64);
        Ok(())
    })?;
    Ok((ok, skipped))
}

/// Simulate `footprints` (each with the collocation offset already applied to it, if any) on the
/// dataset's `als/` table into `dest` (atomically), block by block (see [`BlockSimulation`]).
/// `progress` advances by the footprints of each block.
pub fn simulate_on_dataset(
    ds: &Dataset,
    footprints: Vec<(Footprint, Option<AppliedOffset>)>,
    cfg: &SimConfig,
    profile: Profile,
    dest: &Path,
    progress: &dyn Progress,
) -> Result<(usize, usize)> {
    simulate_on_dataset_with(ds, footprints, cfg, profile, dest, &HashMap::new(), progress)
}

/// [`simulate_on_dataset`] with `extra` key-value metadata in the written file (beside the
/// profile and bin-label keys): `run` records there what the file was made from.
pub fn simulate_on_dataset_with(
    ds: &Dataset,
    footprints: Vec<(Footprint, Option<AppliedOffset>)>,
    cfg: &SimConfig,
    profile: Profile,
    dest: &Path,
    extra: &HashMap<String, String>,
    progress: &dyn Progress,
) -> Result<(usize, usize)> {
    let mut metadata = sim_metadata(profile);
    metadata.extend(extra.iter().map(|(k, v)| (k.clone(), v.clone())));
    let mut writer =
        AtomicParquet::create(dest, sim_schema(), dataset::writer_properties(&metadata, SIM_ROW_GROUP_ROWS))?;
    let (mut ok, mut skipped) = (0, 0);
    for block in BlockSimulation::new(ds, footprints, cfg.clone())? {
        let block = block?;
        let n_ok = block.results.iter().filter(|r| r.is_ok()).count();
        ok += n_ok;
        skipped += block.results.len() - n_ok;
        writer.write(&block.batch()?)?;
        progress.advance(block.footprints.len() as u64);
    }
    writer.finish()?;
    Ok((ok, skipped))
}

/// [`simulate_on_dataset`] as one plan on `engine` ([`simulate_groups`]): the same file.
fn simulate_dataset_on(
    engine: &Engine,
    ds: &Dataset,
    footprints: FootprintPartition,
    cfg: &SimConfig,
    profile: Profile,
    dest: &Path,
) -> Result<(usize, usize)> {
    if *cfg != SimConfig::new(profile) || footprints.iter().any(|(f, _)| f.pulse.is_some()) {
        return Err(Error::Usage(format!(
            "--cluster: a cluster simulates with the {} profile's settings only (no --pulse, --psigma, --fsigma, \
             --density, --no-norm or --pulse-before)",
            profile.name()
        )));
    }
    let rt = crate::sql::runtime()?;
    let batch = rt.block_on(async {
        let ctx = crate::sql::session_on(ds, &Default::default(), engine).await?;
        simulate_groups(&ctx, ds, vec![footprints], profile).await
    })?;
    dataset::write_parquet(dest, sim_schema(), &batch, &sim_metadata(profile))?;
    status_counts(dest, &batch[0])
}

/// Footprints per partition of a distributed simulation (whole blocks, so at least one block).
const PARTITION_FOOTPRINTS: usize = 256;

/// The `sim` rows of each of `groups`, simulated as one plan on `ctx`'s engine (a cluster): a
/// partition per run of whole blocks ([`blocks`]) of one group, about [`PARTITION_FOOTPRINTS`]
/// footprints each. The rows come back in any order; each group's are returned in the order a
/// local simulation writes them (block by block), as one batch. Footprints ids must be unique.
pub async fn simulate_groups(
    ctx: &SessionContext,
    ds: &Dataset,
    groups: Vec<FootprintPartition>,
    profile: Profile,
) -> Result<Vec<RecordBatch>> {
    // Footprint id → (group, place in the local order).
    let mut place: HashMap<String, (usize, usize)> = HashMap::new();
    let mut partitions = Vec::new();
    let sizes: Vec<usize> = groups.iter().map(Vec::len).collect();
    for (g, footprints) in groups.into_iter().enumerate() {
        let mut part: FootprintPartition = Vec::new();
        for block in blocks(footprints) {
            for (f, _) in &block {
                if place.insert(f.id.clone(), (g, place.len())).is_some() {
                    return Err(Error::Usage(format!("footprint {} appears twice", f.id)));
                }
            }
            part.extend(block);
            if part.len() >= PARTITION_FOOTPRINTS {
                partitions.push(std::mem::take(&mut part));
            }
        }
        if !part.is_empty() {
            partitions.push(part);
        }
    }
    let failed = |e: datafusion::error::DataFusionError| {
        Error::Usage(format!("simulation on the cluster: {}", crate::error::one_line(&e.to_string())))
    };
    let shots = SimulatedShots::partitioned(ds.clone(), profile, partitions);
    let batches = ctx.read_table(Arc::new(shots)).map_err(failed)?.collect().await.map_err(failed)?;
    let mut rows: Vec<Vec<(usize, usize, usize)>> = vec![Vec::new(); sizes.len()];
    for (b, batch) in batches.iter().enumerate() {
        let ids = crate::dataset::read::Columns::new(ds.root(), batch).strings("footprint_id")?;
        for i in 0..batch.num_rows() {
            let id = ids.value(i);
            let Some(&(g, k)) = place.get(id) else {
                return Err(Error::field(ds.root(), "footprint_id", format!("the cluster returned footprint {id}")));
            };
            rows[g].push((k, b, i));
        }
    }
    for (rows, n) in rows.iter().zip(&sizes) {
        if rows.len() != n * Weighting::STUDY.len() {
            let got = rows.len() / Weighting::STUDY.len();
            return Err(Error::Usage(format!("simulation on the cluster: {got} of {n} footprints came back")));
        }
    }
    let arrays: Vec<Vec<&dyn arrow::array::Array>> =
        (0..sim_schema().fields().len()).map(|c| batches.iter().map(|b| b.column(c).as_ref()).collect()).collect();
    rows.into_iter()
        .map(|mut rows| {
            // Stable: a footprint's weightings stay in their order.
            rows.sort_by_key(|&(k, _, _)| k);
            let take: Vec<(usize, usize)> = rows.iter().map(|&(_, b, i)| (b, i)).collect();
            let columns = arrays
                .iter()
                .map(|a| arrow::compute::interleave(a, &take))
                .collect::<std::result::Result<Vec<_>, _>>()
                .map_err(|e| Error::table(ds.root(), e))?;
            RecordBatch::try_new(sim_schema(), columns).map_err(|e| Error::table(ds.root(), e))
        })
        .collect()
}

/// Footprints simulated (`status` ok) and skipped among the `sim` rows of `batch` (read from `path`).
pub fn status_counts(path: &Path, batch: &RecordBatch) -> Result<(usize, usize)> {
    let columns = crate::dataset::read::Columns::new(path, batch);
    let (ids, status) = (columns.strings(sim_col::FOOTPRINT_ID)?, columns.strings(sim_col::STATUS)?);
    let (mut all, mut ok) = (HashSet::new(), HashSet::new());
    for j in 0..batch.num_rows() {
        all.insert(ids.value(j));
        if status.value(j) == STATUS_OK {
            ok.insert(ids.value(j));
        }
    }
    Ok((ok.len(), all.len() - ok.len()))
}
