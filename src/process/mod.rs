//! Pure kernels on waveforms: relative heights, L2A algorithms, noise twin, denoising.

pub mod rh;
