//! `gedisim sql`: SQL statements over a dataset's tables (a directory, or an object store by URL;
//! with gedisim's functions), printed as tables, CSV or JSON, or one result written to a CSV, JSON or
//! Parquet file; a session kept across statements for the interactive mode.
//!
//! Read-only by default: DDL, DML and `COPY` need `allow_writes`, and even then no statement may
//! name a location inside the dataset (its tables change only through gedisim's commands).

mod result;

use std::io::Write;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use arrow::datatypes::SchemaRef;
use arrow::record_batch::RecordBatch;
use datafusion::logical_expr::{DdlStatement, LogicalPlan};
use datafusion::sql::parser::Statement;
use datafusion::sql::sqlparser::ast::{Expr, Visit, Visitor};
use futures::StreamExt;

use crate::dataset::Dataset;
use crate::error::{Error, Result};
pub use crate::sql::{Engine, SessionLimits};
pub use result::ResultFormat;
use result::{ResultFile, TextWriter};

/// The deepest expression gedisim plans (`a + b + …` and `x = 1 OR x = 2 OR …` nest one level per
/// operator): the planner recurses once per level, and a much deeper statement would overflow its
/// stack (docs/robustness.md). A list of values is flat: `x IN (1, 2, …)`.
pub const MAX_EXPRESSION_DEPTH: usize = 256;

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

fn sql_err(e: datafusion::error::DataFusionError) -> Error {
    Error::Usage(format!("SQL: {}", crate::error::one_line(&e.to_string())))
}

impl SqlSession {
    /// The error of a failed statement; a Parquet error names the table file that cannot be read,
    /// if one cannot (a stray file in a table folder).
    fn failed(&self, e: datafusion::error::DataFusionError) -> Error {
        match self.ds.as_ref().and_then(|ds| crate::sql::unreadable_cause(ds, &e)) {
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

    /// Run every statement of `sql` (separated by `;`) in order, each parsed when its turn comes,
    /// handing `sink` the batches of each that has result columns as they come. The first failing
    /// statement ends the run with its error (the results before it were handed over).
    pub fn run(&self, sql: &str, sink: &mut dyn ResultSink) -> Result<()> {
        use datafusion::sql::sqlparser::tokenizer::Token;
        let dialect = datafusion::sql::sqlparser::dialect::GenericDialect {};
        let mut parser =
            datafusion::sql::parser::DFParserBuilder::new(sql).with_dialect(&dialect).build().map_err(sql_err)?;
        let mut ran = 0;
        loop {
            while parser.parser.consume_token(&Token::SemiColon) {}
            if parser.parser.peek_token() == Token::EOF {
                break;
            }
            let statement = parser.parse_statement().map_err(sql_err)?;
            let next = parser.parser.peek_token();
            if !matches!(next.token, Token::SemiColon | Token::EOF) {
                return Err(Error::Usage(format!(
                    "SQL: expected the end of statement {}, found {}{}",
                    ran + 1,
                    next.token,
                    next.span.start
                )));
            }
            if too_deep(&statement) {
                // Dropping it would recurse as deep as it nests, which is what overflows: it is
                // left to the end of the process (its memory is that of its text).
                std::mem::forget(statement);
                return Err(Error::Usage(format!(
                    "SQL: statement {}: an expression nests deeper than {MAX_EXPRESSION_DEPTH} levels (each \
                     operator of `a + b + …` or `… OR …` is one): split it, or give a list of values as `x IN (…)`",
                    ran + 1
                )));
            }
            self.runtime.block_on(self.execute(statement, sink))?;
            ran += 1;
        }
        if ran == 0 {
            return Err(Error::Usage("SQL: no statement given".into()));
        }
        Ok(())
    }

    /// Every batch of the results of `sql`'s statements, in order: what a program (a notebook, a test)
    /// takes from a session instead of printed rows.
    pub fn collect(&self, sql: &str) -> Result<Vec<RecordBatch>> {
        struct Collect(Vec<RecordBatch>);
        impl ResultSink for Collect {
            fn start(&mut self, _: &SchemaRef) -> Result<()> {
                Ok(())
            }
            fn batch(&mut self, batch: &RecordBatch) -> Result<()> {
                self.0.push(batch.clone());
                Ok(())
            }
            fn end(&mut self) -> Result<()> {
                Ok(())
            }
        }
        let mut sink = Collect(Vec::new());
        self.run(sql, &mut sink)?;
        Ok(sink.0)
    }

    /// Plan, check and run one statement, its result batches handed to `sink` as they come.
    async fn execute(&self, statement: Statement, sink: &mut dyn ResultSink) -> Result<()> {
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
        let schema: SchemaRef = std::sync::Arc::new(df.schema().as_arrow().clone());
        let has_columns = !schema.fields().is_empty();
        let mut stream = df.execute_stream().await.map_err(|e| self.failed(e))?;
        if has_columns {
            sink.start(&schema)?;
        }
        while let Some(batch) = stream.next().await {
            let batch = batch.map_err(|e| self.failed(e))?;
            if has_columns {
                sink.batch(&batch)?;
            }
        }
        if has_columns {
            sink.end()?;
        }
        Ok(())
    }
}

/// Whether an expression of `statement` nests deeper than [`MAX_EXPRESSION_DEPTH`]. The walk stops
/// there, so it never recurses deeper itself.
fn too_deep(statement: &Statement) -> bool {
    struct Depth(usize);
    impl Visitor for Depth {
        type Break = ();
        fn pre_visit_expr(&mut self, _: &Expr) -> ControlFlow<()> {
            self.0 += 1;
            if self.0 > MAX_EXPRESSION_DEPTH {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        }
        fn post_visit_expr(&mut self, _: &Expr) -> ControlFlow<()> {
            self.0 -= 1;
            ControlFlow::Continue(())
        }
    }
    match statement {
        Statement::Statement(s) => s.visit(&mut Depth(0)).is_break(),
        Statement::CopyTo(c) => match &c.source {
            datafusion::sql::parser::CopyToSource::Query(q) => q.visit(&mut Depth(0)).is_break(),
            datafusion::sql::parser::CopyToSource::Relation(_) => false,
        },
        Statement::Explain(e) => too_deep(&e.statement),
        Statement::CreateExternalTable(_) | Statement::Reset(_) => false,
    }
}

/// Where [`SqlSession::run`] hands each statement's result, batch by batch as it comes.
pub trait ResultSink {
    /// A statement with result columns begins.
    fn start(&mut self, schema: &SchemaRef) -> Result<()>;
    fn batch(&mut self, batch: &RecordBatch) -> Result<()>;
    /// Its last batch was handed over.
    fn end(&mut self) -> Result<()>;
}

/// Results printed to `out`: CSV and JSON as their batches come; a table, whose column widths need
/// every row, gathered up to `budget` bytes (a larger one is refused, not grown without bound).
pub struct Printer<'a> {
    out: Option<&'a mut dyn Write>,
    text: Option<TextWriter<&'a mut dyn Write>>,
    format: SqlFormat,
    budget: usize,
    table: Vec<RecordBatch>,
    bytes: usize,
}

impl<'a> Printer<'a> {
    /// A printer to `out` in `format`, a table gathered up to half of `limits`' memory.
    pub fn new(out: &'a mut dyn Write, format: SqlFormat, limits: &SessionLimits) -> Printer<'a> {
        Printer { out: Some(out), text: None, format, budget: limits.memory_limit / 2, table: Vec::new(), bytes: 0 }
    }

    /// Back to between statements (a statement that failed midway left a result open).
    fn reset(&mut self) -> Result<()> {
        self.table.clear();
        self.bytes = 0;
        if let Some(text) = self.text.take() {
            self.out = Some(text.finish()?);
        }
        Ok(())
    }

    fn out(&mut self) -> &mut dyn Write {
        self.out.as_deref_mut().expect("the output is held between results")
    }
}

fn stdout_err(e: std::io::Error) -> Error {
    Error::file("stdout", e)
}

impl ResultSink for Printer<'_> {
    fn start(&mut self, schema: &SchemaRef) -> Result<()> {
        self.reset()?;
        if let SqlFormat::File(format) = self.format {
            let out = self.out.take().expect("the output is held between results");
            self.text = Some(TextWriter::new(Path::new("stdout"), out, schema, format)?);
        }
        Ok(())
    }

    fn batch(&mut self, batch: &RecordBatch) -> Result<()> {
        if let Some(text) = self.text.as_mut() {
            return text.write(batch);
        }
        self.bytes += batch.get_array_memory_size();
        if self.bytes > self.budget {
            self.table.clear();
            return Err(Error::Usage(format!(
                "SQL: Resources exhausted: the result passed {:.0} MiB (half of --memory-limit) before its last \
                 row, and a table is printed only whole: add LIMIT, print it as --format csv or json (row by \
                 row), or write it with --out",
                self.budget as f64 / (1024.0 * 1024.0)
            )));
        }
        self.table.push(batch.clone());
        Ok(())
    }

    fn end(&mut self) -> Result<()> {
        match self.text.take() {
            Some(text) => {
                let out = text.finish()?;
                if self.format == SqlFormat::File(ResultFormat::Json) {
                    writeln!(out).map_err(stdout_err)?; // a JSON array ends without one; CSV lines do
                }
                self.out = Some(out);
            }
            None => {
                let table = arrow::util::pretty::pretty_format_batches(&self.table)
                    .map_err(|e| Error::Usage(e.to_string()))?
                    .to_string();
                self.table.clear();
                self.bytes = 0;
                writeln!(self.out(), "{table}").map_err(stdout_err)?;
            }
        }
        self.out().flush().map_err(stdout_err)
    }
}

/// The one result `--out` takes, written to its file as it comes (renamed into place by `sql` once
/// every statement has run).
struct ResultToFile<'a> {
    out: &'a Path,
    format: ResultFormat,
    file: Option<ResultFile>,
}

impl ResultSink for ResultToFile<'_> {
    fn start(&mut self, schema: &SchemaRef) -> Result<()> {
        if self.file.is_some() {
            return Err(Error::file(
                self.out,
                "a second statement gives a result: --out takes one (run the others without --out)",
            ));
        }
        self.file = Some(ResultFile::create(self.out, schema, self.format)?);
        Ok(())
    }

    fn batch(&mut self, batch: &RecordBatch) -> Result<()> {
        self.file.as_mut().expect("started").write(batch)
    }

    fn end(&mut self) -> Result<()> {
        Ok(())
    }
}

/// Run the statements of `query` on `dataset` (a directory, or an `s3://`, `http(s)://` URL) with
/// `engine`: each result printed to `stdout` in `format` ([`result_format`]) as its batches come,
/// or the one result written to `out` (a second statement with a result is an error there, and
/// nothing is written).
pub fn sql(
    dataset: &Path,
    query: &str,
    out: Option<&Path>,
    format: Option<SqlFormat>,
    limits: &SessionLimits,
    engine: &Engine,
    stdout: &mut dyn Write,
) -> Result<()> {
    let format = result_format(out, format)?;
    if let Some(out) = out {
        crate::dataset::outside_tables(out)?;
    }
    let session = SqlSession::open(dataset, limits, engine)?;
    match (out, format) {
        (None, format) => session.run(query, &mut Printer::new(stdout, format, limits)),
        (Some(out), SqlFormat::File(format)) => {
            let mut sink = ResultToFile { out, format, file: None };
            session.run(query, &mut sink)?;
            match sink.file {
                Some(file) => file.finish(),
                None => Err(Error::file(out, "no statement gave a result to write")),
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
