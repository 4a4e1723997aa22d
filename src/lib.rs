//! gedisim: simulate NASA GEDI waveforms from airborne lidar (ALS), process real and simulated
//! waveforms the way GEDI L2A does, and measure the sim-to-real gap.
//!
//! Layout (see `docs/ARCHITECTURE.md`): pure kernels (`sim`, `process`, `collocate`) know nothing
//! of files or Arrow; adapters (`ingest`, `dataset`, `sql`) convert between files, Arrow and kernels.

pub mod als_table;
pub mod collocate;
pub mod collocation;
pub mod dataset;
pub mod demo;
pub mod diagnose;
pub mod diagnosis;
pub mod error;
pub mod gedi;
pub mod geo;
pub mod ingest;
pub mod process;
pub mod report;
pub mod run;
pub mod scenario;
pub mod scenario_io;
pub mod sim;
pub mod simulate;
pub mod sql;
pub mod study;
pub mod tables;

pub use error::{Error, Result};
