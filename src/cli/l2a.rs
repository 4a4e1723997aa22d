//! `gedisim l2a`.

use std::path::PathBuf;
use tracing::{info, warn};

use clap::Args;

use gedisim::Result;

#[derive(Args)]
pub struct L2aArgs {
    /// GEDI L1B file (V1 or V2).
    #[arg(long)]
    l1b: PathBuf,
    /// Output Parquet file: one row per shot × algorithm.
    #[arg(long)]
    out: PathBuf,
    /// Algorithms to run, e.g. 1,3.
    #[arg(long, value_delimiter = ',', default_value = "1,2,3,4,5,6")]
    algorithms: Vec<u8>,
}

pub fn l2a(a: L2aArgs) -> Result<()> {
    let r = gedisim::ops::l2a::l2a(&a.l1b, &a.algorithms, &a.out)?;
    for w in &r.warnings {
        warn!("{w}");
    }
    info!("{} shots × {} algorithms → {} rows in {}", r.shots, a.algorithms.len(), r.rows, a.out.display());
    Ok(())
}
