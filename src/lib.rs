//! gedisim: simulate NASA GEDI waveforms from airborne lidar (ALS), process real and simulated
//! waveforms the way GEDI L2A does, and measure the sim-to-real gap.
//!
//! Layout (docs/ARCHITECTURE.md), dependencies pointing one way (`tests/layout.rs` checks it):
//! - [`ops`]: one operation per command, files in and files out; the only place that sequences steps.
//! - [`kernels`]: pure computation (simulator, L2A, collocation, study, scenario, diagnosis).
//! - [`io`]: foreign formats (LAS/LAZ, GEDI HDF5, CSV) read and written.
//! - [`dataset`]: the store: table folders, schemas, atomic Parquet writes.
//! - [`sql`]: the DataFusion session and gedisim's SQL functions.
//!
//! The command line (`src/main.rs`, `src/cli/`) parses arguments and calls `ops`.

pub mod dataset;
pub mod error;
pub mod io;
/// The pure kernels, a package of their own (`src/kernels/`, `gedisim-kernels`).
pub use gedisim_kernels as kernels;
pub mod ops;
pub mod sql;

pub use error::{Error, Result};
