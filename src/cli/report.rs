//! `gedisim report`.

use std::path::PathBuf;
use tracing::info;

use super::reporters::Bars;
use clap::Args;

use gedisim::Result;

#[derive(Args)]
pub struct ReportArgs {
    /// Dataset directory (with a results table).
    #[arg(long)]
    dataset: PathBuf,
    /// Output directory (default <dataset>/report).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Show a diagnosis in report.html: the folder `gedisim diagnose --out` wrote.
    #[arg(long, value_name = "DIR")]
    diagnosis: Option<PathBuf>,
    /// Run the report's queries on the Ballista cluster whose scheduler is at this address
    /// (`gedisim cluster`); every node must see the dataset at the same path.
    #[arg(long, value_name = "df://HOST:PORT")]
    cluster: Option<String>,
}

pub fn report(a: ReportArgs) -> Result<()> {
    let ds = gedisim::dataset::Dataset::create(&a.dataset)?;
    let engine = a.cluster.map(gedisim::ops::report::Engine::Cluster).unwrap_or_default();
    let opts = gedisim::ops::report::ReportOptions { out: a.out, diagnosis: a.diagnosis };
    let s = gedisim::ops::report::run_report(&ds, &opts, &engine, &Bars::new())?;
    for (name, rows) in &s.tables {
        info!("{name}: {rows} rows");
    }
    for (name, missing) in &s.skipped {
        info!("{name}: skipped (no {} table)", missing.join(", "));
    }
    for note in &s.figure_notes {
        info!("figure not drawn: {note}");
    }
    info!(
        "{} tables, {} figures (PNG + SVG), {} GeoParquet files → {}",
        s.tables.len(),
        s.figures.len() / 2,
        s.geoparquet.len(),
        s.html.display()
    );
    Ok(())
}
