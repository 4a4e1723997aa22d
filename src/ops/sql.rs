//! `gedisim sql`: SQL statements over a dataset's tables (a directory, or an object store by URL;
//! with gedisim's functions), printed as tables, CSV or JSON, or one result written to a CSV, JSON or
//! Parquet file; a session kept across statements for the interactive mode.
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

/// A SQL session over a dataset (a directory, or an `s3://`, `http(s)://` URL): its tables and
/// gedisim's functions, kept across statements (a view created by one is seen by the next).
pub struct SqlSession {
    runtime: tokio::runtime::Runtime,
    ctx: datafusion::prelude::SessionContext,
    ds: Option<Dataset>,
    dataset: PathBuf,
    limits: SessionLimits,
}

/// One statement's result (a statement without result columns, e.g. `CREATE VIEW`, has none).
pub type StatementResult = Vec<arrow::record_batch::RecordBatch>;

fn sql_err(e: datafusion::error::DataFusionError) -> Error {
    Error::Usage(format!("SQL: {}", crate::error::one_line(&e.to_string())))
}

impl SqlSession {
    /// The error of a failed statement; a Parquet error names the table file that cannot be read,
    /// if one cannot (a stray file in a table folder).
    fn failed(&self, e: datafusion::error::DataFusionError) -> Error {
        let parquet = matches!(e.find_root(), datafusion::error::DataFusionError::ParquetError(_))
            || e.to_string().contains("Parquet error");
        match self.ds.as_ref().filter(|_| parquet).and_then(crate::sql::unreadable_table_file) {
            Some(named) => named,
            None => sql_err(e),
        }
    }

    /// Open `dataset` with `limits` on `engine`.
    pub fn open(dataset: &Path, limits: &SessionLimits, engine: &Engine) -> Result<SqlSession> {
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
        let runtime = crate::sql::runtime()?;
        let ctx = runtime.block_on(async {
            match (&ds, &url) {
                (_, Some(url)) => crate::sql::session_at_url(url, limits, engine).await,
                (Some(ds), None) => crate::sql::session_on(ds, limits, engine).await,
                (None, None) => Err(Error::Usage("no dataset".into())),
            }
        })?;
        Ok(SqlSession { runtime, ctx, ds, dataset: dataset.to_path_buf(), limits: *limits })
    }

    /// Whether `sql` ends a statement: its last token, comments and whitespace aside, is a `;` outside any string,
    /// quoted name or comment (`'a;` followed by more lines is not; nor is `-- done;`).
    pub fn statement_complete(sql: &str) -> bool {
        use datafusion::sql::sqlparser::tokenizer::{Token, Tokenizer};
        let dialect = datafusion::sql::sqlparser::dialect::GenericDialect {};
        match Tokenizer::new(&dialect, sql).tokenize() {
            Ok(tokens) => tokens.iter().rev().find(|t| !matches!(t, Token::Whitespace(_))) == Some(&Token::SemiColon),
            Err(_) => false, // an unterminated string or quoted name: the statement goes on
        }
    }

    /// Run every statement of `sql` (separated by `;`) in order, handing `on_result` the result of
    /// each that has result columns as soon as it is known. The first failing statement ends the
    /// run with its error (the results before it were handed over).
    pub fn run(&self, sql: &str, on_result: &mut dyn FnMut(StatementResult) -> Result<()>) -> Result<()> {
        let dialect = datafusion::sql::sqlparser::dialect::GenericDialect {};
        let statements = datafusion::sql::parser::DFParser::parse_sql_with_dialect(sql, &dialect)
            .map_err(|e| Error::Usage(format!("SQL: {}", crate::error::one_line(&e.to_string()))))?;
        if statements.is_empty() {
            return Err(Error::Usage("SQL: no statement given".into()));
        }
        self.runtime.block_on(async {
            for statement in statements {
                let plan = self.ctx.state().statement_to_plan(statement).await.map_err(sql_err)?;
                crate::sql::statement_options(&self.limits).verify_plan(&plan).map_err(|e| {
                    Error::Usage(format!(
                        "SQL: {} (gedisim sql is read-only; --allow-writes permits it)",
                        crate::error::one_line(&e.to_string())
                    ))
                })?;
                if let Some(location) = self.ds.as_ref().and_then(|ds| location_inside(&plan, ds.root())) {
                    return Err(Error::Usage(format!(
                        "SQL: {location} lies inside the dataset {}: its tables change only through gedisim's commands",
                        self.dataset.display()
                    )));
                }
                let df = self.ctx.execute_logical_plan(plan).await.map_err(|e| self.failed(e))?;
                let has_columns = !df.schema().fields().is_empty();
                let batches = df.collect().await.map_err(|e| self.failed(e))?;
                if has_columns {
                    on_result(batches)?;
                }
            }
            Ok(())
        })
    }
}

/// A result as text in `format` (a table, CSV or JSON).
pub fn render(batches: &[arrow::record_batch::RecordBatch], format: SqlFormat) -> Result<String> {
    match format {
        SqlFormat::Table => {
            let table = arrow::util::pretty::pretty_format_batches(batches).map_err(|e| Error::Usage(e.to_string()))?;
            Ok(table.to_string())
        }
        SqlFormat::File(f) => {
            let text = crate::dataset::write_text(Path::new("stdout"), Vec::new(), batches, f)?;
            Ok(String::from_utf8_lossy(&text).trim_end().to_string())
        }
    }
}

/// Run the statements of `query` on `dataset` (a directory, or an `s3://`, `http(s)://` URL) with
/// `engine`: each result handed to `print` as text in `format` ([`result_format`]) as it comes,
/// or the one result written to `out` (several statements with results are an error there).
pub fn sql(
    dataset: &Path,
    query: &str,
    out: Option<&Path>,
    format: Option<SqlFormat>,
    limits: &SessionLimits,
    engine: &Engine,
    print: &mut dyn FnMut(&str),
) -> Result<()> {
    let format = result_format(out, format)?;
    if let Some(out) = out {
        crate::dataset::outside_tables(out)?;
    }
    let session = SqlSession::open(dataset, limits, engine)?;
    match (out, format) {
        (None, format) => session.run(query, &mut |batches| {
            print(&render(&batches, format)?);
            Ok(())
        }),
        (Some(out), SqlFormat::File(f)) => {
            let mut results = Vec::new();
            session.run(query, &mut |batches| {
                results.push(batches);
                Ok(())
            })?;
            match results.as_slice() {
                [one] => crate::dataset::write_result(out, one, f),
                [] => Err(Error::file(out, "no statement gave a result to write")),
                many => Err(Error::file(
                    out,
                    format!("{} statements give results: --out takes one (run the others without --out)", many.len()),
                )),
            }
        }
        (Some(out), SqlFormat::Table) => Err(Error::file(out, "a table is printed, not written")),
    }
}

/// gedisim's SQL functions and their documentation, for `gedisim sql --help`.
pub fn functions_help() -> String {
    let mut s = String::from("gedisim's SQL functions (also in information_schema.routines):\n");
    for f in crate::sql::scalar_functions() {
        if let Some(d) = f.documentation() {
            s += &format!("  {}\n      {}\n", d.syntax_example, d.description);
            if let Some(example) = &d.sql_example {
                s += &format!("      e.g. {example}\n");
            }
        }
    }
    s += "  gedi_simulate([profile])\n      Table function: the dataset's shots simulated (docs/schemas.md).\n";
    s += "RH lists hold RH0…RH100: rh(rh_sim, 98) is RH98 (in SQL the list index is 1-based: rh_sim[99]).";
    s
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
