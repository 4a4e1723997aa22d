//! The `strata/` table: the forest type of every shot (docs/schemas.md).

use std::collections::HashMap;
use std::sync::Arc;

use arrow::array::{ArrayRef, StringArray, UInt16Array, UInt64Array};
use arrow::datatypes::{DataType, Field, Schema, SchemaRef};
use arrow::record_batch::RecordBatch;

use super::{read, tables, Dataset};
use crate::error::{Error, Result};
use crate::kernels::study::classes::Stratum;

/// The names of the `strata/` columns (docs/schemas.md), one constant each.
pub mod col {
    pub const SHOT_NUMBER: &str = "shot_number";
    pub const FOREST_TYPE: &str = "forest_type";
    pub const SOURCE: &str = "source";
    pub const CLC_CODE: &str = "clc_code";
}

/// Schema of the `strata` table.
pub fn strata_schema() -> SchemaRef {
    Arc::new(Schema::new(vec![
        Field::new(col::SHOT_NUMBER, DataType::UInt64, false),
        Field::new(col::FOREST_TYPE, DataType::Utf8, false),
        Field::new(col::SOURCE, DataType::Utf8, false),
        Field::new(col::CLC_CODE, DataType::UInt16, true),
    ]))
}

/// Key-value metadata of a `strata/` file: where the forest types came from.
pub fn strata_metadata(source: &str) -> HashMap<String, String> {
    HashMap::from([("gedisim:strata_source".to_string(), source.to_string())])
}

/// Strata rows as a record batch.
pub fn strata_batch(strata: &[Stratum], source: &str) -> Result<RecordBatch> {
    let columns: Vec<ArrayRef> = vec![
        Arc::new(strata.iter().map(|s| s.shot_number).collect::<UInt64Array>()),
        Arc::new(strata.iter().map(|s| Some(s.forest_type)).collect::<StringArray>()),
        Arc::new(StringArray::from(vec![source; strata.len()])),
        Arc::new(strata.iter().map(|s| s.clc_code).collect::<UInt16Array>()),
    ];
    RecordBatch::try_new(strata_schema(), columns).map_err(|e| Error::table("strata", e))
}

/// Shot → forest type from `strata/` (empty without the table).
pub fn read_forest_types(ds: &Dataset) -> Result<HashMap<u64, String>> {
    let mut out = HashMap::new();
    if !ds.has_table(tables::STRATA) {
        return Ok(out);
    }
    let dir = ds.root().join(tables::STRATA);
    for path in super::table_files(&dir).map_err(|e| Error::file(&dir, e))? {
        read::for_each_batch(&path, Some(&[col::SHOT_NUMBER, col::FOREST_TYPE]), None, |c| {
            for i in 0..c.num_rows() {
                if let (Some(s), Some(f)) = (c.u64(col::SHOT_NUMBER, i)?, c.string(col::FOREST_TYPE, i)?) {
                    out.insert(s, f);
                }
            }
            Ok(())
        })?;
    }
    Ok(out)
}
