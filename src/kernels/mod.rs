//! Pure kernels: plain slices and structs in, plain structs out; no files, no Arrow, no Parquet.

pub mod collocate;
pub mod diagnose;
pub mod error;
pub mod gedi;
pub mod geo;
pub mod scenario;
pub mod sim;
pub mod study;
pub mod waveform;
