//! `gedisim sql`: one SQL statement over a dataset's tables (a directory, or an object store by URL;
//! with gedisim's functions), printed as a table, CSV or JSON, or written to a CSV, JSON or Parquet file.
//!
//! Read-only by default: DDL, DML and `COPY` need `allow_writes`, and even then no statement may
//! name a location inside the dataset (its tables change only through gedisim's commands).

use std::path::{Path, PathBuf};

use datafusion::logical_expr::{DdlStatement, LogicalPlan};

use crate::dataset::Dataset;
pub use crate::dataset::ResultFormat;
use crate::error::{Error, Result};
pub use crate::sql::{Engine, SessionLimits};

/// How `sql` gives its result: printed as a text table, or as CSV, JSON or Parquet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SqlFormat {
    Table,
    File(ResultFormat),
}

/// The format of a result written to `out` (`None`: printed) given `--format`: a file's extension and
/// `--format` must agree (never CSV into a `.json` file), and one of them must name the format.
pub fn result_format(out: Option<&Path>, format: Option<SqlFormat>) -> Result<SqlFormat> {
    let Some(out) = out else {
        return match format {
            Some(SqlFormat::File(ResultFormat::Parquet)) => {
                Err(Error::Usage("--format parquet: give --out <file>.parquet (Parquet is not printed)".into()))
            }
            f => Ok(f.unwrap_or(SqlFormat::Table)),
        };
    };
    if out.is_dir() {
        return Err(Error::file(out, "is a directory: give a .csv, .json or .parquet file name"));
    }
    match (format, ResultFormat::of_file(out)) {
        (Some(SqlFormat::Table), _) => Err(Error::Usage(format!(
            "--format table prints the result: give --format csv, json or parquet with --out {}",
            out.display()
        ))),
        (Some(SqlFormat::File(f)), Some(e)) if f != e => Err(Error::Usage(format!(
            "--format {} but --out {} names {}: make them agree",
            f.name(),
            out.display(),
            e.name()
        ))),
        (Some(f), _) => Ok(f),
        (None, Some(e)) => Ok(SqlFormat::File(e)),
        (None, None) => {
            Err(Error::Usage(format!("--out {}: name a .csv, .json or .parquet file, or give --format", out.display())))
        }
    }
}

/// Run `query` on `dataset` (a directory, or an `s3://`, `http(s)://` URL) with `engine`; the result as
/// text in `format` ([`result_format`]), or written to `out` (then `None`).
pub fn sql(
    dataset: &Path,
    query: &str,
    out: Option<&Path>,
    format: Option<SqlFormat>,
    limits: &SessionLimits,
    engine: &Engine,
) -> Result<Option<String>> {
    let format = result_format(out, format)?;
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
        match (out, format) {
            (None, SqlFormat::Table) => {
                let table =
                    arrow::util::pretty::pretty_format_batches(&batches).map_err(|e| Error::Usage(e.to_string()))?;
                Ok(Some(table.to_string()))
            }
            (None, SqlFormat::File(f)) => {
                let text = crate::dataset::write_text(Path::new("stdout"), Vec::new(), &batches, f)?;
                Ok(Some(String::from_utf8_lossy(&text).trim_end().to_string()))
            }
            (Some(out), SqlFormat::File(f)) => crate::dataset::write_result(out, &batches, f).map(|_| None),
            (Some(out), SqlFormat::Table) => Err(Error::file(out, "a table is printed, not written")),
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
