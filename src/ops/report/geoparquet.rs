//! GeoParquet 1.1 hand-off of the `shots` and `results` tables: every column of the table, plus
//! a WKB point `geometry` column and a `bbox` covering column (struct of xmin, ymin, xmax, ymax),
//! with the `geo` key-value metadata that GeoPandas, DuckDB spatial and GDAL read.
//!
//! Positions: the shot's lowest mode (lat/lon_lowestmode) when valid, else the mean of the L1B
//! bin0 and last bin (the same rule as `shots.x`, `shots.y`); a shot with neither has a null
//! geometry. `results` rows take the position of their shot (a join on `shot_number`).

use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

use arrow::array::{Array, ArrayRef, AsArray, BinaryBuilder, Float64Array, RecordBatch, StructArray};
use arrow::datatypes::{DataType, Field, Fields, Float64Type, Schema, SchemaRef};
use futures::StreamExt;

use crate::dataset::{self, tables, AtomicParquet, Dataset};
use crate::error::{Error, Result};

/// Coordinate reference system of the geometry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GeoCrs {
    /// Longitude, latitude in degrees (OGC:CRS84, the GeoParquet default: no `crs` key).
    Wgs84,
}

/// Tables that can be exported.
pub const EXPORTABLE: [&str; 2] = [tables::SHOTS, tables::RESULTS];

/// WKB of a 2-D point, little-endian (21 bytes).
pub fn wkb_point(x: f64, y: f64) -> [u8; 21] {
    let mut b = [0u8; 21];
    b[0] = 1; // little-endian
    b[1..5].copy_from_slice(&1u32.to_le_bytes()); // wkbPoint
    b[5..13].copy_from_slice(&x.to_le_bytes());
    b[13..21].copy_from_slice(&y.to_le_bytes());
    b
}

/// The `geo` metadata value (GeoParquet 1.1) for a point column `geometry` with a `bbox` covering.
pub fn geo_metadata(bbox: Option<[f64; 4]>) -> String {
    let mut col = serde_json::json!({
        "encoding": "WKB",
        "geometry_types": ["Point"],
        "covering": {"bbox": {
            "xmin": ["bbox", "xmin"], "ymin": ["bbox", "ymin"],
            "xmax": ["bbox", "xmax"], "ymax": ["bbox", "ymax"]
        }}
    });
    if let Some(b) = bbox {
        col["bbox"] = serde_json::json!(b);
    }
    serde_json::json!({"version": "1.1.0", "primary_column": "geometry", "columns": {"geometry": col}}).to_string()
}

fn bbox_fields() -> Fields {
    Fields::from(["xmin", "ymin", "xmax", "ymax"].map(|n| Field::new(n, DataType::Float64, false)).to_vec())
}

/// The SQL that reads `table` with its position (`__lon`, `__lat`).
fn select(table: &str) -> Result<String> {
    const LON: &str = "COALESCE(s.lon_lowestmode, (s.lon_bin0 + s.lon_lastbin) / 2)";
    const LAT: &str = "COALESCE(s.lat_lowestmode, (s.lat_bin0 + s.lat_lastbin) / 2)";
    match table {
        tables::SHOTS => Ok(format!("SELECT s.*, {LON} AS __lon, {LAT} AS __lat FROM shots s")),
        tables::RESULTS => Ok(format!(
            "SELECT r.*, p.__lon, p.__lat FROM results r LEFT JOIN \
             (SELECT s.shot_number, {LON} AS __lon, {LAT} AS __lat FROM shots s) p ON r.shot_number = p.shot_number"
        )),
        other => Err(Error::Usage(format!("--table {other}: GeoParquet export covers {}", EXPORTABLE.join(" and ")))),
    }
}

/// Export `table` (`shots` or `results`) of `ds` to the GeoParquet file `out` (atomically);
/// returns the number of rows.
pub async fn export(ds: &Dataset, table: &str, out: &Path, crs: GeoCrs) -> Result<u64> {
    let GeoCrs::Wgs84 = crs;
    let sql = select(table)?;
    for needed in [table, tables::SHOTS] {
        if !ds.has_table(needed) {
            return Err(Error::file(
                ds.root().join(needed),
                format!("no {needed} table: GeoParquet export of {table} needs it"),
            ));
        }
    }
    let ctx = crate::sql::session(ds).await?;
    // A table file that cannot be read is named (a stray file in a table folder), not the output.
    let read_err = |e: datafusion::error::DataFusionError, or: &dyn Fn(datafusion::error::DataFusionError) -> Error| {
        crate::sql::unreadable_cause(ds, &e).unwrap_or_else(|| or(e))
    };
    let df = ctx
        .sql(&sql)
        .await
        .map_err(|e| read_err(e, &|e| Error::field(ds.root().join(table), "GeoParquet export", e)))?;
    let in_schema: SchemaRef = super::plain_schema(df.schema().as_arrow());
    let keep: Vec<usize> =
        (0..in_schema.fields().len()).filter(|&i| !in_schema.field(i).name().starts_with("__")).collect();
    let mut fields: Vec<Field> = keep.iter().map(|&i| in_schema.field(i).clone()).collect();
    fields.push(Field::new("geometry", DataType::Binary, true));
    fields.push(Field::new("bbox", DataType::Struct(bbox_fields()), true));
    let mut meta: HashMap<String, String> = HashMap::new();
    meta.insert("geo".into(), geo_metadata(None));
    // The `geo` key goes to the file's key-value metadata (not the Arrow schema's, which would repeat it).
    let schema = Arc::new(Schema::new(fields));
    let mut writer = AtomicParquet::create(out, schema.clone(), dataset::writer_properties(&meta, 1 << 16))?;
    let mut stream = df.execute_stream().await.map_err(|e| read_err(e, &|e| Error::table(out, e)))?;
    let mut rows = 0u64;
    while let Some(batch) = stream.next().await {
        let batch = super::plain_batch(&batch.map_err(|e| read_err(e, &|e| Error::table(out, e)))?, &in_schema)?;
        let lon = column_f64(&batch, "__lon", out)?;
        let lat = column_f64(&batch, "__lat", out)?;
        let n = batch.num_rows();
        let mut geom = BinaryBuilder::with_capacity(n, n * 21);
        let (mut xs, mut ys) = (Vec::with_capacity(n), Vec::with_capacity(n));
        let mut valid = Vec::with_capacity(n);
        for i in 0..n {
            let ok = lon.is_valid(i) && lat.is_valid(i) && lon.value(i).is_finite() && lat.value(i).is_finite();
            if ok {
                geom.append_value(wkb_point(lon.value(i), lat.value(i)));
            } else {
                geom.append_null();
            }
            xs.push(if ok { lon.value(i) } else { 0.0 });
            ys.push(if ok { lat.value(i) } else { 0.0 });
            valid.push(ok);
        }
        let (x, y): (ArrayRef, ArrayRef) = (Arc::new(Float64Array::from(xs)), Arc::new(Float64Array::from(ys)));
        let bbox = StructArray::try_new(bbox_fields(), vec![x.clone(), y.clone(), x, y], Some(valid.into()))
            .map_err(|e| Error::table(out, e))?;
        let mut cols: Vec<ArrayRef> = keep.iter().map(|&i| batch.column(i).clone()).collect();
        cols.push(Arc::new(geom.finish()));
        cols.push(Arc::new(bbox));
        let b = RecordBatch::try_new(schema.clone(), cols).map_err(|e| Error::table(out, e))?;
        writer.write(&b)?;
        rows += n as u64;
    }
    writer.finish()?;
    Ok(rows)
}

fn column_f64(b: &RecordBatch, name: &str, out: &Path) -> Result<Float64Array> {
    let c = b.column_by_name(name).ok_or_else(|| Error::field(out, name, "missing"))?;
    let c = arrow::compute::cast(c, &DataType::Float64).map_err(|e| Error::field(out, name, e))?;
    Ok(c.as_primitive::<Float64Type>().clone())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wkb_point_layout() {
        let b = wkb_point(5.5, -45.25);
        assert_eq!(b[0], 1);
        assert_eq!(u32::from_le_bytes(b[1..5].try_into().unwrap()), 1);
        assert_eq!(f64::from_le_bytes(b[5..13].try_into().unwrap()), 5.5);
        assert_eq!(f64::from_le_bytes(b[13..21].try_into().unwrap()), -45.25);
    }

    #[test]
    fn geo_metadata_names_the_covering() {
        let v: serde_json::Value = serde_json::from_str(&geo_metadata(Some([1.0, 2.0, 3.0, 4.0]))).unwrap();
        assert_eq!(v["version"], "1.1.0");
        assert_eq!(v["primary_column"], "geometry");
        let g = &v["columns"]["geometry"];
        assert_eq!(g["encoding"], "WKB");
        assert_eq!(g["covering"]["bbox"]["xmin"][0], "bbox");
        assert_eq!(g["bbox"][3], 4.0);
        assert!(g.get("crs").is_none(), "no crs key: OGC:CRS84");
    }

    #[test]
    fn only_shots_and_results() {
        assert!(select("sim").is_err());
    }
}
