//! The real waveform as the collocation compares it: denoised as collocateWaves does
//! (docs/simulator-reference.md §3: noise from the first 12 m, μ + 4σ, features of ≥ 6 samples extended
//! while above μ), put on orthometric heights with the geoid offset, resampled onto the absolute
//! vertical grid of the simulation and cut to its signal extent.

use crate::waveform::denoise::{denoise_leading_noise, DenoiseError, LeadingNoiseDenoise};

/// Fraction of a waveform's total below which its leading and trailing samples are outside its
/// signal extent (collocateWaves `waveCorrel`: 10⁻⁴).
pub const EXTENT_FRACTION: f64 = 1e-4;

/// A waveform on the absolute vertical grid, cut to its signal extent: `values[r]` is the energy
/// of bin `first_bin + r` (heights [(first_bin + r)·dz, (first_bin + r + 1)·dz)), ascending.
#[derive(Debug, Clone, PartialEq)]
pub struct GridProfile {
    /// Absolute bin index of `values[0]`.
    pub first_bin: i64,
    /// Values, bottom to top, normalised to a unit sum.
    pub values: Vec<f32>,
    /// Σ values.
    pub sum: f64,
    /// Σ values².
    pub sum_sq: f64,
}

impl GridProfile {
    /// The profile of `values` (bin `first_bin` first), cut to the bins above
    /// [`EXTENT_FRACTION`] of the total and scaled to a unit sum; `None` without positive energy.
    pub fn from_bins(first_bin: i64, values: &[f64]) -> Option<GridProfile> {
        let total: f64 = values.iter().filter(|v| **v > 0.0).sum();
        if !(total > 0.0) || !total.is_finite() {
            return None;
        }
        let thr = EXTENT_FRACTION * total;
        let start = values.iter().position(|&v| v > thr)?;
        let end = values.iter().rposition(|&v| v > thr)?;
        let kept: Vec<f32> = values[start..=end].iter().map(|&v| (v.max(0.0) / total) as f32).collect();
        let sum = kept.iter().map(|&v| v as f64).sum();
        let sum_sq = kept.iter().map(|&v| (v as f64) * (v as f64)).sum();
        Some(GridProfile { first_bin: first_bin + start as i64, values: kept, sum, sum_sq })
    }

    /// Absolute bin of the last value.
    pub fn last_bin(&self) -> i64 {
        self.first_bin + self.values.len() as i64 - 1
    }
}

/// Why a real waveform cannot be used.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum ProfileError {
    /// Fewer than two samples, or elevations that are not finite and decreasing.
    #[error("bad waveform geometry")]
    BadGeometry,
    /// The record is shorter than the 12 m noise window.
    #[error("record shorter than the noise window")]
    TooShort,
    /// A sample is NaN or infinite.
    #[error("non-finite sample")]
    NonFinite,
    /// Nothing rises above the noise threshold.
    #[error("no signal above the noise")]
    NoSignal,
}

/// A received waveform (counts, top to bottom) whose first sample is at orthometric height
/// `z_top` and last at `z_bottom` (m), denoised and resampled onto bins of `dz` (linear
/// interpolation at the bin centres).
pub fn real_profile(samples: &[f32], z_top: f64, z_bottom: f64, dz: f64) -> Result<GridProfile, ProfileError> {
    let n = samples.len();
    if n < 2 || !(z_top > z_bottom) || !z_top.is_finite() || !z_bottom.is_finite() || !(dz > 0.0) {
        return Err(ProfileError::BadGeometry);
    }
    let spacing = (z_top - z_bottom) / (n - 1) as f64;
    let denoised = denoise_leading_noise(samples, spacing, LeadingNoiseDenoise::COLLOCATE).map_err(|e| match e {
        DenoiseError::TooShort => ProfileError::TooShort,
        DenoiseError::NonFinite => ProfileError::NonFinite,
    })?;
    let first = denoised.iter().position(|&v| v > 0.0).ok_or(ProfileError::NoSignal)?;
    let last = denoised.iter().rposition(|&v| v > 0.0).ok_or(ProfileError::NoSignal)?;
    // Sample k sits at z_top − k·spacing; the signal spans samples first−1 … last+1 (zeros at
    // both ends make the interpolation fall to 0 there).
    let (k0, k1) = (first.saturating_sub(1), (last + 1).min(n - 1));
    let (z_hi, z_lo) = (z_top - k0 as f64 * spacing, z_top - k1 as f64 * spacing);
    // Bins whose centre (m + ½)·dz lies within [z_lo, z_hi].
    let m_lo = (z_lo / dz - 0.5).ceil() as i64;
    let m_hi = (z_hi / dz - 0.5).floor() as i64;
    if m_hi < m_lo {
        return Err(ProfileError::NoSignal);
    }
    let values: Vec<f64> = (m_lo..=m_hi)
        .map(|m| {
            let u = (z_top - (m as f64 + 0.5) * dz) / spacing;
            let i = (u.floor() as usize).min(n - 1);
            let f = u - i as f64;
            let next = denoised[(i + 1).min(n - 1)];
            denoised[i] * (1.0 - f) + next * f
        })
        .collect();
    GridProfile::from_bins(m_lo, &values).ok_or(ProfileError::NoSignal)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_noisy_pulse_lands_at_its_height() {
        // 800 samples of 0.15 m from 200 m down; noise ±1 on 50; a Gaussian return at 150 m.
        let spacing = 0.149_896_229;
        let z = |k: usize| 200.0 - k as f64 * spacing;
        let wave: Vec<f32> = (0..800)
            .map(|k| {
                let noise = if k % 2 == 0 { 1.0 } else { -1.0 };
                (50.0 + noise + 80.0 * (-0.5 * ((z(k) - 150.0) / 0.8f64).powi(2)).exp()) as f32
            })
            .collect();
        let p = real_profile(&wave, z(0), z(799), 0.15).unwrap();
        let peak = p.values.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)).unwrap().0 as i64 + p.first_bin;
        assert!(((peak as f64 + 0.5) * 0.15 - 150.0).abs() <= 0.15, "peak bin {peak}");
        assert!((p.sum - 1.0).abs() < 1e-6);
        assert!(p.values.len() < 60, "cut to the signal extent: {}", p.values.len());
        let flat = vec![50f32; 800];
        assert_eq!(real_profile(&flat, z(0), z(799), 0.15), Err(ProfileError::NoSignal));
        assert_eq!(real_profile(&wave, z(799), z(0), 0.15), Err(ProfileError::BadGeometry));
    }
}
