//! The `offsets` table: one row per collocated segment (docs/contracts.md, "Collocate"), and the
//! per-shot lookup that `simulate` applies.

use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

use arrow::array::{ArrayRef, AsArray, Float64Array, ListBuilder, StringArray, UInt32Array, UInt64Builder};
use arrow::datatypes::{DataType, Field, Schema, SchemaRef, UInt64Type};
use arrow::record_batch::RecordBatch;

use crate::dataset::{self, read, tables, Dataset};
use crate::error::{Error, Result};

/// One solved segment.
#[derive(Debug, Clone, PartialEq)]
pub struct OffsetRow {
    /// `<granule>:<beam or ALL>:<first shot number>` (at the shot level, the shot itself).
    pub segment_id: String,
    pub granule: String,
    /// Beam group name, or `ALL` at the granule level.
    pub beam: String,
    /// `beam`, `track` or `shot`.
    pub level: String,
    /// The shots the offset applies to.
    pub shot_numbers: Vec<u64>,
    /// Waveforms correlated (at the shot level the shot and its neighbours).
    pub n_shots: u32,
    /// m, to add to the reported position.
    pub dx: f64,
    pub dy: f64,
    /// m, GEDI height after subtracting the geoid offset minus ALS height of the same surface.
    pub dz: f64,
    /// m, mean geoid offset N used for the shots.
    pub geoid_offset: f64,
    /// Mean Pearson r at zero offset.
    pub r_before: f64,
    /// Mean Pearson r at the optimum.
    pub r_after: f64,
    pub dx_halfwidth: f64,
    pub dy_halfwidth: f64,
    pub dz_halfwidth: f64,
}

/// The names of the `offsets/` columns (docs/schemas.md), one constant each.
pub mod col {
    pub const SEGMENT_ID: &str = "segment_id";
    pub const GRANULE: &str = "granule";
    pub const BEAM: &str = "beam";
    pub const LEVEL: &str = "level";
    pub const SHOT_NUMBERS: &str = "shot_numbers";
    pub const N_SHOTS: &str = "n_shots";
    pub const DX: &str = "dx";
    pub const DY: &str = "dy";
    pub const DZ: &str = "dz";
    pub const GEOID_OFFSET: &str = "geoid_offset";
    pub const R_BEFORE: &str = "r_before";
    pub const R_AFTER: &str = "r_after";
    pub const DX_HALFWIDTH: &str = "dx_halfwidth";
    pub const DY_HALFWIDTH: &str = "dy_halfwidth";
    pub const DZ_HALFWIDTH: &str = "dz_halfwidth";
}

/// Key-value metadata of an `offsets/` file: the collocation's level (`mixed` when the file holds
/// segments of several), its search half-width and step (m).
pub fn offsets_metadata(level: &str, max_shift_m: f64, step_m: f64) -> HashMap<String, String> {
    HashMap::from([
        (meta::LEVEL.to_string(), level.to_string()),
        (meta::MAX_SHIFT.to_string(), max_shift_m.to_string()),
        (meta::STEP.to_string(), step_m.to_string()),
    ])
}

/// Parquet key-value metadata keys of an `offsets/` file.
pub mod meta {
    pub const LEVEL: &str = "gedisim:collocate_level";
    pub const MAX_SHIFT: &str = "gedisim:max_shift_m";
    pub const STEP: &str = "gedisim:step_m";
}

/// Schema of the offsets table.
pub fn offsets_schema() -> SchemaRef {
    let f = |n: &str, t: DataType| Field::new(n, t, false);
    Arc::new(Schema::new(vec![
        f(col::SEGMENT_ID, DataType::Utf8),
        f(col::GRANULE, DataType::Utf8),
        f(col::BEAM, DataType::Utf8),
        f(col::LEVEL, DataType::Utf8),
        f(col::SHOT_NUMBERS, DataType::List(Arc::new(Field::new_list_field(DataType::UInt64, true)))),
        f(col::N_SHOTS, DataType::UInt32),
        f(col::DX, DataType::Float64),
        f(col::DY, DataType::Float64),
        f(col::DZ, DataType::Float64),
        f(col::GEOID_OFFSET, DataType::Float64),
        f(col::R_BEFORE, DataType::Float64),
        f(col::R_AFTER, DataType::Float64),
        f(col::DX_HALFWIDTH, DataType::Float64),
        f(col::DY_HALFWIDTH, DataType::Float64),
        f(col::DZ_HALFWIDTH, DataType::Float64),
    ]))
}

/// The rows as one record batch.
pub fn offsets_batch(rows: &[OffsetRow]) -> Result<RecordBatch> {
    let strings = |f: fn(&OffsetRow) -> &str| Arc::new(StringArray::from_iter_values(rows.iter().map(f))) as ArrayRef;
    let floats = |f: fn(&OffsetRow) -> f64| Arc::new(Float64Array::from_iter_values(rows.iter().map(f))) as ArrayRef;
    let mut shots = ListBuilder::new(UInt64Builder::new());
    for r in rows {
        shots.append_value(r.shot_numbers.iter().map(|&s| Some(s)));
    }
    let cols: Vec<ArrayRef> = vec![
        strings(|r| &r.segment_id),
        strings(|r| &r.granule),
        strings(|r| &r.beam),
        strings(|r| &r.level),
        Arc::new(shots.finish()),
        Arc::new(UInt32Array::from_iter_values(rows.iter().map(|r| r.n_shots))),
        floats(|r| r.dx),
        floats(|r| r.dy),
        floats(|r| r.dz),
        floats(|r| r.geoid_offset),
        floats(|r| r.r_before),
        floats(|r| r.r_after),
        floats(|r| r.dx_halfwidth),
        floats(|r| r.dy_halfwidth),
        floats(|r| r.dz_halfwidth),
    ];
    RecordBatch::try_new(offsets_schema(), cols).map_err(|e| Error::Usage(format!("offsets table: {e}")))
}

/// The offset applied to one shot by `simulate`.
#[derive(Debug, Clone, PartialEq)]
pub struct AppliedOffset {
    /// Segment the offset comes from.
    pub segment_id: String,
    pub dx: f64,
    pub dy: f64,
    pub dz: f64,
}

/// The offset of every shot listed in `<dataset>/offsets/`, by shot number; empty when the
/// dataset has no offsets table. A shot listed twice is an error naming the file.
pub fn read_offsets(ds: &Dataset) -> Result<HashMap<u64, AppliedOffset>> {
    let dir = ds.root().join(tables::OFFSETS);
    let mut out = HashMap::new();
    if !dir.is_dir() {
        return Ok(out);
    }
    let files = dataset::table_files(&dir).map_err(|e| Error::file(&dir, e))?;
    for f in files {
        read_file(&f, &mut out)?;
    }
    Ok(out)
}

/// `r_after` of every segment of `<dataset>/offsets/`, by `segment_id`; empty without the table.
pub fn read_r_after(ds: &Dataset) -> Result<HashMap<String, f64>> {
    let dir = ds.root().join(tables::OFFSETS);
    let mut out = HashMap::new();
    if !dir.is_dir() {
        return Ok(out);
    }
    for path in dataset::table_files(&dir).map_err(|e| Error::file(&dir, e))? {
        read::for_each_batch(&path, Some(&[col::SEGMENT_ID, col::R_AFTER]), None, |c| {
            let (ids, r) = (c.strings(col::SEGMENT_ID)?, c.f64s(col::R_AFTER)?);
            for i in 0..c.num_rows() {
                out.insert(ids.value(i).to_string(), r.value(i));
            }
            Ok(())
        })?;
    }
    Ok(out)
}

fn read_file(path: &Path, out: &mut HashMap<u64, AppliedOffset>) -> Result<()> {
    read::for_each_batch(path, None, None, |c| {
        let (ids, shots) = (c.strings(col::SEGMENT_ID)?, c.lists(col::SHOT_NUMBERS)?);
        let (dx, dy, dz) = (c.f64s(col::DX)?, c.f64s(col::DY)?, c.f64s(col::DZ)?);
        for i in 0..c.num_rows() {
            let list = shots.value(i);
            let list = list
                .as_primitive_opt::<UInt64Type>()
                .ok_or_else(|| Error::field(path, col::SHOT_NUMBERS, "not a list of uint64"))?;
            for s in list.iter().flatten() {
                let applied = AppliedOffset {
                    segment_id: ids.value(i).to_string(),
                    dx: dx.value(i),
                    dy: dy.value(i),
                    dz: dz.value(i),
                };
                if !(applied.dx.is_finite() && applied.dy.is_finite()) {
                    return Err(Error::field(path, col::DX, format!("segment {}: not finite", applied.segment_id)));
                }
                if out.insert(s, applied).is_some() {
                    return Err(Error::field(path, col::SHOT_NUMBERS, format!("shot {s} is in two segments")));
                }
            }
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_round_trip_through_a_dataset() {
        let tmp = tempfile::tempdir().unwrap();
        let ds = Dataset::create(tmp.path()).unwrap();
        assert!(read_offsets(&ds).unwrap().is_empty());
        let row = OffsetRow {
            segment_id: "g:BEAM0101:7".into(),
            granule: "g".into(),
            beam: "BEAM0101".into(),
            level: "beam".into(),
            shot_numbers: vec![7, 8, u64::MAX],
            n_shots: 3,
            dx: 4.0,
            dy: -3.0,
            dz: 47.5,
            geoid_offset: 0.0,
            r_before: 0.1,
            r_after: 0.99,
            dx_halfwidth: 1.0,
            dy_halfwidth: 1.0,
            dz_halfwidth: 0.1,
        };
        let dest = ds.table_file(tables::OFFSETS, "offsets").unwrap();
        dataset::write_parquet(
            &dest,
            offsets_schema(),
            &[offsets_batch(std::slice::from_ref(&row)).unwrap()],
            &Default::default(),
        )
        .unwrap();
        let got = read_offsets(&ds).unwrap();
        assert_eq!(got.len(), 3);
        assert_eq!(got[&u64::MAX], AppliedOffset { segment_id: row.segment_id.clone(), dx: 4.0, dy: -3.0, dz: 47.5 });
        assert_eq!(read_r_after(&ds).unwrap()[&row.segment_id], 0.99);
        let twice = [row.clone(), row];
        dataset::write_parquet(&dest, offsets_schema(), &[offsets_batch(&twice).unwrap()], &Default::default())
            .unwrap();
        let err = read_offsets(&ds).unwrap_err().to_string();
        assert!(err.contains("shot_numbers") && err.contains("offsets.parquet"), "{err}");
    }
}
