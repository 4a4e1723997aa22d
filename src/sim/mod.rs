//! Pure simulation kernels: ALS points in, simulated GEDI waveforms out. No I/O, no Arrow.

pub mod points;

pub use points::AlsPoints;
