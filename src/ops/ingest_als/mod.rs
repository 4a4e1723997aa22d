//! `ingest als`: LAS/LAZ tiles into the `als/` table (points clustered by spatial cell) and the
//! `tiles/` table (one row per file).
//!
//! A COPC tile given windows (the squares around the dataset's shots) is read only there: the
//! octree nodes meeting the windows' cells are decoded, the points inside them kept, and the cells
//! read recorded with the tile. A later ingest with more shots reads only the cells still missing
//! and rewrites the tile's file with the points of both (docs/copc.md). Its points are held in
//! memory: those of the windows of one tile.
//!
//! Any other file is streamed in chunks. Points are filed by a global square cell (`CELL_SIZE_M`) and
//! spilled to a temporary file in runs sorted by cell; the Parquet file is then written cell by
//! cell, one or more row groups per cell, so that row-group statistics of x and y span one cell
//! and a bounding-box query reads only the row groups it needs. Peak memory is bounded by the
//! chunk and the largest cell, never by the file.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow::array::{
    ArrayRef, BooleanArray, Float64Array, StringArray, TimestampMicrosecondArray, UInt16Array, UInt32Array,
    UInt64Array, UInt8Array,
};
use arrow::record_batch::RecordBatch;
use rayon::prelude::*;

use crate::dataset::als::{
    self as table, als_batch, als_schema, cell_key, meta, tiles_col, tiles_schema, ReadWindow, CELL_SIZE_M,
    DROPPED_CLASSES, MAX_ROW_GROUP_ROWS,
};
use crate::dataset::shots::col as shot_col;
use crate::dataset::{self, read, tables, AtomicParquet, Dataset};
use crate::error::{Error, Result};
use crate::io::copc::{Attributes, CopcRead, CopcTile};
use crate::io::las::{read_header, TileHeader, TileReader, CHUNK_POINTS};
use crate::io::source::{self, Fetched};
use crate::kernels::geo::cells::{Cells, Windows};
use crate::kernels::sim::{self, AlsPoints, Profile, SimConfig};
use crate::ops::progress::{Progress, Step};

/// Where tiles are read (`AlsOptions::engine`).
pub use crate::sql::Engine;

mod on_cluster;
mod spill;
pub use on_cluster::stage_from_json;
use spill::{Run, SpillFile, SpillReader};

/// Options of `ingest als`.
#[derive(Debug, Clone, Default)]
pub struct AlsOptions {
    /// Keep classes 7, 18 and 64–67.
    pub keep_all_classes: bool,
    /// CRS for tiles that carry none; must agree with tiles that do.
    pub epsg: Option<u32>,
    /// Where COPC tiles are read: only the nodes meeting these windows are decoded and only the
    /// points inside their cells kept. `None`: every tile is read whole.
    pub windows: Option<Windows>,
    /// Where tiles are read: here, or a partition each on a cluster (`run --cluster`).
    pub engine: Engine,
}

/// Half-width (m) of the window a shot needs for `run`: the collocation's largest shift plus the
/// simulator's read radius at the study's footprint width.
pub fn run_window_half(max_shift: f64) -> f64 {
    max_shift + sim::footprint::read_radius(SimConfig::new(Profile::Default).fsigma)
}

/// The windows of half-width `half` around every shot of the dataset (`None` without shots).
pub fn shot_windows(ds: &Dataset, half: f64) -> Result<Option<Windows>> {
    let dir = ds.root().join(tables::SHOTS);
    let files = dataset::table_files(&dir).unwrap_or_default();
    if files.is_empty() {
        return Ok(None);
    }
    let mut centres = Vec::new();
    for f in files {
        read::for_each_batch(&f, Some(&[shot_col::X, shot_col::Y]), None, |c| {
            for i in 0..c.num_rows() {
                if let (Some(x), Some(y)) = (c.f64(shot_col::X, i)?, c.f64(shot_col::Y, i)?) {
                    centres.push((x, y));
                }
            }
            Ok(())
        })?;
    }
    Ok(Some(Windows::new(centres, half)))
}

/// The key of a tile's content: SHA-256 of a local file's bytes, or, for a remote object, of its
/// URL, size and version ([`source::Remote::content_key`]: its bytes are not read for this).
fn content_key(input: &Path) -> Result<String> {
    match source::remote(input)? {
        Some(remote) => Ok(remote.content_key()),
        None => dataset::content_hash(input),
    }
}

/// What was fetched from each remote input (`https://…`, `s3://…`) read so far in this process.
pub fn remote_reads(inputs: &[PathBuf]) -> Vec<(&Path, Fetched)> {
    inputs.iter().filter_map(|i| source::fetched(i).map(|f| (i.as_path(), f))).collect()
}

/// The CRS (EPSG) recorded by the first of the LAS/LAZ files of `inputs` that records one.
pub fn inputs_epsg(inputs: &[PathBuf]) -> Result<Option<u32>> {
    for f in expand_inputs(inputs)? {
        if let Some(epsg) = read_header(&f)?.epsg {
            return Ok(Some(epsg));
        }
    }
    Ok(None)
}

/// What happened to one input file.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub enum TileOutcome {
    /// Points written (`window`: a COPC tile read in windows; `points` and `dropped` count the
    /// points of the cells read this time).
    ///
    /// `odd_returns`: points of the tile whose return number is 0 or above their number of returns
    /// (the simulation takes each as the last return of its pulse; `sim::density::is_last_return`).
    Ingested { tile: String, points: u64, dropped: u64, odd_returns: u64, window: Option<WindowRead> },
    /// The same content was ingested before (keyed by content hash).
    AlreadyIngested { tile: String },
}

/// What a read of a COPC tile in windows did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct WindowRead {
    /// Cells read this time, and read so far (this time included).
    pub cells_new: usize,
    pub cells_read: usize,
    /// What the COPC read decoded.
    pub copc: CopcRead,
}

/// Expand folders into the LAS/LAZ files they contain (sorted); files are kept as given.
pub fn expand_inputs(inputs: &[PathBuf]) -> Result<Vec<PathBuf>> {
    crate::io::expand_inputs(inputs, |f| crate::io::has_extension(f, "las") || crate::io::has_extension(f, "laz"))
}

/// `gedisim ingest als`: the LAS/LAZ files of `inputs` (folders expanded) into `dataset`, as one
/// [`Step::IngestAls`] counted in points.
pub fn ingest(
    dataset: &Dataset,
    inputs: &[PathBuf],
    opts: &AlsOptions,
    progress: &dyn Progress,
) -> Result<Vec<TileOutcome>> {
    let dataset = &dataset.as_writer()?;
    let files = expand_inputs(inputs)?;
    if files.is_empty() {
        return Err(Error::Usage("no LAS/LAZ file found in the inputs".into()));
    }
    progress.start(Step::IngestAls, 0);
    let outcomes = ingest_tiles(dataset, &files, opts, progress);
    progress.finish();
    outcomes
}

/// Ingest `files` into `dataset`, several files in parallel. Every header is read and checked
/// first, and one call brings one CRS, that of the dataset if it has one: nothing is written
/// otherwise. `progress` gets the total points, then advances by the points decoded.
pub fn ingest_tiles(
    dataset: &Dataset,
    files: &[PathBuf],
    opts: &AlsOptions,
    progress: &dyn Progress,
) -> Result<Vec<TileOutcome>> {
    let dataset = &dataset.as_writer()?;
    let existing = dataset::dataset_epsg(dataset)?;
    let mut headers: Vec<TileHeader> = Vec::with_capacity(files.len());
    let mut epsgs: Vec<u32> = Vec::with_capacity(files.len());
    for f in files {
        let header = read_header(f)?;
        let epsg = resolve_epsg(&header, opts, existing)?;
        if let Some(&first) = epsgs.first().filter(|&&first| first != epsg) {
            return Err(Error::field(
                f,
                "CRS",
                format!("EPSG:{epsg} differs from EPSG:{first} of {} in the same call", files[0].display()),
            ));
        }
        headers.push(header);
        epsgs.push(epsg);
    }
    progress.set_total(headers.iter().map(|h| h.number_of_points).sum());
    let als_dir = dataset.table_dir(tables::ALS)?;
    let tiles_dir = dataset.table_dir(tables::TILES)?;
    // The cells of each COPC tile its windows meet (`None`: read whole).
    let wanted: Vec<Option<Cells>> = headers
        .iter()
        .map(|h| {
            let b = h.bounds;
            opts.windows.as_ref().filter(|_| h.copc).map(|w| w.cells_in([b[0], b[1], b[3], b[4]]))
        })
        .collect();
    if let Engine::Cluster(_) = &opts.engine {
        let jobs = on_cluster::jobs(files, &headers, &epsgs, &wanted)?;
        return on_cluster::ingest_tiles(dataset, &jobs, opts, progress);
    }
    // Content hashes first: a file whose content appears earlier in the call is skipped like one
    // ingested before (two copies must not write the same table files at once).
    let hashes = files.par_iter().map(|f| content_key(f)).collect::<Result<Vec<_>>>()?;
    let mut seen = std::collections::HashSet::new();
    let first_copy: Vec<bool> = hashes.iter().map(|h| seen.insert(h.clone())).collect();
    // A single file gets both cores for LAZ decoding; several files run one per core.
    let parallel_decode = seen.len() == 1;
    (0..files.len())
        .into_par_iter()
        .map(|i| {
            let f = &files[i];
            if !first_copy[i] {
                progress.advance(headers[i].number_of_points);
                return Ok(TileOutcome::AlreadyIngested { tile: tile_name(f) });
            }
            let (hash, epsg) = (&hashes[i], epsgs[i]);
            let target = Target { path: f, given: f, hash, als_dir: &als_dir, tiles_dir: &tiles_dir, epsg };
            stage_tile(&target, opts, wanted[i].as_ref(), parallel_decode, progress)?.commit()
        })
        .collect()
}

/// Read one tile into its files, written under temporary names: the cells `wanted` of a COPC tile,
/// or the whole tile.
fn stage_tile(
    t: &Target,
    opts: &AlsOptions,
    wanted: Option<&Cells>,
    parallel_decode: bool,
    progress: &dyn Progress,
) -> Result<StagedTile> {
    match wanted {
        Some(cells) => ingest_windows(t, opts, cells, progress),
        None => ingest_tile(t, opts, parallel_decode, progress),
    }
}

/// A tile's files written under temporary names, with their places (its `als/` file, then its
/// `tiles/` row: the points become visible with the row), and what the read did.
#[derive(Debug, serde::Serialize, serde::Deserialize)]
struct StagedTile {
    /// (staged, destination), in the order they are put in place; none for a tile ingested before.
    files: Vec<(PathBuf, PathBuf)>,
    outcome: TileOutcome,
}

impl StagedTile {
    fn already(tile: String) -> Self {
        StagedTile { files: Vec::new(), outcome: TileOutcome::AlreadyIngested { tile } }
    }

    /// Put its files in place, in order.
    fn commit(self) -> Result<TileOutcome> {
        for (i, (staged, dest)) in self.files.iter().enumerate() {
            if let Err(e) = dataset::place_staged(staged, dest) {
                self.files[i + 1..].iter().for_each(|(s, _)| drop(std::fs::remove_file(s)));
                return Err(e);
            }
        }
        Ok(self.outcome)
    }

    /// Remove its staged files.
    fn discard(&self) {
        self.files.iter().for_each(|(s, _)| drop(std::fs::remove_file(s)));
    }
}

fn tile_name(path: &Path) -> String {
    path.file_stem().and_then(|s| s.to_str()).unwrap_or("tile").to_string()
}

fn resolve_epsg(h: &TileHeader, opts: &AlsOptions, existing: Option<u32>) -> Result<u32> {
    let epsg = match (h.epsg, opts.epsg) {
        (Some(file), Some(given)) if file != given => {
            return Err(Error::field(&h.path, "CRS", format!("file says EPSG:{file} but --epsg {given} was given")))
        }
        (Some(file), _) => file,
        (None, Some(given)) => given,
        (None, None) if h.crs_wkt.as_deref().is_some_and(crate::io::las::is_vertical_only) => {
            let code = h.crs_wkt.as_deref().and_then(crate::io::las::epsg_from_wkt);
            let code = code.map_or(String::new(), |c| format!(" (EPSG:{c})"));
            return Err(Error::field(
                &h.path,
                "CRS",
                format!("the file's CRS is vertical only{code}: pass --epsg with its horizontal CRS"),
            ));
        }
        (None, None) => return Err(Error::field(&h.path, "CRS", "no WKT or GeoTIFF CRS record: pass --epsg")),
    };
    if let Some(ds) = existing {
        if ds != epsg {
            return Err(Error::field(&h.path, "CRS", format!("EPSG:{epsg} differs from the dataset's EPSG:{ds}")));
        }
    }
    Ok(epsg)
}

/// Running statistics of a tile's kept points.
struct TileStats {
    intensity_hist: Vec<u64>,
    bounds: [f64; 6],
    gps: [f64; 2],
    kept: u64,
    dropped: u64,
    /// Kept points whose return number is 0 or above their number of returns.
    odd_returns: u64,
}

impl TileStats {
    fn new() -> Self {
        TileStats {
            intensity_hist: vec![0; 1 << 16],
            bounds: [
                f64::INFINITY,
                f64::INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::NEG_INFINITY,
                f64::NEG_INFINITY,
            ],
            gps: [f64::INFINITY, f64::NEG_INFINITY],
            kept: 0,
            dropped: 0,
            odd_returns: 0,
        }
    }

    fn add(&mut self, p: &AlsPoints, i: usize) {
        self.intensity_hist[p.intensity[i] as usize] += 1;
        let (x, y, z) = (p.x[i], p.y[i], p.z[i]);
        self.bounds[0] = self.bounds[0].min(x);
        self.bounds[1] = self.bounds[1].min(y);
        self.bounds[2] = self.bounds[2].min(z);
        self.bounds[3] = self.bounds[3].max(x);
        self.bounds[4] = self.bounds[4].max(y);
        self.bounds[5] = self.bounds[5].max(z);
        let t = p.gps_time[i];
        if t.is_finite() {
            self.gps[0] = self.gps[0].min(t);
            self.gps[1] = self.gps[1].max(t);
        }
        self.kept += 1;
        let (rn, nr) = (p.return_number[i], p.number_of_returns[i]);
        self.odd_returns += u64::from(rn == 0 || rn > nr);
    }

    /// Intensity at cumulative fraction `q` (exact, from the histogram).
    fn intensity_quantile(&self, q: f64) -> Option<u16> {
        if self.kept == 0 {
            return None;
        }
        let target = ((q * self.kept as f64).ceil() as u64).max(1);
        let mut cum = 0;
        for (v, &c) in self.intensity_hist.iter().enumerate() {
            cum += c;
            if cum >= target {
                return Some(v as u16);
            }
        }
        None
    }

    fn intensity_mean(&self) -> Option<f64> {
        (self.kept > 0).then(|| {
            self.intensity_hist.iter().enumerate().map(|(v, &c)| v as f64 * c as f64).sum::<f64>() / self.kept as f64
        })
    }
}

/// One input file and where its rows go.
struct Target<'a> {
    /// Where the file is read.
    path: &'a Path,
    /// The file as it was given: the tile's name and the `path` of its `tiles/` row (a cluster's
    /// executor reads it at its absolute path).
    given: &'a Path,
    hash: &'a str,
    als_dir: &'a Path,
    tiles_dir: &'a Path,
    epsg: u32,
}

impl Target<'_> {
    fn key(&self) -> &str {
        &self.hash[..16]
    }

    fn als_file(&self) -> PathBuf {
        self.als_dir.join(format!("{}.parquet", self.key()))
    }

    fn tiles_file(&self) -> PathBuf {
        self.tiles_dir.join(format!("{}.parquet", self.key()))
    }

    /// The key-value metadata of the tile's `als/` and `tiles/` files.
    fn metadata(&self, header: &TileHeader, window: Option<&ReadWindow>) -> HashMap<String, String> {
        let mut m = HashMap::new();
        m.insert(meta::EPSG.to_string(), self.epsg.to_string());
        m.insert(meta::CELL_SIZE.to_string(), CELL_SIZE_M.to_string());
        m.insert(meta::VERTICAL.to_string(), "as stored in the LAS file (IGN69 for LiDAR HD)".to_string());
        if let Some(wkt) = &header.crs_wkt {
            m.insert(meta::CRS_WKT.to_string(), wkt.clone());
        }
        // Every tile's header extent (a window's metadata repeats it): the GEDI ingest's default area.
        let b = header.bounds;
        m.insert(meta::TILE_EXTENT.to_string(), format!("{} {} {} {}", b[0], b[1], b[3], b[4]));
        m.extend(window.map(ReadWindow::metadata).into_iter().flatten());
        m
    }

    /// The tile staged: its `als/` file written at `als` and its `tiles/` row (put in place after
    /// the `als/` file: the points become visible with it).
    fn staged(
        &self,
        als: PathBuf,
        header: &TileHeader,
        stats: &TileStats,
        window: Option<&ReadWindow>,
        metadata: &HashMap<String, String>,
        outcome: TileOutcome,
    ) -> Result<StagedTile> {
        let row = tiles_batch(header, self.given, self.hash, self.epsg, stats, window)
            .and_then(|batch| dataset::stage_parquet(&self.tiles_file(), tiles_schema(), &[batch], metadata))
            .and_then(|w| w.finish_staged());
        match row {
            Ok(row) => Ok(StagedTile { files: vec![(als, self.als_file()), (row, self.tiles_file())], outcome }),
            Err(e) => {
                let _ = std::fs::remove_file(&als);
                Err(e)
            }
        }
    }
}

/// Whether point `i` of `chunk` is kept (its class not dropped); its coordinates must be finite.
fn keep_point(path: &Path, chunk: &AlsPoints, i: usize, opts: &AlsOptions, stats: &mut TileStats) -> Result<bool> {
    if !opts.keep_all_classes && DROPPED_CLASSES.contains(&chunk.classification[i]) {
        stats.dropped += 1;
        return Ok(false);
    }
    for (name, v) in [(table::col::X, chunk.x[i]), (table::col::Y, chunk.y[i]), (table::col::Z, chunk.z[i])] {
        if !v.is_finite() {
            return Err(Error::field(
                path,
                name,
                format!("non-finite coordinate {v} at point {}", stats.kept + stats.dropped),
            ));
        }
    }
    stats.add(chunk, i);
    Ok(true)
}

/// Write one cell's points as row groups of at most [`MAX_ROW_GROUP_ROWS`].
fn write_cell(writer: &mut AtomicParquet, points: AlsPoints, tile: &str, cell: u64) -> Result<()> {
    let batch = als_batch(points, tile, cell)?;
    for part in (0..batch.num_rows()).step_by(MAX_ROW_GROUP_ROWS) {
        writer.write_row_group(&batch.slice(part, MAX_ROW_GROUP_ROWS.min(batch.num_rows() - part)))?;
    }
    Ok(())
}

/// Ingest the points of a COPC tile inside the cells `wanted`, decoding only the octree nodes that
/// meet them. A tile read before in other windows is topped up: only the cells not read yet are
/// decoded, and its `als/` file is rewritten with the points read before and the new ones, then
/// its `tiles/` row. The cells recorded in the `als/` file are the authority: a run cut between
/// the two renames leaves a `tiles/` row behind, which the next ingest rewrites.
fn ingest_windows(t: &Target, opts: &AlsOptions, wanted: &Cells, progress: &dyn Progress) -> Result<StagedTile> {
    let tile = tile_name(t.given);
    let copc = CopcTile::open(t.path)?;
    let header = copc.header().clone();
    let b = header.bounds;
    let extent = [b[0], b[1], b[3], b[4]];
    let (als_file, tiles_file) = (t.als_file(), t.tiles_file());
    let before = if tiles_file.exists() && als_file.exists() {
        match table::read_window(&als_file)? {
            Some(w) => Some(w),
            None => {
                progress.advance(header.number_of_points);
                return Ok(StagedTile::already(tile)); // read whole before
            }
        }
    } else {
        None
    };
    let missing = wanted.without(before.as_ref().map_or(&Cells::default(), |w| &w.cells));
    let (earlier_dropped, row_cells) = match &before {
        Some(_) => tiles_row_window(&tiles_file)?,
        None => (0, None),
    };
    if let Some(w) = &before {
        if missing.is_empty() && row_cells == Some(w.cells.len() as u64) {
            progress.advance(header.number_of_points);
            return Ok(StagedTile::already(tile));
        }
    }
    let (new, read) = if missing.is_empty() {
        (AlsPoints::default(), CopcRead::default())
    } else {
        copc.read(Some(&missing), Attributes::All)?
    };
    progress.advance(header.number_of_points);

    let mut stats = TileStats::new();
    let mut points = match &before {
        Some(_) => table::read_file_points(&als_file)?,
        None => AlsPoints::default(),
    };
    for i in 0..points.len() {
        stats.add(&points, i);
    }
    let mut keep = Vec::with_capacity(new.len());
    for i in 0..new.len() {
        if keep_point(t.path, &new, i, opts, &mut stats)? {
            keep.push(i as u32);
        }
    }
    let (points_new, dropped_new) = (keep.len() as u64, stats.dropped);
    points.extend_from(&new.permuted(&keep));
    drop(new);
    stats.dropped += earlier_dropped;

    let window = ReadWindow { cells: before.map(|w| w.cells).unwrap_or_default().union(&missing), extent };
    let metadata = t.metadata(&header, Some(&window));
    let props = als_writer_properties(dataset::writer_properties(&metadata, MAX_ROW_GROUP_ROWS));
    let cells: Vec<u64> = (0..points.len()).map(|i| cell_key(points.x[i], points.y[i])).collect();
    let mut order: Vec<u32> = (0..points.len() as u32).collect();
    order.sort_by_key(|&i| cells[i as usize]); // stable: file order within a cell
    let mut writer = AtomicParquet::create(&als_file, als_schema(), props)?;
    for run in order.chunk_by(|&a, &b| cells[a as usize] == cells[b as usize]) {
        write_cell(&mut writer, points.permuted(run), &tile, cells[run[0] as usize])?;
    }
    let als = writer.finish_staged()?;
    let window_read = WindowRead { cells_new: missing.len(), cells_read: window.cells.len(), copc: read };
    let outcome = TileOutcome::Ingested {
        tile,
        points: points_new,
        dropped: dropped_new,
        odd_returns: stats.odd_returns,
        window: Some(window_read),
    };
    t.staged(als, &header, &stats, Some(&window), &metadata, outcome)
}

/// The `n_dropped` and `read_cells` of a tile's `tiles/` row.
fn tiles_row_window(path: &Path) -> Result<(u64, Option<u64>)> {
    let mut out = (0, None);
    read::for_each_batch(path, Some(&[tiles_col::N_DROPPED, tiles_col::READ_CELLS]), None, |c| {
        if c.num_rows() > 0 {
            out = (c.u64(tiles_col::N_DROPPED, 0)?.unwrap_or(0), c.u64(tiles_col::READ_CELLS, 0)?);
        }
        Ok(())
    })?;
    Ok(out)
}

/// Ingest a whole tile, streamed: decoded chunk by chunk, its points filed by cell and spilled to
/// disk in sorted runs, then written cell by cell.
fn ingest_tile(t: &Target, opts: &AlsOptions, parallel_decode: bool, progress: &dyn Progress) -> Result<StagedTile> {
    let (path, key, als_dir) = (t.path, t.key(), t.als_dir);
    let tile = tile_name(t.given);
    // A tile read in windows before is read again, whole.
    if t.tiles_file().exists() && table::read_window(&t.als_file())?.is_none() {
        return Ok(StagedTile::already(tile));
    }
    let mut reader = TileReader::open_with(path, parallel_decode)?;
    let header = reader.header().clone();

    // Pass 1: decode, filter, file by cell, spill runs sorted by cell.
    let spill_path = dataset::tmp_path(&als_dir.join(format!("{key}.spill")));
    let spill = SpillFile::create(&spill_path)?;
    let result = (|| {
        let mut spill = spill;
        let mut stats = TileStats::new();
        let mut runs: Vec<Run> = Vec::new();
        while let Some(chunk) = reader.next_chunk(CHUNK_POINTS)? {
            progress.advance(chunk.len() as u64);
            let mut keep: Vec<(u64, u32)> = Vec::with_capacity(chunk.len());
            for i in 0..chunk.len() {
                if keep_point(path, &chunk, i, opts, &mut stats)? {
                    keep.push((cell_key(chunk.x[i], chunk.y[i]), i as u32));
                }
            }
            keep.sort_unstable_by_key(|&(c, _)| c);
            spill.write_runs(&chunk, &keep, &mut runs)?;
        }
        let spill = spill.finish()?;

        // Pass 2: write the Parquet file cell by cell.
        runs.sort_by_key(|r| (r.cell, r.offset));
        let metadata = t.metadata(&header, None);
        let props = als_writer_properties(dataset::writer_properties(&metadata, MAX_ROW_GROUP_ROWS));
        let mut writer = AtomicParquet::create(&t.als_file(), als_schema(), props)?;
        let mut spill_reader = SpillReader::open(&spill)?;
        let mut start = 0;
        while start < runs.len() {
            let cell = runs[start].cell;
            let mut end = start;
            while end < runs.len() && runs[end].cell == cell {
                end += 1;
            }
            write_cell(&mut writer, spill_reader.read_runs(&runs[start..end])?, &tile, cell)?;
            start = end;
        }
        let als = writer.finish_staged()?;
        drop(spill_reader);
        let _ = std::fs::remove_file(&spill);

        let outcome = TileOutcome::Ingested {
            tile: tile.clone(),
            points: stats.kept,
            dropped: stats.dropped,
            odd_returns: stats.odd_returns,
            window: None,
        };
        t.staged(als, &header, &stats, None, &metadata, outcome)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&spill_path);
    }
    result
}

/// The `als/` table's writer properties: the clustering declared so that readers may rely on it,
/// and no dictionary for the columns whose values are nearly all distinct.
fn als_writer_properties(
    props: parquet::file::properties::WriterProperties,
) -> parquet::file::properties::WriterProperties {
    use parquet::schema::types::ColumnPath;
    let cell_col = als_schema().index_of(table::col::CELL).expect("cell column");
    let mut builder = props.into_builder().set_sorting_columns(Some(vec![parquet::file::metadata::SortingColumn {
        column_idx: cell_col as i32,
        descending: false,
        nulls_first: false,
    }]));
    for name in [table::col::X, table::col::Y, table::col::Z, table::col::GPS_TIME] {
        builder = builder.set_column_dictionary_enabled(ColumnPath::from(name), false);
    }
    builder.build()
}

/// The `tiles/` row of the tile given as `given`.
fn tiles_batch(
    h: &TileHeader,
    given: &Path,
    hash: &str,
    epsg: u32,
    s: &TileStats,
    window: Option<&ReadWindow>,
) -> Result<RecordBatch> {
    let has = s.kept > 0;
    let b = |i: usize| has.then_some(s.bounds[i]);
    let gps = |i: usize| (s.gps[0] <= s.gps[1]).then_some(s.gps[i]);
    let acq = |i: usize| gps(i).and_then(gps_to_utc_micros);
    let cols: Vec<ArrayRef> = vec![
        Arc::new(StringArray::from(vec![tile_name(given)])),
        Arc::new(StringArray::from(vec![given.display().to_string()])),
        Arc::new(StringArray::from(vec![hash])),
        Arc::new(StringArray::from(vec![h.version.clone()])),
        Arc::new(UInt8Array::from(vec![h.point_format])),
        Arc::new(BooleanArray::from(vec![h.compressed])),
        Arc::new(UInt64Array::from(vec![h.number_of_points])),
        Arc::new(UInt64Array::from(vec![s.kept])),
        Arc::new(UInt64Array::from(vec![s.dropped])),
        Arc::new(Float64Array::from(vec![b(0)])),
        Arc::new(Float64Array::from(vec![b(1)])),
        Arc::new(Float64Array::from(vec![b(2)])),
        Arc::new(Float64Array::from(vec![b(3)])),
        Arc::new(Float64Array::from(vec![b(4)])),
        Arc::new(Float64Array::from(vec![b(5)])),
        Arc::new(UInt32Array::from(vec![epsg])),
        Arc::new(StringArray::from(vec![h.crs_wkt.clone()])),
        Arc::new(StringArray::from(vec![h.extra_bytes.join(",")])),
        Arc::new(UInt16Array::from(vec![s.intensity_quantile(0.0)])),
        Arc::new(UInt16Array::from(vec![s.intensity_quantile(1.0)])),
        Arc::new(Float64Array::from(vec![s.intensity_mean()])),
        Arc::new(UInt16Array::from(vec![s.intensity_quantile(0.01)])),
        Arc::new(UInt16Array::from(vec![s.intensity_quantile(0.50)])),
        Arc::new(UInt16Array::from(vec![s.intensity_quantile(0.99)])),
        Arc::new(Float64Array::from(vec![gps(0)])),
        Arc::new(Float64Array::from(vec![gps(1)])),
        Arc::new(TimestampMicrosecondArray::from(vec![acq(0)]).with_timezone("UTC")),
        Arc::new(TimestampMicrosecondArray::from(vec![acq(1)]).with_timezone("UTC")),
        Arc::new(BooleanArray::from(vec![h.copc])),
        Arc::new(UInt64Array::from(vec![window.map(|w| w.cells.len() as u64)])),
        Arc::new(StringArray::from(vec![window.map(|w| w.cells.to_text())])),
    ];
    RecordBatch::try_new(tiles_schema(), cols).map_err(|e| Error::table(given, e))
}

/// UTC (µs since 1970) of a LAS GPS time stored as adjusted standard GPS time
/// (GPS seconds − 1e9); `None` for GPS week time (values below one week), which has no date.
pub fn gps_to_utc_micros(t: f64) -> Option<i64> {
    const WEEK_S: f64 = 604_800.0;
    const GPS_EPOCH_UNIX_S: f64 = 315_964_800.0; // 1980-01-06T00:00:00Z
    const LEAP_SECONDS: f64 = 18.0; // GPS − UTC since 2017-01-01
    if !(t.is_finite() && t.abs() > WEEK_S) {
        return None;
    }
    Some(((GPS_EPOCH_UNIX_S + t + 1e9 - LEAP_SECONDS) * 1e6).round() as i64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cell_key_orders_rows_then_columns() {
        assert!(cell_key(10.0, 0.0) < cell_key(60.0, 0.0));
        assert!(cell_key(1000.0, 0.0) < cell_key(0.0, 60.0));
        assert_eq!(cell_key(0.0, 0.0), cell_key(49.9, 49.9));
        assert!(cell_key(-0.1, 0.0) < cell_key(0.0, 0.0));
    }

    #[test]
    fn gps_time_to_utc() {
        // 338993840.636 s adjusted GPS = 2022-06-11 14:43:42 UTC (provenance of lidarforfuel_1_42).
        let us = gps_to_utc_micros(338993840.636).unwrap();
        let dt = chrono::DateTime::from_timestamp_micros(us).unwrap();
        assert_eq!(dt.format("%Y-%m-%d %H:%M:%S").to_string(), "2022-06-11 14:43:42");
        assert_eq!(gps_to_utc_micros(3600.0), None);
    }
}
