//! `gedisim sql`.

use std::path::PathBuf;

use clap::Args;

use gedisim::{Error, Result};

#[derive(Args)]
pub struct SqlArgs {
    /// Dataset directory, or its URL (`s3://bucket/prefix` with the AWS_* environment, `https://…` on a
    /// WebDAV server): its tables as listed now; `gedi_simulate` needs a directory.
    #[arg(long)]
    dataset: PathBuf,
    /// The SQL statement (or use -f).
    query: Option<String>,
    /// File holding the SQL statement.
    #[arg(short = 'f', long = "file")]
    file: Option<PathBuf>,
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
    let query = match (a.query, a.file) {
        (Some(q), None) => q,
        (None, Some(f)) => std::fs::read_to_string(&f).map_err(|e| Error::file(&f, e))?,
        _ => return Err(Error::Usage("give either a SQL statement or -f <file>".into())),
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
    if let Some(table) = gedisim::ops::sql::sql(&a.dataset, &query, a.out.as_deref(), format, &limits, &engine)? {
        println!("{table}");
    }
    Ok(())
}
