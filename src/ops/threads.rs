//! `--threads N`: a cap on this process's compute threads — rayon's global pool (simulation,
//! ingest and its granule readers, collocation, diagnosis) and the SQL engine's (tokio workers,
//! DataFusion's target partitions). Not capped: the few threads that wait on remote reads
//! (`io::source`) and a cluster executor's (`gedisim cluster executor --concurrency`). Set once,
//! before any work starts.

use crate::error::{Error, Result};

/// Cap the worker threads at `n`.
pub fn set(n: usize) -> Result<()> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .build_global()
        .map_err(|e| Error::Usage(format!("--threads {n}: {e}")))?;
    crate::sql::set_threads(n);
    Ok(())
}
