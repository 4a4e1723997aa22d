//! Reading ALS points back from the dataset's `als/` table around footprints, touching only the
//! row groups whose x/y statistics intersect a footprint's box (the table is clustered by cell).

use std::fs::File;
use std::path::{Path, PathBuf};

use arrow::array::{Array, AsArray};
use arrow::datatypes::{Float32Type, Float64Type, UInt16Type, UInt8Type};
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use parquet::file::metadata::ParquetMetaData;
use parquet::file::statistics::Statistics;

use crate::dataset::{self, tables, Dataset};
use crate::error::{Error, Result};
use crate::sim::AlsPoints;

/// Axis-aligned box [xmin, ymin, xmax, ymax].
pub type BBox = [f64; 4];

/// One Parquet file of `als/` with the x/y extent of each row group.
struct AlsFile {
    path: PathBuf,
    groups: Vec<BBox>,
}

/// The `als/` table's files and row-group extents, read once.
pub struct AlsTable {
    files: Vec<AlsFile>,
}

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
        let paths = dataset::table_files(&dir).map_err(|e| Error::file(&dir, format!("no ALS table ({e}): run `gedisim ingest als`")))?;
        let mut files = Vec::new();
        for path in paths {
            let file = File::open(&path).map_err(|e| Error::file(&path, e))?;
            let builder = ParquetRecordBatchReaderBuilder::try_new(file).map_err(|e| Error::table(&path, e))?;
            let groups = row_group_boxes(builder.metadata(), &path)?;
            files.push(AlsFile { path, groups });
        }
        Ok(AlsTable { files })
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
            let file = File::open(&f.path).map_err(|e| Error::file(&f.path, e))?;
            let reader = ParquetRecordBatchReaderBuilder::try_new(file)
                .and_then(|b| {
                    // The point attributes only: `tile` and `cell` are constant per row group.
                    let columns = POINT_COLUMNS.iter().copied();
                    let mask = parquet::arrow::ProjectionMask::columns(b.parquet_schema(), columns);
                    b.with_row_groups(wanted).with_projection(mask).with_batch_size(1 << 16).build()
                })
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
    "x",
    "y",
    "z",
    "intensity",
    "return_number",
    "number_of_returns",
    "classification",
    "scan_angle_deg",
    "gps_time",
    "point_source_id",
];

fn row_group_boxes(meta: &ParquetMetaData, path: &Path) -> Result<Vec<BBox>> {
    let schema = meta.file_metadata().schema_descr();
    let col = |name: &str| {
        (0..schema.num_columns())
            .find(|&i| schema.column(i).name() == name)
            .ok_or_else(|| Error::field(path, name, "column missing from the ALS table"))
    };
    let (xi, yi) = (col("x")?, col("y")?);
    let range = |g: usize, i: usize, name: &str| match meta.row_group(g).column(i).statistics() {
        Some(Statistics::Double(s)) => match (s.min_opt(), s.max_opt()) {
            (Some(a), Some(b)) => Ok((*a, *b)),
            _ => Err(Error::field(path, name, "row group without min/max statistics")),
        },
        _ => Err(Error::field(path, name, "row group without f64 statistics")),
    };
    (0..meta.num_row_groups())
        .map(|g| {
            let (x0, x1) = range(g, xi, "x")?;
            let (y0, y1) = range(g, yi, "y")?;
            Ok([x0, y0, x1, y1])
        })
        .collect()
}

/// Append the rows of `b` (those inside `keep`, when given) to `out`.
fn append(out: &mut AlsPoints, b: &arrow::record_batch::RecordBatch, keep: Option<BBox>, path: &Path) -> Result<()> {
    let col = |name: &str| b.column_by_name(name).ok_or_else(|| Error::field(path, name, "column missing from the ALS table"));
    let (x, y) = (col("x")?.as_primitive::<Float64Type>().values(), col("y")?.as_primitive::<Float64Type>().values());
    let rows: Vec<usize> = match keep {
        Some(k) => (0..b.num_rows()).filter(|&i| x[i] >= k[0] && x[i] <= k[2] && y[i] >= k[1] && y[i] <= k[3]).collect(),
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
    put(&mut out.z, col("z")?.as_primitive::<Float64Type>().values(), &rows);
    put(&mut out.intensity, col("intensity")?.as_primitive::<UInt16Type>().values(), &rows);
    put(&mut out.return_number, col("return_number")?.as_primitive::<UInt8Type>().values(), &rows);
    put(&mut out.number_of_returns, col("number_of_returns")?.as_primitive::<UInt8Type>().values(), &rows);
    put(&mut out.classification, col("classification")?.as_primitive::<UInt8Type>().values(), &rows);
    put(&mut out.scan_angle_deg, col("scan_angle_deg")?.as_primitive::<Float32Type>().values(), &rows);
    let gps = col("gps_time")?.as_primitive::<Float64Type>();
    out.gps_time.extend(rows.iter().map(|&i| if gps.is_null(i) { f64::NAN } else { gps.value(i) }));
    put(&mut out.point_source_id, col("point_source_id")?.as_primitive::<UInt16Type>().values(), &rows);
    Ok(())
}
