//! `gedisim sql`.

use std::path::PathBuf;

use clap::Args;

use gedisim::dataset::Dataset;
use gedisim::{Error, Result};


#[derive(Args)]
pub struct SqlArgs {
    /// Dataset directory.
    #[arg(long)]
    pub dataset: PathBuf,
    /// The SQL statement (or use -f).
    pub query: Option<String>,
    /// File holding the SQL statement.
    #[arg(short = 'f', long = "file")]
    pub file: Option<PathBuf>,
    /// Write the result to this Parquet or CSV file instead of printing it.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

pub fn sql(a: SqlArgs) -> Result<()> {
    let query = match (a.query, a.file) {
        (Some(q), None) => q,
        (None, Some(f)) => std::fs::read_to_string(&f).map_err(|e| Error::file(&f, e))?,
        _ => return Err(Error::Usage("give either a SQL statement or -f <file>".into())),
    };
    let ds = Dataset::open(&a.dataset)?;
    let rt = tokio::runtime::Runtime::new().map_err(|e| Error::Usage(e.to_string()))?;
    rt.block_on(async move {
        let ctx = gedisim::sql::session(&ds).await?;
        let df = ctx.sql(&query).await.map_err(|e| Error::Usage(format!("SQL: {e}")))?;
        let batches = df.collect().await.map_err(|e| Error::Usage(format!("SQL: {e}")))?;
        match a.out {
            None => {
                let table = arrow::util::pretty::pretty_format_batches(&batches).map_err(|e| Error::Usage(e.to_string()))?;
                println!("{table}");
            }
            Some(out) => gedisim::dataset::write_result(&out, &batches)?,
        }
        Ok(())
    })
}
