//! `gedisim sql`: one SQL statement over a dataset's tables (with gedisim's functions), printed as
//! a table or written to a Parquet or CSV file.

use std::path::Path;

use crate::dataset::Dataset;
use crate::error::{Error, Result};

/// Run `query` on `dataset`; the result as a text table, or written to `out` (then `None`).
pub fn sql(dataset: &Path, query: &str, out: Option<&Path>) -> Result<Option<String>> {
    let ds = Dataset::open(dataset)?;
    let rt = tokio::runtime::Runtime::new().map_err(|e| Error::Usage(e.to_string()))?;
    rt.block_on(async move {
        let ctx = crate::sql::session(&ds).await?;
        let df = ctx.sql(query).await.map_err(|e| Error::Usage(format!("SQL: {e}")))?;
        let batches = df.collect().await.map_err(|e| Error::Usage(format!("SQL: {e}")))?;
        match out {
            None => {
                let table =
                    arrow::util::pretty::pretty_format_batches(&batches).map_err(|e| Error::Usage(e.to_string()))?;
                Ok(Some(table.to_string()))
            }
            Some(out) => crate::dataset::write_result(out, &batches).map(|_| None),
        }
    })
}
