//! The `shots/` table read back: the shots' positions, moved by their collocation offsets.

use arrow::array::{Array, AsArray};
use arrow::datatypes::{Float64Type, UInt64Type};

use crate::dataset::offsets::{read_offsets, AppliedOffset};
use crate::dataset::{self, tables, Dataset};
use crate::error::{Error, Result};
use crate::kernels::sim::Footprint;

/// The shots' ids and positions (`shot_number`, `x`, `y`) from the `shots/` table, each moved by
/// its collocation offset when `<dataset>/offsets/` has one (position + (dx, dy)), with the
/// offset applied.
pub fn shot_footprints(ds: &Dataset) -> Result<Vec<(Footprint, Option<AppliedOffset>)>> {
    let offsets = read_offsets(ds)?;
    let dir = ds.root().join(tables::SHOTS);
    let files = dataset::table_files(&dir)
        .map_err(|e| Error::file(&dir, format!("no shots table ({e}): run `gedisim ingest gedi`")))?;
    let mut out = Vec::new();
    for f in files {
        let file = std::fs::File::open(&f).map_err(|e| Error::file(&f, e))?;
        let builder = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file)
            .map_err(|e| Error::table(&f, e))?;
        let mask = parquet::arrow::ProjectionMask::columns(builder.parquet_schema(), ["shot_number", "x", "y"]);
        let reader = builder.with_projection(mask).build().map_err(|e| Error::table(&f, e))?;
        for b in reader {
            let b = b.map_err(|e| Error::table(&f, e))?;
            let get =
                |n: &str| b.column_by_name(n).ok_or_else(|| Error::field(&f, n, "column missing from the shots table"));
            let (sn, x, y) = (get("shot_number")?, get("x")?, get("y")?);
            let (sn, x, y) =
                (sn.as_primitive::<UInt64Type>(), x.as_primitive::<Float64Type>(), y.as_primitive::<Float64Type>());
            for i in 0..b.num_rows() {
                if x.is_null(i) || y.is_null(i) {
                    continue;
                }
                let off = offsets.get(&sn.value(i)).cloned();
                let (dx, dy) = off.as_ref().map_or((0.0, 0.0), |o| (o.dx, o.dy));
                out.push((Footprint { id: sn.value(i).to_string(), x: x.value(i) + dx, y: y.value(i) + dy }, off));
            }
        }
    }
    Ok(out)
}
