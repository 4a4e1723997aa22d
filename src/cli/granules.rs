//! `gedisim granules`: the GEDI L1B and L2A V2 granules over a dataset's tiles, found through
//! NASA's CMR search, as CSV (docs/granules.md).

use std::path::PathBuf;

use clap::Args;
use tracing::info;

use gedisim::error::Error;
use gedisim::ops::granules::{Fetched, Granule};
use gedisim::Result;

#[derive(Args)]
pub struct GranulesArgs {
    /// Dataset whose ALS tiles the granules must cross.
    #[arg(long)]
    dataset: PathBuf,
    /// First day (YYYY-MM-DD, UTC).
    #[arg(long)]
    from: Option<chrono::NaiveDate>,
    /// Last day (YYYY-MM-DD, UTC), included.
    #[arg(long)]
    to: Option<chrono::NaiveDate>,
    /// CMR's address (another CMR, or a mirror that answers as CMR does).
    #[arg(long, default_value = gedisim::ops::granules::CMR)]
    cmr: String,
    /// Write the list here (CSV) instead of standard output.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Also download the granules into this folder, with the Earthdata Login bearer token in
    /// EARTHDATA_TOKEN (resumed where an earlier run stopped; checked against the sizes announced).
    #[arg(long, value_name = "DIR")]
    download: Option<PathBuf>,
    /// Downloads at once.
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u16).range(1..=16))]
    parallel: u16,
}

/// The CSV of the granules: one row per granule, L1B then L2A.
fn csv_text(granules: &[Granule]) -> Result<Vec<u8>> {
    let mut w = csv::Writer::from_writer(Vec::new());
    let err = |e: csv::Error| Error::Usage(format!("granule list: {e}"));
    w.write_record(["product", "granule_id", "time_start", "time_end", "size_mb", "url"]).map_err(err)?;
    for g in granules {
        let size = g.size_mb.map(|s| s.to_string()).unwrap_or_default();
        let url = g.url.clone().unwrap_or_default();
        w.write_record([&g.short_name, &g.granule_id, &g.time_start, &g.time_end, &size, &url]).map_err(err)?;
    }
    w.into_inner().map_err(|e| Error::Usage(format!("granule list: {e}")))
}

pub fn granules(a: GranulesArgs) -> Result<()> {
    use gedisim::ops::granules::TOKEN_VAR;
    // Before any request: a download without a token would fail only after the search.
    let token = match &a.download {
        Some(_) => Some(std::env::var(TOKEN_VAR).ok().filter(|t| !t.trim().is_empty()).ok_or_else(|| {
            Error::Usage(format!(
                "--download: set {TOKEN_VAR} to an Earthdata Login token (urs.earthdata.nasa.gov → Generate Token)"
            ))
        })?),
        None => None,
    };
    let opts = gedisim::ops::granules::GranulesOptions { cmr: a.cmr, from: a.from, to: a.to };
    let found = gedisim::ops::granules::find_granules(&a.dataset, &opts, &|product, n| {
        info!("{product}: {n} granules so far");
    })?;
    let [w, s, e, n] = found.bbox;
    let [l1b, l2a] = gedisim::ops::granules::COLLECTIONS
        .map(|(product, _)| found.granules.iter().filter(|g| g.short_name == product).count());
    let size: f64 = found.granules.iter().filter_map(|g| g.size_mb).sum();
    info!(
        "{} L1B and {} L2A granules cross the tiles (lon {w:.4}…{e:.4}, lat {s:.4}…{n:.4}), {:.1} GB announced",
        l1b,
        l2a,
        size / 1000.0
    );
    let text = csv_text(&found.granules)?;
    match &a.out {
        Some(path) => {
            gedisim::dataset::write_atomic(path, &text)?;
            info!("list → {}", path.display());
        }
        None => {
            use std::io::Write;
            std::io::stdout().write_all(&text).map_err(|e| Error::Usage(format!("stdout: {e}")))?;
        }
    }
    if let (Some(dir), Some(token)) = (&a.download, token) {
        let progress = crate::cli::reporters::Bars::new();
        let fetched = gedisim::ops::granules::download(&found, dir, token.trim(), usize::from(a.parallel), &progress)?;
        let (mut new, mut resumed, mut present, mut bytes) = (0, 0, 0, 0u64);
        for f in &fetched {
            match *f {
                Fetched::New(b) => (new, bytes) = (new + 1, bytes + b),
                Fetched::Resumed(from, to) => (resumed, bytes) = (resumed + 1, bytes + to - from),
                Fetched::Present(_) => present += 1,
            }
        }
        info!(
            "{new} downloaded, {resumed} resumed, {present} already there ({:.1} MB received) → {}",
            bytes as f64 / 1e6,
            dir.display()
        );
    }
    Ok(())
}
