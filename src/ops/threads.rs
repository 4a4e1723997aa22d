//! `--threads N`: a cap on this process's compute threads — rayon's global pool (simulation,
//! ingest and its granule readers, collocation, diagnosis) and the SQL engine's (tokio workers,
//! DataFusion's target partitions). Not capped: the few threads that wait on remote reads
//! (`io::source`) and a cluster executor's (`gedisim cluster executor --concurrency`). Set once,
//! before any work starts.

use crate::error::{Error, Result};

/// Worker threads per core that `--threads` may ask for: beyond a few per core threads only take
/// turns, and 10⁵ of them hang the process while it creates them.
pub const MAX_PER_CORE: usize = 4;

/// The most worker threads `--threads` gives: [`MAX_PER_CORE`] per core of this machine.
pub fn max_threads() -> usize {
    MAX_PER_CORE * std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// Cap the worker threads at `n`, itself capped at [`max_threads`] (with a warning).
pub fn set(n: usize) -> Result<()> {
    let max = max_threads();
    let n = if n > max {
        tracing::warn!("--threads {n}: more than {MAX_PER_CORE} per core of this machine; using {max}");
        max
    } else {
        n
    };
    rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .build_global()
        .map_err(|e| Error::Usage(format!("--threads {n}: {e}")))?;
    crate::sql::set_threads(n);
    Ok(())
}
