//! Operations, one per command: files in, files out. The only place that sequences steps
//! (read with `io`/`dataset`, compute with `kernels`, write with `dataset`).

pub mod bench;
#[cfg(feature = "cluster")]
pub mod cluster;
pub mod collocate;
pub mod demo;
pub mod diagnose;
pub mod export;
pub mod granules;
pub mod ingest_als;
pub mod ingest_gedi;
pub mod ingest_strata;
pub mod l2a;
pub mod progress;
pub mod report;
pub mod run;
pub mod scenario;
pub mod simulate;
pub mod sql;
pub mod threads;
