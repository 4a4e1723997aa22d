//! `gedisim export geoparquet`.

use std::path::PathBuf;
use tracing::info;

use clap::Args;

use gedisim::Result;

#[derive(Args)]
pub struct ExportGeoArgs {
    /// Dataset directory.
    #[arg(long)]
    dataset: PathBuf,
    /// Table to export: shots or results.
    #[arg(long)]
    table: String,
    /// Output file (.parquet).
    #[arg(long)]
    out: PathBuf,
}

pub fn export_geoparquet(a: ExportGeoArgs) -> Result<()> {
    let rows = gedisim::ops::export::export_geoparquet(&a.dataset, &a.table, &a.out)?;
    info!("{rows} rows → {}", a.out.display());
    Ok(())
}
