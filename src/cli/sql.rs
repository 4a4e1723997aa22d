//! `gedisim sql`.

use std::path::PathBuf;

use clap::Args;

use gedisim::{Error, Result};

#[derive(Args)]
pub struct SqlArgs {
    /// Dataset directory.
    #[arg(long)]
    dataset: PathBuf,
    /// The SQL statement (or use -f).
    query: Option<String>,
    /// File holding the SQL statement.
    #[arg(short = 'f', long = "file")]
    file: Option<PathBuf>,
    /// Write the result to this Parquet or CSV file instead of printing it.
    #[arg(long)]
    out: Option<PathBuf>,
}

pub fn sql(a: SqlArgs) -> Result<()> {
    let query = match (a.query, a.file) {
        (Some(q), None) => q,
        (None, Some(f)) => std::fs::read_to_string(&f).map_err(|e| Error::file(&f, e))?,
        _ => return Err(Error::Usage("give either a SQL statement or -f <file>".into())),
    };
    if let Some(table) = gedisim::ops::sql::sql(&a.dataset, &query, a.out.as_deref())? {
        println!("{table}");
    }
    Ok(())
}
