//! `gedisim sql`: one SQL statement over a dataset's tables (a directory, or an object store by URL;
//! with gedisim's functions), printed as a table or written to a Parquet or CSV file.
//!
//! Read-only by default: DDL, DML and `COPY` need `allow_writes`, and even then no statement may
//! name a location inside the dataset (its tables change only through gedisim's commands).

use std::path::{Path, PathBuf};

use datafusion::logical_expr::{DdlStatement, LogicalPlan};

use crate::dataset::Dataset;
use crate::error::{Error, Result};
pub use crate::sql::{Engine, SessionLimits};

/// Run `query` on `dataset` (a directory, or an `s3://`, `http(s)://` URL) with `engine`; the result as a
/// text table, or written to `out` (then `None`).
pub fn sql(
    dataset: &Path,
    query: &str,
    out: Option<&Path>,
    limits: &SessionLimits,
    engine: &Engine,
) -> Result<Option<String>> {
    // A dataset by URL (an object store) or a directory.
    if limits.allow_writes && crate::io::source::is_remote(dataset) {
        return Err(Error::Usage(format!(
            "--allow-writes: not with a dataset by URL ({}): no statement may write where its tables are",
            dataset.display()
        )));
    }
    let (ds, url) = match crate::io::source::is_remote(dataset) {
        true => (None, Some(url::Url::parse(&dataset.to_string_lossy()).map_err(|e| Error::file(dataset, e))?)),
        false => (Some(Dataset::open(dataset)?), None),
    };
    let sql_err = |e: datafusion::error::DataFusionError| {
        Error::Usage(format!("SQL: {}", crate::error::one_line(&e.to_string())))
    };
    crate::sql::runtime()?.block_on(async move {
        let ctx = match (&ds, &url) {
            (_, Some(url)) => crate::sql::session_at_url(url, limits, engine).await?,
            (Some(ds), None) => crate::sql::session_on(ds, limits, engine).await?,
            (None, None) => return Err(Error::Usage("no dataset".into())),
        };
        let plan = ctx.state().create_logical_plan(query).await.map_err(sql_err)?;
        crate::sql::statement_options(limits).verify_plan(&plan).map_err(|e| {
            Error::Usage(format!(
                "SQL: {} (gedisim sql is read-only; --allow-writes permits it)",
                crate::error::one_line(&e.to_string())
            ))
        })?;
        if let Some(location) = ds.as_ref().and_then(|ds| location_inside(&plan, ds.root())) {
            return Err(Error::Usage(format!(
                "SQL: {location} lies inside the dataset {}: its tables change only through gedisim's commands",
                dataset.display()
            )));
        }
        let df = ctx.execute_logical_plan(plan).await.map_err(sql_err)?;
        let batches = df.collect().await.map_err(sql_err)?;
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

/// The location a `COPY … TO` or `CREATE EXTERNAL TABLE` of `plan` names inside `root`, if any.
fn location_inside(plan: &LogicalPlan, root: &Path) -> Option<String> {
    let locations = match plan {
        LogicalPlan::Copy(copy) => vec![copy.output_url.clone()],
        LogicalPlan::Ddl(DdlStatement::CreateExternalTable(t)) => t.locations.clone(),
        _ => return None,
    };
    let root = root.canonicalize().ok()?;
    locations.into_iter().find(|location| {
        let path = PathBuf::from(location.strip_prefix("file://").unwrap_or(location));
        let Ok(cwd) = std::env::current_dir() else { return true };
        let path = if path.is_absolute() { path } else { cwd.join(path) };
        // The deepest existing ancestor, resolved (the target itself may not exist yet).
        path.ancestors().find(|p| p.exists()).and_then(|p| p.canonicalize().ok()).is_some_and(|p| p.starts_with(&root))
    })
}
