//! `gedisim export geoparquet`.

use std::path::PathBuf;

use clap::Args;

use gedisim::dataset::Dataset;
use gedisim::{Error, Result};


#[derive(Args)]
pub struct ExportGeoArgs {
    /// Dataset directory.
    #[arg(long)]
    pub dataset: PathBuf,
    /// Table to export: shots or results.
    #[arg(long)]
    pub table: String,
    /// Output file (.parquet).
    #[arg(long)]
    pub out: PathBuf,
}

pub fn export_geoparquet(a: ExportGeoArgs) -> Result<()> {
    let ds = Dataset::open(&a.dataset)?;
    let rt = tokio::runtime::Runtime::new().map_err(|e| Error::Usage(e.to_string()))?;
    let rows = rt.block_on(gedisim::ops::report::geoparquet::export(&ds, &a.table, &a.out, gedisim::ops::report::geoparquet::GeoCrs::Wgs84))?;
    eprintln!("{rows} rows → {}", a.out.display());
    Ok(())
}
