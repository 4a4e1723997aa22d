//! The `als/` and `tiles/` tables: their layout (points clustered by [`CELL_SIZE_M`] cell), schemas
//! and batches, and the reading of ALS points back around footprints, touching only the row groups
//! whose x/y statistics intersect a footprint's box.

use std::collections::HashMap;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow::array::{
    Array, ArrayRef, AsArray, Float32Array, Float64Array, StringArray, UInt16Array, UInt64Array, UInt8Array,
};
use arrow::datatypes::{DataType, Field, Schema, SchemaRef, TimeUnit};
use arrow::datatypes::{Float32Type, Float64Type, UInt16Type, UInt8Type};
use arrow::record_batch::RecordBatch;
use parquet::arrow::arrow_reader::{ArrowReaderMetadata, ArrowReaderOptions, ParquetRecordBatchReaderBuilder};
use parquet::arrow::ProjectionMask;
use parquet::file::metadata::ParquetMetaData;
use parquet::file::statistics::Statistics;
use rayon::prelude::*;

use crate::dataset::{tables, Dataset};
use crate::error::{Error, Result};
use crate::kernels::collocate::PointCloud;
use crate::kernels::geo::cells::Cells;
use crate::kernels::sim::AlsPoints;

/// Axis-aligned box [xmin, ymin, xmax, ymax].
pub type BBox = [f64; 4];

/// Side of the square spatial cells that cluster the `als/` table, metres.
pub const CELL_SIZE_M: f64 = 50.0;

/// Most rows in one row group of `als/`.
pub const MAX_ROW_GROUP_ROWS: usize = 1 << 17;

/// Classes dropped unless `keep_all_classes`: noise (7, 18) and IGN artefacts/virtual points (64–67).
pub const DROPPED_CLASSES: [u8; 6] = [7, 18, 64, 65, 66, 67];

/// Parquet key-value metadata keys.
pub mod meta {
    pub const EPSG: &str = "gedisim:crs_epsg";
    pub const CRS_WKT: &str = "gedisim:crs_wkt";
    pub const CELL_SIZE: &str = "gedisim:cell_size_m";
    pub const VERTICAL: &str = "gedisim:vertical_reference";
    /// The [`READ_CELL_M`](crate::kernels::geo::cells::READ_CELL_M) cells of a COPC tile read so
    /// far ([`Cells::to_text`]); absent when the whole tile was read. Authoritative in the `als/`
    /// file, copied to the tile's `tiles/` row.
    pub const READ_CELLS: &str = "gedisim:read_cells";
    /// The horizontal extent `xmin ymin xmax ymax` of a tile read in windows (its header bounds).
    pub const TILE_EXTENT: &str = "gedisim:tile_extent";
}

/// What a COPC tile read in windows holds: the cells read so far, inside the tile's extent.
#[derive(Debug, Clone, PartialEq)]
pub struct ReadWindow {
    pub cells: Cells,
    /// The tile's horizontal extent (header bounds).
    pub extent: BBox,
}

impl ReadWindow {
    /// The file metadata that records it ([`meta::READ_CELLS`], [`meta::TILE_EXTENT`]).
    pub fn metadata(&self) -> [(String, String); 2] {
        let e = self.extent;
        [
            (meta::READ_CELLS.to_string(), self.cells.to_text()),
            (meta::TILE_EXTENT.to_string(), format!("{} {} {} {}", e[0], e[1], e[2], e[3])),
        ]
    }
}

/// Most cells a window record may hold (a 20 km × 20 km tile read whole in 10 m cells).
pub const MAX_WINDOW_CELLS: usize = 4_000_000;

/// The cells of a COPC tile that its `als/` file holds, from the file's metadata; `None` when the
/// file holds the whole tile.
pub fn read_window(path: &Path) -> Result<Option<ReadWindow>> {
    let kv =
        super::read::key_value_metadata(path).ok_or_else(|| Error::file(path, "cannot read the Parquet footer"))?;
    window_of(path, &kv)
}

/// The header extent an `als/` file records (`gedisim:tile_extent`), if it records one.
pub fn tile_extent(path: &Path) -> Option<BBox> {
    extent_of(&super::read::key_value_metadata(path)?)
}

/// The `gedisim:tile_extent` value of a file's metadata, when it is four ordered numbers.
fn extent_of(kv: &HashMap<String, String>) -> Option<BBox> {
    let v: Vec<f64> = kv.get(meta::TILE_EXTENT)?.split_whitespace().filter_map(|v| v.parse().ok()).collect();
    match v[..] {
        [x0, y0, x1, y1] if x0 <= x1 && y0 <= y1 => Some([x0, y0, x1, y1]),
        _ => None,
    }
}

fn window_of(path: &Path, kv: &HashMap<String, String>) -> Result<Option<ReadWindow>> {
    let Some(text) = kv.get(meta::READ_CELLS) else { return Ok(None) };
    let cells = Cells::parse(text, MAX_WINDOW_CELLS)
        .ok_or_else(|| Error::field(path, meta::READ_CELLS, "not a list of cells (row:col0-col1,…;…)"))?;
    match extent_of(kv) {
        Some(extent) => Ok(Some(ReadWindow { cells, extent })),
        None => Err(Error::field(path, meta::TILE_EXTENT, "missing or not four numbers xmin ymin xmax ymax")),
    }
}

/// Every point of one `als/` file.
pub fn read_file_points(path: &Path) -> Result<AlsPoints> {
    let b = super::read::open(path)?;
    let mask = parquet::arrow::ProjectionMask::columns(b.parquet_schema(), POINT_COLUMNS.iter().copied());
    let reader = b.with_projection(mask).with_batch_size(1 << 16).build().map_err(|e| Error::table(path, e))?;
    let mut out = AlsPoints::default();
    for batch in reader {
        append(&mut out, &batch.map_err(|e| Error::table(path, e))?, None, path)?;
    }
    Ok(out)
}

/// Columns of `als/` a points table may leave out: no scan angle is read as 0°, no GPS time as
/// none (a pulse is then one return), no flight line as line 0.
const OPTIONAL_POINT_COLUMNS: [&str; 3] = [col::SCAN_ANGLE_DEG, col::GPS_TIME, col::POINT_SOURCE_ID];

/// The points of a points table from elsewhere (the Python API's), `source` naming it in errors:
/// the columns of `als/` by name, cast to their types (docs/schemas.md); x, y, z, intensity,
/// return_number, number_of_returns and classification are required, finite and not null, the
/// [`OPTIONAL_POINT_COLUMNS`] may be missing. A table without a point is an error.
pub fn points_from_batches(batches: &[RecordBatch], source: &Path) -> Result<AlsPoints> {
    let schema = als_schema();
    let mut out = AlsPoints::default();
    for b in batches {
        let cast = super::read::cast_columns(source, b, &schema, &POINT_COLUMNS, &OPTIONAL_POINT_COLUMNS)?;
        let n = cast.num_rows();
        let mut fields = Vec::with_capacity(POINT_COLUMNS.len());
        let mut columns = Vec::with_capacity(POINT_COLUMNS.len());
        for name in POINT_COLUMNS {
            let field = schema.field_with_name(name).expect("a column of als/");
            let column: ArrayRef = match cast.column_by_name(name) {
                Some(c) if c.null_count() > 0 && !field.is_nullable() => {
                    let row = out.len() + (0..n).find(|&i| c.is_null(i)).unwrap_or_default();
                    return Err(Error::field(source, name, format!("null at row {row}: every point needs one")));
                }
                Some(c) => c.clone(),
                None => match name {
                    col::SCAN_ANGLE_DEG => Arc::new(Float32Array::from(vec![0f32; n])),
                    col::POINT_SOURCE_ID => Arc::new(UInt16Array::from(vec![0u16; n])),
                    _ => arrow::array::new_null_array(field.data_type(), n),
                },
            };
            if let Some(v) = column.as_primitive_opt::<Float64Type>().filter(|_| !field.is_nullable()) {
                if let Some(i) = v.values().iter().position(|x| !x.is_finite()) {
                    let why = format!("{} at row {}: not a position", v.value(i), out.len() + i);
                    return Err(Error::field(source, name, why));
                }
            }
            fields.push(field.clone());
            columns.push(column);
        }
        let batch =
            RecordBatch::try_new(Arc::new(Schema::new(fields)), columns).map_err(|e| Error::table(source, e))?;
        append(&mut out, &batch, None, source)?;
    }
    if out.is_empty() {
        return Err(Error::file(source, "the points table has no point"));
    }
    Ok(out)
}

/// The global cell key of a position: row-major over (floor(y/CELL), floor(x/CELL)), so that
/// sorting by key clusters points spatially.
pub fn cell_key(x: f64, y: f64) -> u64 {
    let ix = (x / CELL_SIZE_M).floor() as i64 + (1 << 31);
    let iy = (y / CELL_SIZE_M).floor() as i64 + (1 << 31);
    ((iy as u64 & 0xffff_ffff) << 32) | (ix as u64 & 0xffff_ffff)
}

/// The names of the `als/` columns (docs/schemas.md), one constant each.
pub mod col {
    pub const X: &str = "x";
    pub const Y: &str = "y";
    pub const Z: &str = "z";
    pub const INTENSITY: &str = "intensity";
    pub const RETURN_NUMBER: &str = "return_number";
    pub const NUMBER_OF_RETURNS: &str = "number_of_returns";
    pub const CLASSIFICATION: &str = "classification";
    pub const SCAN_ANGLE_DEG: &str = "scan_angle_deg";
    pub const GPS_TIME: &str = "gps_time";
    pub const POINT_SOURCE_ID: &str = "point_source_id";
    pub const TILE: &str = "tile";
    pub const CELL: &str = "cell";
}

/// Schema of the `als/` table.
pub fn als_schema() -> SchemaRef {
    Arc::new(Schema::new(vec![
        Field::new(col::X, DataType::Float64, false),
        Field::new(col::Y, DataType::Float64, false),
        Field::new(col::Z, DataType::Float64, false),
        Field::new(col::INTENSITY, DataType::UInt16, false),
        Field::new(col::RETURN_NUMBER, DataType::UInt8, false),
        Field::new(col::NUMBER_OF_RETURNS, DataType::UInt8, false),
        Field::new(col::CLASSIFICATION, DataType::UInt8, false),
        Field::new(col::SCAN_ANGLE_DEG, DataType::Float32, false),
        Field::new(col::GPS_TIME, DataType::Float64, true),
        Field::new(col::POINT_SOURCE_ID, DataType::UInt16, false),
        Field::new(col::TILE, DataType::Utf8, false),
        Field::new(col::CELL, DataType::UInt64, false),
    ]))
}

/// The names of the `tiles/` columns (docs/schemas.md), one constant each.
pub mod tiles_col {
    pub const TILE: &str = "tile";
    pub const PATH: &str = "path";
    pub const CONTENT_HASH: &str = "content_hash";
    pub const LAS_VERSION: &str = "las_version";
    pub const POINT_FORMAT: &str = "point_format";
    pub const COMPRESSED: &str = "compressed";
    pub const N_POINTS_HEADER: &str = "n_points_header";
    pub const N_POINTS: &str = "n_points";
    pub const N_DROPPED: &str = "n_dropped";
    pub const XMIN: &str = "xmin";
    pub const YMIN: &str = "ymin";
    pub const ZMIN: &str = "zmin";
    pub const XMAX: &str = "xmax";
    pub const YMAX: &str = "ymax";
    pub const ZMAX: &str = "zmax";
    pub const EPSG: &str = "epsg";
    pub const CRS_WKT: &str = "crs_wkt";
    pub const EXTRA_BYTES: &str = "extra_bytes";
    pub const INTENSITY_MIN: &str = "intensity_min";
    pub const INTENSITY_MAX: &str = "intensity_max";
    pub const INTENSITY_MEAN: &str = "intensity_mean";
    pub const INTENSITY_P01: &str = "intensity_p01";
    pub const INTENSITY_P50: &str = "intensity_p50";
    pub const INTENSITY_P99: &str = "intensity_p99";
    pub const GPS_TIME_MIN: &str = "gps_time_min";
    pub const GPS_TIME_MAX: &str = "gps_time_max";
    pub const ACQUISITION_START: &str = "acquisition_start";
    pub const ACQUISITION_END: &str = "acquisition_end";
    pub const COPC: &str = "copc";
    pub const READ_CELLS: &str = "read_cells";
    pub const READ_WINDOW: &str = "read_window";
}

/// Schema of the `tiles/` table.
pub fn tiles_schema() -> SchemaRef {
    let ts = DataType::Timestamp(TimeUnit::Microsecond, Some("UTC".into()));
    Arc::new(Schema::new(vec![
        Field::new(tiles_col::TILE, DataType::Utf8, false),
        Field::new(tiles_col::PATH, DataType::Utf8, false),
        Field::new(tiles_col::CONTENT_HASH, DataType::Utf8, false),
        Field::new(tiles_col::LAS_VERSION, DataType::Utf8, false),
        Field::new(tiles_col::POINT_FORMAT, DataType::UInt8, false),
        Field::new(tiles_col::COMPRESSED, DataType::Boolean, false),
        Field::new(tiles_col::N_POINTS_HEADER, DataType::UInt64, false),
        Field::new(tiles_col::N_POINTS, DataType::UInt64, false),
        Field::new(tiles_col::N_DROPPED, DataType::UInt64, false),
        Field::new(tiles_col::XMIN, DataType::Float64, true),
        Field::new(tiles_col::YMIN, DataType::Float64, true),
        Field::new(tiles_col::ZMIN, DataType::Float64, true),
        Field::new(tiles_col::XMAX, DataType::Float64, true),
        Field::new(tiles_col::YMAX, DataType::Float64, true),
        Field::new(tiles_col::ZMAX, DataType::Float64, true),
        Field::new(tiles_col::EPSG, DataType::UInt32, false),
        Field::new(tiles_col::CRS_WKT, DataType::Utf8, true),
        Field::new(tiles_col::EXTRA_BYTES, DataType::Utf8, false),
        Field::new(tiles_col::INTENSITY_MIN, DataType::UInt16, true),
        Field::new(tiles_col::INTENSITY_MAX, DataType::UInt16, true),
        Field::new(tiles_col::INTENSITY_MEAN, DataType::Float64, true),
        Field::new(tiles_col::INTENSITY_P01, DataType::UInt16, true),
        Field::new(tiles_col::INTENSITY_P50, DataType::UInt16, true),
        Field::new(tiles_col::INTENSITY_P99, DataType::UInt16, true),
        Field::new(tiles_col::GPS_TIME_MIN, DataType::Float64, true),
        Field::new(tiles_col::GPS_TIME_MAX, DataType::Float64, true),
        Field::new(tiles_col::ACQUISITION_START, ts.clone(), true),
        Field::new(tiles_col::ACQUISITION_END, ts, true),
        Field::new(tiles_col::COPC, DataType::Boolean, false),
        Field::new(tiles_col::READ_CELLS, DataType::UInt64, true),
        Field::new(tiles_col::READ_WINDOW, DataType::Utf8, true),
    ]))
}

/// The points of one cell as an `als/` batch (the columns are moved, not copied).
pub fn als_batch(p: AlsPoints, tile: &str, cell: u64) -> Result<RecordBatch> {
    let n = p.len();
    let gps_time = Float64Array::from_iter(p.gps_time.iter().map(|&t| t.is_finite().then_some(t)));
    let cols: Vec<ArrayRef> = vec![
        Arc::new(Float64Array::from(p.x)),
        Arc::new(Float64Array::from(p.y)),
        Arc::new(Float64Array::from(p.z)),
        Arc::new(UInt16Array::from(p.intensity)),
        Arc::new(UInt8Array::from(p.return_number)),
        Arc::new(UInt8Array::from(p.number_of_returns)),
        Arc::new(UInt8Array::from(p.classification)),
        Arc::new(Float32Array::from(p.scan_angle_deg)),
        Arc::new(gps_time),
        Arc::new(UInt16Array::from(p.point_source_id)),
        Arc::new(StringArray::from(vec![tile; n])),
        Arc::new(UInt64Array::from(vec![cell; n])),
    ];
    RecordBatch::try_new(als_schema(), cols).map_err(|e| Error::table(tile, e))
}

/// One Parquet file of `als/` with the x/y extent of each row group.
struct AlsFile {
    path: PathBuf,
    groups: Vec<BBox>,
    meta: ArrowReaderMetadata,
    /// What a COPC tile read in windows holds; `None`: the whole tile.
    window: Option<ReadWindow>,
}

/// The `als/` table's files and row-group extents, read once.
pub struct AlsTable {
    files: Vec<AlsFile>,
    /// (file, row group) of the extents meeting each [`COVER_CELL`] cell (extents grown by
    /// [`COVER_TOLERANCE`]).
    cover_index: HashMap<(i64, i64), Vec<(usize, usize)>>,
    /// The files of tiles read in windows whose extent meets each [`WINDOW_INDEX_CELL`] cell.
    window_index: HashMap<(i64, i64), Vec<usize>>,
}

/// Cell of the index of tiles read in windows (m): a LiDAR HD tile's side.
const WINDOW_INDEX_CELL: f64 = 1000.0;

fn window_index_cells(b: BBox) -> impl Iterator<Item = (i64, i64)> {
    let cell = |v: f64| (v / WINDOW_INDEX_CELL).floor() as i64;
    (cell(b[0])..=cell(b[2])).flat_map(move |cx| (cell(b[1])..=cell(b[3])).map(move |cy| (cx, cy)))
}

/// Cell of the coverage index (m): the ingest's cell size.
const COVER_CELL: f64 = CELL_SIZE_M;

/// Gap (m) between the extents of neighbouring row groups still counted as covered: row-group
/// extents are those of their points, so neighbouring cells leave gaps of the point spacing.
const COVER_TOLERANCE: f64 = 1.0;

/// How much a query read.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ReadStats {
    /// Row groups read.
    pub row_groups_read: usize,
    /// Row groups in the table.
    pub row_groups_total: usize,
}

impl AlsTable {
    /// Open the `als/` table of a dataset (reads only the footers).
    pub fn open(ds: &Dataset) -> Result<Self> {
        let dir = ds.root().join(tables::ALS);
        let paths = ds
            .visible_files(tables::ALS)
            .map_err(|e| Error::file(&dir, format!("no ALS table ({e}): run `gedisim ingest als`")))?;
        let mut files = Vec::new();
        let mut cover_index: HashMap<(i64, i64), Vec<(usize, usize)>> = HashMap::new();
        let mut window_index: HashMap<(i64, i64), Vec<usize>> = HashMap::new();
        for path in paths {
            let file = File::open(&path).map_err(|e| Error::file(&path, e))?;
            let meta =
                ArrowReaderMetadata::load(&file, ArrowReaderOptions::new()).map_err(|e| Error::table(&path, e))?;
            let groups = row_group_boxes(meta.metadata(), &path)?;
            let kv: HashMap<String, String> = (meta.metadata().file_metadata().key_value_metadata())
                .map(|kv| kv.iter().filter_map(|k| Some((k.key.clone(), k.value.clone()?))).collect())
                .unwrap_or_default();
            let window = window_of(&path, &kv)?;
            for (g, b) in groups.iter().enumerate() {
                let cell = |v: f64| (v / COVER_CELL).floor() as i64;
                let t = COVER_TOLERANCE;
                for cx in cell(b[0] - t)..=cell(b[2] + t) {
                    for cy in cell(b[1] - t)..=cell(b[3] + t) {
                        cover_index.entry((cx, cy)).or_default().push((files.len(), g));
                    }
                }
            }
            if let Some(w) = &window {
                window_index_cells(w.extent).for_each(|c| window_index.entry(c).or_default().push(files.len()));
            }
            files.push(AlsFile { path, groups, meta, window });
        }
        Ok(AlsTable { files, cover_index, window_index })
    }

    /// Whether the row groups' extents cover the disc of `radius` around (x, y): its centre and
    /// eight points on its rim each lie in some extent (grown by 1 m). A quick test from the
    /// footers that reads no point.
    pub fn covers(&self, x: f64, y: f64, radius: f64) -> bool {
        if !(x.is_finite() && y.is_finite()) {
            return false;
        }
        let inside = |px: f64, py: f64| {
            let key = ((px / COVER_CELL).floor() as i64, (py / COVER_CELL).floor() as i64);
            let t = COVER_TOLERANCE;
            self.cover_index.get(&key).is_some_and(|v| {
                v.iter().any(|&(f, g)| {
                    let (b, window) = (self.files[f].groups[g], &self.files[f].window);
                    px >= b[0] - t
                        && px <= b[2] + t
                        && py >= b[1] - t
                        && py <= b[3] + t
                        && window.as_ref().is_none_or(|w| w.cells.contains(px, py))
                })
            })
        };
        inside(x, y)
            && (0..8).all(|k| {
                let a = k as f64 * std::f64::consts::FRAC_PI_4;
                inside(x + radius * a.cos(), y + radius * a.sin())
            })
    }

    /// The `als/` file of a tile read in windows whose extent the square of half-width `half`
    /// around (x, y) reaches outside the cells read: the tile's points there were never read, so
    /// a simulation would see part of the ALS.
    pub fn unread_window(&self, x: f64, y: f64, half: f64) -> Option<&Path> {
        if self.window_index.is_empty() || !(x.is_finite() && y.is_finite()) {
            return None;
        }
        let square = [x - half, y - half, x + half, y + half];
        let cells = Cells::around([(x, y)], half);
        let mut candidates: Vec<usize> =
            window_index_cells(square).filter_map(|c| self.window_index.get(&c)).flatten().copied().collect();
        candidates.sort_unstable();
        candidates.dedup();
        candidates.into_iter().map(|i| &self.files[i]).find_map(|f| {
            let w = f.window.as_ref()?;
            (!cells.within(w.extent).without(&w.cells).is_empty()).then_some(f.path.as_path())
        })
    }

    /// x, y, z of the points inside any of `boxes` (inclusive), reading only those three columns
    /// of the row groups that meet a box, in parallel.
    pub fn xyz_in_boxes(&self, boxes: &[BBox]) -> Result<(PointCloud, ReadStats)> {
        let meets = |g: &BBox, b: &BBox| g[0] <= b[2] && g[2] >= b[0] && g[1] <= b[3] && g[3] >= b[1];
        let mut jobs: Vec<(usize, usize, Vec<BBox>)> = Vec::new();
        for (fi, f) in self.files.iter().enumerate() {
            for (g, gb) in f.groups.iter().enumerate() {
                let hit: Vec<BBox> = boxes.iter().filter(|b| meets(gb, b)).copied().collect();
                if !hit.is_empty() {
                    jobs.push((fi, g, hit));
                }
            }
        }
        let parts =
            jobs.par_iter().map(|(fi, g, hit)| self.read_xyz(*fi, *g, hit)).collect::<Result<Vec<PointCloud>>>()?;
        let n = parts.iter().map(PointCloud::len).sum();
        let mut out = PointCloud { x: Vec::with_capacity(n), y: Vec::with_capacity(n), z: Vec::with_capacity(n) };
        for p in parts {
            out.x.extend_from_slice(&p.x);
            out.y.extend_from_slice(&p.y);
            out.z.extend_from_slice(&p.z);
        }
        Ok((out, ReadStats { row_groups_read: jobs.len(), row_groups_total: self.row_groups() }))
    }

    /// x, y, z of row group `g` of file `fi`, kept when inside one of `boxes`.
    fn read_xyz(&self, fi: usize, g: usize, boxes: &[BBox]) -> Result<PointCloud> {
        let f = &self.files[fi];
        let file = File::open(&f.path).map_err(|e| Error::file(&f.path, e))?;
        let builder = ParquetRecordBatchReaderBuilder::new_with_metadata(file, f.meta.clone());
        let mask = ProjectionMask::columns(builder.parquet_schema(), [col::X, col::Y, col::Z]);
        let reader = builder
            .with_projection(mask)
            .with_row_groups(vec![g])
            .with_batch_size(1 << 16)
            .build()
            .map_err(|e| Error::table(&f.path, e))?;
        let mut out = PointCloud::default();
        for batch in reader {
            let batch = batch.map_err(|e| Error::table(&f.path, e))?;
            let column = |name: &str| {
                batch
                    .column_by_name(name)
                    .and_then(|c| c.as_primitive_opt::<Float64Type>())
                    .ok_or_else(|| Error::field(&f.path, name, "missing or not float64 in the ALS table"))
            };
            let (x, y, z) = (column(col::X)?.values(), column(col::Y)?.values(), column(col::Z)?.values());
            for i in 0..batch.num_rows() {
                let (px, py) = (x[i], y[i]);
                if boxes.iter().any(|b| px >= b[0] && px <= b[2] && py >= b[1] && py <= b[3]) {
                    out.x.push(px);
                    out.y.push(py);
                    out.z.push(z[i]);
                }
            }
        }
        Ok(out)
    }

    /// Number of row groups in the table.
    pub fn row_groups(&self) -> usize {
        self.files.iter().map(|f| f.groups.len()).sum()
    }

    /// Every point of the row groups that intersect any of `boxes` (a superset of the points
    /// inside the boxes, in table order).
    pub fn points_near(&self, boxes: &[BBox]) -> Result<(AlsPoints, ReadStats)> {
        self.read(boxes, None)
    }

    /// The points inside `bbox` (edges included), reading only the row groups that intersect it.
    pub fn points_in(&self, bbox: BBox) -> Result<(AlsPoints, ReadStats)> {
        self.read(&[bbox], Some(bbox))
    }

    fn read(&self, boxes: &[BBox], keep: Option<BBox>) -> Result<(AlsPoints, ReadStats)> {
        let mut out = AlsPoints::default();
        let mut stats = ReadStats { row_groups_read: 0, row_groups_total: self.row_groups() };
        for f in &self.files {
            let wanted: Vec<usize> = f
                .groups
                .iter()
                .enumerate()
                .filter(|(_, g)| boxes.iter().any(|b| g[0] <= b[2] && g[2] >= b[0] && g[1] <= b[3] && g[3] >= b[1]))
                .map(|(i, _)| i)
                .collect();
            if wanted.is_empty() {
                continue;
            }
            stats.row_groups_read += wanted.len();
            let b = super::read::open(&f.path)?;
            // The point attributes only: `tile` and `cell` are constant per row group.
            let mask = parquet::arrow::ProjectionMask::columns(b.parquet_schema(), POINT_COLUMNS.iter().copied());
            let reader = b
                .with_row_groups(wanted)
                .with_projection(mask)
                .with_batch_size(1 << 16)
                .build()
                .map_err(|e| Error::table(&f.path, e))?;
            for batch in reader {
                let batch = batch.map_err(|e| Error::table(&f.path, e))?;
                append(&mut out, &batch, keep, &f.path)?;
            }
        }
        Ok((out, stats))
    }
}

/// The columns of `als/` that make an [`AlsPoints`].
const POINT_COLUMNS: [&str; 10] = [
    col::X,
    col::Y,
    col::Z,
    col::INTENSITY,
    col::RETURN_NUMBER,
    col::NUMBER_OF_RETURNS,
    col::CLASSIFICATION,
    col::SCAN_ANGLE_DEG,
    col::GPS_TIME,
    col::POINT_SOURCE_ID,
];

fn row_group_boxes(meta: &ParquetMetaData, path: &Path) -> Result<Vec<BBox>> {
    let schema = meta.file_metadata().schema_descr();
    let column = |name: &str| {
        (0..schema.num_columns())
            .find(|&i| schema.column(i).name() == name)
            .ok_or_else(|| Error::field(path, name, "column missing from the ALS table"))
    };
    let (xi, yi) = (column(col::X)?, column(col::Y)?);
    let range = |g: usize, i: usize, name: &str| match meta.row_group(g).column(i).statistics() {
        Some(Statistics::Double(s)) => match (s.min_opt(), s.max_opt()) {
            (Some(a), Some(b)) => Ok((*a, *b)),
            _ => Err(Error::field(path, name, "row group without min/max statistics")),
        },
        _ => Err(Error::field(path, name, "row group without f64 statistics")),
    };
    (0..meta.num_row_groups())
        .map(|g| {
            let (x0, x1) = range(g, xi, col::X)?;
            let (y0, y1) = range(g, yi, col::Y)?;
            Ok([x0, y0, x1, y1])
        })
        .collect()
}

/// Append the rows of `b` (those inside `keep`, when given) to `out`.
fn append(out: &mut AlsPoints, b: &arrow::record_batch::RecordBatch, keep: Option<BBox>, path: &Path) -> Result<()> {
    let column = |name: &str| {
        b.column_by_name(name).ok_or_else(|| Error::field(path, name, "column missing from the ALS table"))
    };
    let (x, y) = (
        column(col::X)?.as_primitive::<Float64Type>().values(),
        column(col::Y)?.as_primitive::<Float64Type>().values(),
    );
    let rows: Vec<usize> = match keep {
        Some(k) => {
            (0..b.num_rows()).filter(|&i| x[i] >= k[0] && x[i] <= k[2] && y[i] >= k[1] && y[i] <= k[3]).collect()
        }
        None => (0..b.num_rows()).collect(),
    };
    fn put<T: Copy>(dst: &mut Vec<T>, src: &[T], rows: &[usize]) {
        if rows.len() == src.len() {
            dst.extend_from_slice(src);
        } else {
            dst.extend(rows.iter().map(|&i| src[i]));
        }
    }
    put(&mut out.x, x, &rows);
    put(&mut out.y, y, &rows);
    put(&mut out.z, column(col::Z)?.as_primitive::<Float64Type>().values(), &rows);
    put(&mut out.intensity, column(col::INTENSITY)?.as_primitive::<UInt16Type>().values(), &rows);
    put(&mut out.return_number, column(col::RETURN_NUMBER)?.as_primitive::<UInt8Type>().values(), &rows);
    put(&mut out.number_of_returns, column(col::NUMBER_OF_RETURNS)?.as_primitive::<UInt8Type>().values(), &rows);
    put(&mut out.classification, column(col::CLASSIFICATION)?.as_primitive::<UInt8Type>().values(), &rows);
    put(&mut out.scan_angle_deg, column(col::SCAN_ANGLE_DEG)?.as_primitive::<Float32Type>().values(), &rows);
    let gps = column(col::GPS_TIME)?.as_primitive::<Float64Type>();
    out.gps_time.extend(rows.iter().map(|&i| if gps.is_null(i) { f64::NAN } else { gps.value(i) }));
    put(&mut out.point_source_id, column(col::POINT_SOURCE_ID)?.as_primitive::<UInt16Type>().values(), &rows);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use arrow::array::{Float32Array, Int64Array};

    fn table(columns: Vec<(&str, ArrayRef)>) -> RecordBatch {
        RecordBatch::try_from_iter(columns).unwrap()
    }

    fn required(x: Vec<f64>) -> Vec<(&'static str, ArrayRef)> {
        let n = x.len();
        vec![
            (col::X, Arc::new(Float64Array::from(x)) as ArrayRef),
            (col::Y, Arc::new(Float32Array::from(vec![2.5f32; n]))),
            (col::Z, Arc::new(Int64Array::from(vec![100i64; n]))),
            (col::INTENSITY, Arc::new(Int64Array::from(vec![300i64; n]))),
            (col::RETURN_NUMBER, Arc::new(Int64Array::from(vec![1i64; n]))),
            (col::NUMBER_OF_RETURNS, Arc::new(Int64Array::from(vec![2i64; n]))),
            (col::CLASSIFICATION, Arc::new(Int64Array::from(vec![5i64; n]))),
        ]
    }

    #[test]
    fn a_points_table_is_cast_and_checked() {
        let source = Path::new("points");
        let p = points_from_batches(&[table(required(vec![1.0, 2.0])), table(required(vec![3.0]))], source).unwrap();
        assert_eq!(p.x, [1.0, 2.0, 3.0]);
        assert_eq!((p.y[0], p.z[0], p.intensity[0], p.number_of_returns[0]), (2.5, 100.0, 300, 2));
        // The optional columns: no scan angle is 0°, no GPS time NaN, no flight line 0.
        assert_eq!((p.scan_angle_deg[2], p.point_source_id[2]), (0.0, 0));
        assert!(p.gps_time.iter().all(|t| t.is_nan()));

        let err =
            |b: RecordBatch| points_from_batches(&[table(required(vec![0.0])), b], source).unwrap_err().to_string();
        let mut big = required(vec![0.0]);
        big[3].1 = Arc::new(Int64Array::from(vec![70_000i64]));
        let said = err(table(big));
        assert!(said.contains("intensity: Int64 cannot be read as UInt16"), "{said}");
        let mut null = required(vec![0.0]);
        null[6].1 = Arc::new(Int64Array::from(vec![None]));
        assert!(err(table(null)).contains("classification: null at row 1"));
        assert!(err(table(required(vec![f64::NAN]))).contains("x: NaN at row 1: not a position"));
        assert!(err(table(required(vec![0.0])[1..].to_vec())).contains("x: column missing"));
        assert!(points_from_batches(&[table(required(vec![]))], source).unwrap_err().to_string().contains("no point"));
    }
}
