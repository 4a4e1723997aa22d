//! `gedisim sql`.

use std::path::PathBuf;

use clap::Args;

use gedisim::{Error, Result};

#[derive(Args)]
#[command(after_long_help = gedisim::ops::sql::functions_help())]
pub struct SqlArgs {
    /// Dataset directory, or its URL (`s3://bucket/prefix` with the AWS_* environment, `https://…` on a
    /// WebDAV server): its tables as listed now; `gedi_simulate` needs a directory.
    #[arg(long)]
    dataset: PathBuf,
    /// SQL statements, separated by `;` (or -f; `-` or nothing with a pipe: read stdin; nothing at
    /// a terminal: the interactive mode).
    query: Option<String>,
    /// File holding SQL statements (`-`: stdin).
    #[arg(short = 'f', long = "file")]
    file: Option<PathBuf>,
    /// Interactive mode: statements ending with `;` run as they are typed, each result printed;
    /// `\q` or end of input quits.
    #[arg(short = 'i', long, conflicts_with_all = ["query", "file", "out"])]
    interactive: bool,
    /// Write the result to this file (.csv, .json or .parquet) instead of printing it.
    #[arg(long)]
    out: Option<PathBuf>,
    /// table (printed), csv or json (printed or written), parquet (written); default: table, or
    /// the format --out's extension names. CSV cells holding lists are JSON arrays.
    #[arg(long, value_enum)]
    format: Option<FormatArg>,
    /// Allow DDL (CREATE …), DML (INSERT …) and COPY … TO. Dataset tables stay read-only, and no
    /// statement may name a location inside the dataset.
    #[arg(long)]
    allow_writes: bool,
    /// Memory that sorts, joins and aggregations may use before spilling to disk or failing
    /// (e.g. 512M, 8G; default: half of the machine's memory).
    #[arg(long, value_parser = parse_size)]
    memory_limit: Option<usize>,
    /// Run on the Ballista cluster whose scheduler is at this address (`gedisim cluster`); every
    /// node must see the dataset at the same path, or its URL (with the same AWS_* environment).
    #[arg(long, value_name = "df://HOST:PORT")]
    cluster: Option<String>,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum FormatArg {
    Table,
    Csv,
    Json,
    Parquet,
}

/// `<number>[K|M|G|T]` (binary units) as bytes.
fn parse_size(s: &str) -> std::result::Result<usize, String> {
    let s = s.trim();
    let (num, unit) = s.split_at(s.find(|c: char| c.is_ascii_alphabetic()).unwrap_or(s.len()));
    let scale: f64 = match unit.to_ascii_uppercase().trim_end_matches(['B', 'I']) {
        "" => 1.0,
        "K" => 1024.0,
        "M" => 1024.0 * 1024.0,
        "G" => 1024.0 * 1024.0 * 1024.0,
        "T" => 1024.0 * 1024.0 * 1024.0 * 1024.0,
        _ => return Err(format!("unknown unit {unit:?} (use K, M, G or T)")),
    };
    match num.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok((v * scale) as usize),
        _ => Err(format!("{s:?} is not a positive size such as 512M or 8G")),
    }
}

pub fn sql(a: SqlArgs) -> Result<()> {
    use std::io::{IsTerminal, Read};
    let stdin = || -> Result<String> {
        let mut text = String::new();
        std::io::stdin().read_to_string(&mut text).map_err(|e| Error::file("stdin", e))?;
        Ok(text)
    };
    let at_terminal = a.query.is_none() && a.file.is_none() && std::io::stdin().is_terminal();
    if at_terminal && a.out.is_some() {
        return Err(Error::Usage("--out: give the SQL statements (or -f <file>) whose result it writes".into()));
    }
    let interactive = a.interactive || at_terminal;
    let query = match (a.query, a.file) {
        _ if interactive => String::new(),
        (Some(q), None) if q == "-" => stdin()?,
        (Some(q), None) => q,
        (None, Some(f)) if f.as_os_str() == "-" => stdin()?,
        (None, Some(f)) => std::fs::read_to_string(&f).map_err(|e| Error::file(&f, e))?,
        (None, None) => stdin()?,
        (Some(_), Some(_)) => return Err(Error::Usage("give either SQL statements or -f <file>, not both".into())),
    };
    let mut limits = gedisim::ops::sql::SessionLimits { allow_writes: a.allow_writes, ..Default::default() };
    if let Some(bytes) = a.memory_limit {
        limits.memory_limit = bytes;
    }
    let engine = a.cluster.map(gedisim::ops::sql::Engine::Cluster).unwrap_or_default();
    use gedisim::ops::sql::{ResultFormat, SqlFormat};
    let format = a.format.map(|f| match f {
        FormatArg::Table => SqlFormat::Table,
        FormatArg::Csv => SqlFormat::File(ResultFormat::Csv),
        FormatArg::Json => SqlFormat::File(ResultFormat::Json),
        FormatArg::Parquet => SqlFormat::File(ResultFormat::Parquet),
    });
    if interactive {
        let format = gedisim::ops::sql::result_format(None, format)?;
        let session = gedisim::ops::sql::SqlSession::open(&a.dataset, &limits, &engine)?;
        return repl(&session, format, &limits);
    }
    let mut stdout = std::io::stdout().lock();
    gedisim::ops::sql::sql(&a.dataset, &query, a.out.as_deref(), format, &limits, &engine, &mut stdout)
}

/// The interactive mode: lines gathered until they end a statement with `;` (not one inside a string or
/// comment), then run; errors printed and the session goes on; `\q`, `quit`, `exit` or the end of input ends it.
fn repl(
    session: &gedisim::ops::sql::SqlSession,
    format: gedisim::ops::sql::SqlFormat,
    limits: &gedisim::ops::sql::SessionLimits,
) -> Result<()> {
    use std::io::{BufRead, Write};
    tracing::info!(
        "gedisim sql: statements end with `;`, `\\q` quits; tables: SHOW TABLES; functions: gedisim sql --help"
    );
    let mut stdout = std::io::stdout();
    let mut print = gedisim::ops::sql::Printer::new(&mut stdout, format, limits);
    let mut buffer = String::new();
    let prompt = |more: bool| {
        eprint!("{}", if more { "     -> " } else { "gedisim> " });
        let _ = std::io::stderr().flush();
    };
    prompt(false);
    for line in std::io::stdin().lock().lines() {
        let line = line.map_err(|e| Error::file("stdin", e))?;
        let trimmed = line.trim();
        if buffer.is_empty() && matches!(trimmed, "\\q" | "quit" | "exit" | "quit;" | "exit;") {
            return Ok(());
        }
        buffer.push_str(&line);
        buffer.push('\n');
        if gedisim::ops::sql::SqlSession::statement_complete(&buffer) {
            if let Err(e) = session.run(&buffer, &mut print) {
                eprintln!("error: {}", gedisim::error::one_line(&e.to_string()));
            }
            buffer.clear();
        }
        prompt(!buffer.trim().is_empty());
    }
    if !buffer.trim().is_empty() {
        session.run(&buffer, &mut print)?;
    }
    Ok(())
}
