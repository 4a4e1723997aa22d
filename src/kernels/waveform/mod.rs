//! Pure kernels on waveforms: relative heights, L2A algorithms, noise twin, denoising.

pub mod denoise;
pub mod forward;
pub mod l2a;
pub mod noise_twin;
pub mod rh;
