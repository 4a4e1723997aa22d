//! `ingest als`: LAS/LAZ tiles into the `als/` table (points clustered by spatial cell) and the
//! `tiles/` table (one row per file).
//!
//! Each file is streamed in chunks. Points are filed by a global square cell (`CELL_SIZE_M`) and
//! spilled to a temporary file in runs sorted by cell; the Parquet file is then written cell by
//! cell, one or more row groups per cell, so that row-group statistics of x and y span one cell
//! and a bounding-box query reads only the row groups it needs. Peak memory is bounded by the
//! chunk and the largest cell, never by the file.

use std::collections::HashMap;
use std::fs::File;
use std::io::{BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow::array::{
    ArrayRef, BooleanArray, Float64Array, StringArray, TimestampMicrosecondArray, UInt16Array, UInt32Array,
    UInt64Array, UInt8Array,
};
use arrow::record_batch::RecordBatch;
use rayon::prelude::*;

use crate::dataset::als::{
    als_batch, als_schema, cell_key, meta, tiles_schema, CELL_SIZE_M, DROPPED_CLASSES, MAX_ROW_GROUP_ROWS,
};
use crate::dataset::{self, tables, AtomicParquet, Dataset};
use crate::error::{Error, Result};
use crate::io::las::{TileHeader, TileReader, CHUNK_POINTS};
use crate::kernels::sim::AlsPoints;
use crate::ops::progress::{Progress, Step};

/// Options of `ingest als`.
#[derive(Debug, Clone, Default)]
pub struct AlsOptions {
    /// Keep classes 7, 18 and 64–67.
    pub keep_all_classes: bool,
    /// CRS for tiles that carry none; must agree with tiles that do.
    pub epsg: Option<u32>,
}

/// What happened to one input file.
#[derive(Debug, Clone)]
pub enum TileOutcome {
    /// Points written.
    Ingested { tile: String, points: u64, dropped: u64 },
    /// The same content was ingested before (keyed by content hash).
    AlreadyIngested { tile: String },
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
    let existing = dataset::dataset_epsg(dataset)?;
    let mut headers: Vec<(u32, u64)> = Vec::with_capacity(files.len()); // (EPSG, points) per file
    for f in files {
        let reader = TileReader::open(f)?;
        let epsg = resolve_epsg(reader.header(), opts, existing)?;
        if let Some(&(first, _)) = headers.first().filter(|&&(first, _)| first != epsg) {
            return Err(Error::field(
                f,
                "CRS",
                format!("EPSG:{epsg} differs from EPSG:{first} of {} in the same call", files[0].display()),
            ));
        }
        headers.push((epsg, reader.header().number_of_points));
    }
    progress.set_total(headers.iter().map(|h| h.1).sum());
    let als_dir = dataset.table_dir(tables::ALS)?;
    let tiles_dir = dataset.table_dir(tables::TILES)?;
    // Content hashes first: a file whose content appears earlier in the call is skipped like one
    // ingested before (two copies must not write the same table files at once).
    let hashes = files.par_iter().map(|f| dataset::content_hash(f)).collect::<Result<Vec<_>>>()?;
    let mut seen = std::collections::HashSet::new();
    let first_copy: Vec<bool> = hashes.iter().map(|h| seen.insert(h.clone())).collect();
    // A single file gets both cores for LAZ decoding; several files run one per core.
    let parallel_decode = seen.len() == 1;
    files
        .par_iter()
        .zip(&hashes)
        .zip(&first_copy)
        .zip(&headers)
        .map(|(((f, hash), &first), &(epsg, points))| {
            if !first {
                progress.advance(points);
                return Ok(TileOutcome::AlreadyIngested { tile: tile_name(f) });
            }
            ingest_tile(f, hash, &als_dir, &tiles_dir, opts, epsg, parallel_decode, progress)
        })
        .collect()
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

/// One run of points of a single cell in the spill file.
#[derive(Clone, Copy)]
struct Run {
    cell: u64,
    offset: u64,
    len: u32,
}

/// Bytes of one spilled point: x, y, z, gps (f64), scan angle (f32), intensity, psid (u16),
/// return number, number of returns, class (u8). A run stores each column contiguously.
const SPILL_RECORD: usize = 8 * 4 + 4 + 2 * 2 + 3;

#[allow(clippy::too_many_arguments)]
fn ingest_tile(
    path: &Path,
    hash: &str,
    als_dir: &Path,
    tiles_dir: &Path,
    opts: &AlsOptions,
    epsg: u32,
    parallel_decode: bool,
    progress: &dyn Progress,
) -> Result<TileOutcome> {
    let key = &hash[..16];
    let tile = tile_name(path);
    let tiles_file = tiles_dir.join(format!("{key}.parquet"));
    if tiles_file.exists() {
        return Ok(TileOutcome::AlreadyIngested { tile });
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
                if !opts.keep_all_classes && DROPPED_CLASSES.contains(&chunk.classification[i]) {
                    stats.dropped += 1;
                    continue;
                }
                for (name, v) in [("x", chunk.x[i]), ("y", chunk.y[i]), ("z", chunk.z[i])] {
                    if !v.is_finite() {
                        return Err(Error::field(
                            path,
                            name,
                            format!("non-finite coordinate {v} at point {}", stats.kept + stats.dropped),
                        ));
                    }
                }
                stats.add(&chunk, i);
                keep.push((cell_key(chunk.x[i], chunk.y[i]), i as u32));
            }
            keep.sort_unstable_by_key(|&(c, _)| c);
            spill.write_runs(&chunk, &keep, &mut runs)?;
        }
        let spill = spill.finish()?;

        // Pass 2: write the Parquet file cell by cell.
        runs.sort_by_key(|r| (r.cell, r.offset));
        let mut metadata = HashMap::new();
        metadata.insert(meta::EPSG.to_string(), epsg.to_string());
        metadata.insert(meta::CELL_SIZE.to_string(), CELL_SIZE_M.to_string());
        metadata.insert(meta::VERTICAL.to_string(), "as stored in the LAS file (IGN69 for LiDAR HD)".to_string());
        if let Some(wkt) = &header.crs_wkt {
            metadata.insert(meta::CRS_WKT.to_string(), wkt.clone());
        }
        let props = dataset::writer_properties(&metadata, MAX_ROW_GROUP_ROWS);
        let props = als_writer_properties(props);
        let dest = als_dir.join(format!("{key}.parquet"));
        let mut writer = AtomicParquet::create(&dest, als_schema(), props)?;
        let mut spill_reader = SpillReader::open(&spill)?;
        let mut start = 0;
        while start < runs.len() {
            let cell = runs[start].cell;
            let mut end = start;
            while end < runs.len() && runs[end].cell == cell {
                end += 1;
            }
            let points = spill_reader.read_runs(&runs[start..end])?;
            let batch = als_batch(points, &tile, cell)?;
            for part in (0..batch.num_rows()).step_by(MAX_ROW_GROUP_ROWS) {
                writer.write_row_group(&batch.slice(part, MAX_ROW_GROUP_ROWS.min(batch.num_rows() - part)))?;
            }
            start = end;
        }
        writer.finish()?;
        drop(spill_reader);
        let _ = std::fs::remove_file(&spill);

        let batch = tiles_batch(&header, &tile, hash, epsg, &stats)?;
        dataset::write_parquet(&tiles_file, tiles_schema(), &[batch], &metadata)?;
        Ok(TileOutcome::Ingested { tile: tile.clone(), points: stats.kept, dropped: stats.dropped })
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
    let cell_col = als_schema().index_of("cell").expect("cell column");
    let mut builder = props.into_builder().set_sorting_columns(Some(vec![parquet::file::metadata::SortingColumn {
        column_idx: cell_col as i32,
        descending: false,
        nulls_first: false,
    }]));
    for col in ["x", "y", "z", "gps_time"] {
        builder = builder.set_column_dictionary_enabled(ColumnPath::from(col), false);
    }
    builder.build()
}

fn tiles_batch(h: &TileHeader, tile: &str, hash: &str, epsg: u32, s: &TileStats) -> Result<RecordBatch> {
    let has = s.kept > 0;
    let b = |i: usize| has.then_some(s.bounds[i]);
    let gps = |i: usize| (s.gps[0] <= s.gps[1]).then_some(s.gps[i]);
    let acq = |i: usize| gps(i).and_then(gps_to_utc_micros);
    let cols: Vec<ArrayRef> = vec![
        Arc::new(StringArray::from(vec![tile])),
        Arc::new(StringArray::from(vec![h.path.display().to_string()])),
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
    ];
    RecordBatch::try_new(tiles_schema(), cols).map_err(|e| Error::table(&h.path, e))
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

/// Write side of the spill file.
struct SpillFile {
    path: PathBuf,
    out: BufWriter<File>,
    offset: u64,
    buf: Vec<u8>,
}

impl SpillFile {
    fn create(path: &Path) -> Result<Self> {
        let f = File::create(path).map_err(|e| Error::file(path, format!("cannot create spill file: {e}")))?;
        Ok(SpillFile {
            path: path.to_path_buf(),
            out: BufWriter::with_capacity(1 << 20, f),
            offset: 0,
            buf: Vec::new(),
        })
    }

    /// Append the points `order` (sorted by cell) of `chunk`, one run per cell, column by column.
    fn write_runs(&mut self, chunk: &AlsPoints, order: &[(u64, u32)], runs: &mut Vec<Run>) -> Result<()> {
        fn put<T: Copy, const N: usize>(
            buf: &mut Vec<u8>,
            col: &[T],
            idx: &[(u64, u32)],
            bytes: impl Fn(T) -> [u8; N],
        ) {
            for &(_, i) in idx {
                buf.extend_from_slice(&bytes(col[i as usize]));
            }
        }
        self.buf.clear();
        self.buf.reserve(order.len() * SPILL_RECORD);
        let mut start = 0;
        while start < order.len() {
            let cell = order[start].0;
            let end = start + order[start..].partition_point(|&(c, _)| c == cell);
            let (idx, buf) = (&order[start..end], &mut self.buf);
            runs.push(Run { cell, offset: self.offset + buf.len() as u64, len: idx.len() as u32 });
            put(buf, &chunk.x, idx, f64::to_le_bytes);
            put(buf, &chunk.y, idx, f64::to_le_bytes);
            put(buf, &chunk.z, idx, f64::to_le_bytes);
            put(buf, &chunk.gps_time, idx, f64::to_le_bytes);
            put(buf, &chunk.scan_angle_deg, idx, f32::to_le_bytes);
            put(buf, &chunk.intensity, idx, u16::to_le_bytes);
            put(buf, &chunk.point_source_id, idx, u16::to_le_bytes);
            put(buf, &chunk.return_number, idx, |v: u8| [v]);
            put(buf, &chunk.number_of_returns, idx, |v: u8| [v]);
            put(buf, &chunk.classification, idx, |v: u8| [v]);
            start = end;
        }
        self.out.write_all(&self.buf).map_err(|e| Error::file(&self.path, format!("cannot write spill file: {e}")))?;
        self.offset += self.buf.len() as u64;
        Ok(())
    }

    fn finish(mut self) -> Result<PathBuf> {
        self.out.flush().map_err(|e| Error::file(&self.path, format!("cannot write spill file: {e}")))?;
        Ok(self.path)
    }
}

/// Read side of the spill file.
struct SpillReader {
    path: PathBuf,
    file: File,
    buf: Vec<u8>,
}

impl SpillReader {
    fn open(path: &Path) -> Result<Self> {
        let file = File::open(path).map_err(|e| Error::file(path, format!("cannot open spill file: {e}")))?;
        Ok(SpillReader { path: path.to_path_buf(), file, buf: Vec::new() })
    }

    fn read_runs(&mut self, runs: &[Run]) -> Result<AlsPoints> {
        fn take<T, const N: usize>(
            col: &mut Vec<T>,
            bytes: &[u8],
            at: &mut usize,
            n: usize,
            from: impl Fn([u8; N]) -> T,
        ) {
            let part = &bytes[*at..*at + n * N];
            col.extend(part.chunks_exact(N).map(|c| from(c.try_into().expect("N bytes"))));
            *at += n * N;
        }
        let total: usize = runs.iter().map(|r| r.len as usize).sum();
        let mut p = AlsPoints::with_capacity(total);
        for r in runs {
            let n = r.len as usize;
            self.buf.resize(n * SPILL_RECORD, 0);
            self.file
                .seek(SeekFrom::Start(r.offset))
                .and_then(|_| self.file.read_exact(&mut self.buf))
                .map_err(|e| Error::file(&self.path, format!("cannot read spill file: {e}")))?;
            let (b, at) = (&self.buf, &mut 0);
            take(&mut p.x, b, at, n, f64::from_le_bytes);
            take(&mut p.y, b, at, n, f64::from_le_bytes);
            take(&mut p.z, b, at, n, f64::from_le_bytes);
            take(&mut p.gps_time, b, at, n, f64::from_le_bytes);
            take(&mut p.scan_angle_deg, b, at, n, f32::from_le_bytes);
            take(&mut p.intensity, b, at, n, u16::from_le_bytes);
            take(&mut p.point_source_id, b, at, n, u16::from_le_bytes);
            take(&mut p.return_number, b, at, n, |[v]: [u8; 1]| v);
            take(&mut p.number_of_returns, b, at, n, |[v]: [u8; 1]| v);
            take(&mut p.classification, b, at, n, |[v]: [u8; 1]| v);
        }
        Ok(p)
    }
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
