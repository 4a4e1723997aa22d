//! `gedisim l2a`: GEDI L2A (algorithms a1–a6) re-run on every waveform of an L1B granule, one row
//! per shot × algorithm written to a Parquet file (docs/l2a.md).

use std::path::Path;

use crate::dataset::l2a::{l2a_batch, l2a_schema};
use crate::dataset::{writer_properties, AtomicParquet};
use crate::error::{Error, Result};
use crate::kernels::waveform::l2a::AlgorithmSettings;
use crate::ops::ingest_gedi::{ingest_gedi, GediOptions};

/// What `gedisim l2a` wrote.
#[derive(Debug, Clone)]
pub struct L2aReport {
    pub shots: usize,
    pub rows: usize,
    /// What reading the L1B found wrong (one line each, naming file, beam and count).
    pub warnings: Vec<String>,
}

/// Run the GEDI `algorithms` (1..6) on every waveform of `l1b` into `out` (atomically).
pub fn l2a(l1b: &Path, algorithms: &[u8], out: &Path) -> Result<L2aReport> {
    if let Some(n) = algorithms.iter().enumerate().find_map(|(i, n)| algorithms[..i].contains(n).then_some(n)) {
        return Err(Error::Usage(format!("--algorithms: {n} given twice (each algorithm's rows once)")));
    }
    let settings = algorithms
        .iter()
        .map(|&n| {
            AlgorithmSettings::gedi(n)
                .ok_or_else(|| Error::Usage(format!("--algorithms: {n} is not a GEDI algorithm (1..6)")))
        })
        .collect::<Result<Vec<_>>>()?;
    let mut writer = AtomicParquet::create(out, l2a_schema(), writer_properties(&Default::default(), 1 << 16))?;
    let mut rows = 0;
    let report = ingest_gedi(std::slice::from_ref(&l1b.to_path_buf()), &[], &GediOptions::default(), |shots| {
        let batch = l2a_batch(&shots, &settings, l1b)?;
        rows += batch.num_rows();
        writer.write(&batch)
    })?;
    writer.finish()?;
    Ok(L2aReport { shots: report.rows(), rows, warnings: report.warnings() })
}
