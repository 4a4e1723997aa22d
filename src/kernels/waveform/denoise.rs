//! Denoising of a received waveform: keep only the signal above the noise, mean removed.
//!
//! [`denoise_leading_noise`] is the reference's denoiser for collocation (noise from the first
//! 12 m of the record). [`denoise`] turns a real waveform into a "noise-free" one with known noise
//! statistics (e.g. to check the noise twin). It follows
//! gediMetric's feature detection (docs/simulator-reference.md §2.4), detecting on a smoothed copy: a
//! feature starts where the smoothed waveform reaches μ + k·σ and is extended both ways while it
//! stays above μ; inside features the output is the **unsmoothed** max(w − μ, 0), as gediMetric
//! writes it, elsewhere 0. The output is not smoothed because L2A smooths again: a smoothed
//! output is smoothed twice, which fills the shallow dips that separate weak modes (docs/l2a.md,
//! "Why a5 and a6 fall short").

use crate::waveform::l2a::{GaussianKernel, Noise};

/// Denoising parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DenoiseSettings {
    /// Feature threshold in noise σ above the mean.
    pub threshold_sigmas: f64,
    /// Nominal smoothing width of the copy features are detected on (samples, as the L2A widths;
    /// ≤ 0.4 = no smoothing).
    pub smoothing_width: f64,
}

impl Default for DenoiseSettings {
    /// 3σ (the L2A front threshold) and the L2A zcross width 3.5.
    fn default() -> Self {
        Self { threshold_sigmas: 3.0, smoothing_width: 3.5 }
    }
}

/// The denoised waveform (counts above the noise mean), same length as `wave`; all zeros when no
/// sample reaches the threshold, and empty for an empty input.
pub fn denoise(wave: &[f32], noise: Noise, settings: DenoiseSettings) -> Vec<f64> {
    let mut smoothed = Vec::new();
    GaussianKernel::for_width(settings.smoothing_width).smooth_into(wave, &mut smoothed);
    let threshold = noise.mean + settings.threshold_sigmas * noise.stddev;
    let mut out = vec![0.0; wave.len()];
    let above_mean = |v: f64| v > noise.mean;
    let mut i = 0;
    while i < smoothed.len() {
        if smoothed[i] >= threshold {
            let mut start = i;
            while start > 0 && above_mean(smoothed[start - 1]) {
                start -= 1;
            }
            let mut end = i;
            while end + 1 < smoothed.len() && above_mean(smoothed[end + 1]) {
                end += 1;
            }
            for k in start..=end {
                out[k] = (f64::from(wave[k]) - noise.mean).max(0.0);
            }
            i = end + 1;
        } else {
            i += 1;
        }
    }
    out
}

/// Settings of the reference's noise-tracking denoiser (gediMetric/collocateWaves `denoise`,
/// docs/simulator-reference.md §2.4, §3): noise statistics from the leading samples, features from
/// μ + k·σ, extended while above μ.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LeadingNoiseDenoise {
    /// Length of the noise window at the top of the record (m); its first two samples are skipped.
    pub stats_len_m: f64,
    /// Feature threshold in noise σ above the mean.
    pub threshold_sigmas: f64,
    /// Features shorter than this many samples are dropped.
    pub min_width: usize,
}

impl LeadingNoiseDenoise {
    /// collocateWaves' settings for real waveforms: noise over the first 12 m, μ + 4σ, features of
    /// at least 6 samples, noise tracking on.
    pub const COLLOCATE: LeadingNoiseDenoise =
        LeadingNoiseDenoise { stats_len_m: 12.0, threshold_sigmas: 4.0, min_width: 6 };
}

/// Why a waveform cannot be denoised from its leading noise.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum DenoiseError {
    /// The record is shorter than the noise window (or the sample spacing is not positive).
    #[error("record shorter than the noise window")]
    TooShort,
    /// A sample is NaN or infinite.
    #[error("non-finite sample")]
    NonFinite,
}

/// Denoise `wave` (samples `spacing_m` apart, top first) the way the reference does for
/// collocation: μ and σ (population) of samples 2 … trunc(L/spacing) − 1, threshold τ = μ + kσ;
/// a feature starts at a sample ≥ τ and ends before the first sample below τ; features of at least
/// `min_width` samples are extended both ways while the signal stays above μ (noise tracking), and
/// their samples become max(w − μ, 0); everything else is 0. Unlike the reference, a feature that
/// reaches the last sample is kept (§5 Q13).
pub fn denoise_leading_noise(wave: &[f32], spacing_m: f64, s: LeadingNoiseDenoise) -> Result<Vec<f64>, DenoiseError> {
    if wave.iter().any(|v| !v.is_finite()) {
        return Err(DenoiseError::NonFinite);
    }
    if !(spacing_m > 0.0) || !spacing_m.is_finite() {
        return Err(DenoiseError::TooShort);
    }
    let end = (s.stats_len_m / spacing_m) as usize;
    if end <= 3 || end > wave.len() {
        return Err(DenoiseError::TooShort);
    }
    let window = &wave[2..end];
    let n = window.len() as f64;
    let mean = window.iter().map(|&v| v as f64).sum::<f64>() / n;
    let var = window.iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / n;
    let tau = mean + s.threshold_sigmas * var.sqrt();
    let w = |i: usize| wave[i] as f64;
    let mut out = vec![0.0; wave.len()];
    let mut i = 0;
    while i < wave.len() {
        if w(i) < tau {
            i += 1;
            continue;
        }
        let mut end = i;
        while end + 1 < wave.len() && w(end + 1) >= tau {
            end += 1;
        }
        if end + 1 - i >= s.min_width.max(1) {
            let mut start = i;
            while start > 0 && w(start - 1) > mean {
                start -= 1;
            }
            while end + 1 < wave.len() && w(end + 1) > mean {
                end += 1;
            }
            for (k, o) in out.iter_mut().enumerate().take(end + 1).skip(start) {
                *o = (w(k) - mean).max(0.0);
            }
        }
        i = end + 1;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn leading_noise_denoise_keeps_wide_features_only() {
        // Noise ±1 around 100 for 200 samples, a 10-sample bump and a 2-sample spike.
        let mut wave: Vec<f32> = (0..300).map(|i| 100.0 + if i % 2 == 0 { 1.0 } else { -1.0 }).collect();
        for (k, v) in wave[150..160].iter_mut().enumerate() {
            *v = 130.0 + k as f32;
        }
        wave[151] = 140.0;
        wave[160] = 100.5; // tail above μ: kept by noise tracking
        wave[250] = 150.0;
        wave[251] = 150.0;
        let d = denoise_leading_noise(&wave, 0.15, LeadingNoiseDenoise::COLLOCATE).unwrap();
        assert_eq!(d.len(), 300);
        assert!((d[151] - 40.0).abs() < 1e-9);
        assert!((d[160] - 0.5).abs() < 1e-9);
        assert_eq!(d[161], 0.0);
        assert_eq!(d[250], 0.0, "a 2-sample spike is below the minimum width");
        assert!(d[..150].iter().all(|&v| v == 0.0));
        // A feature running into the last sample is kept.
        let mut tail = wave.clone();
        tail[290..].iter_mut().for_each(|v| *v = 200.0);
        assert!(denoise_leading_noise(&tail, 0.15, LeadingNoiseDenoise::COLLOCATE).unwrap()[299] > 90.0);
        assert_eq!(
            denoise_leading_noise(&wave[..50], 0.15, LeadingNoiseDenoise::COLLOCATE),
            Err(DenoiseError::TooShort)
        );
        let mut bad = wave.clone();
        bad[3] = f32::NAN;
        assert_eq!(denoise_leading_noise(&bad, 0.15, LeadingNoiseDenoise::COLLOCATE), Err(DenoiseError::NonFinite));
    }

    #[test]
    fn keeps_the_feature_and_zeroes_the_noise() {
        // Baseline 1 count below the noise mean, as where noise pulls the smoothed record below μ.
        let mut wave = vec![99.0f32; 200];
        for (i, w) in wave.iter_mut().enumerate() {
            *w += 50.0 * (-0.5 * ((i as f32 - 100.0) / 4.0).powi(2)).exp();
        }
        wave[10] = 103.0; // a lone noise spike below 3σ after smoothing
        let d = denoise(&wave, Noise { mean: 100.0, stddev: 2.0 }, DenoiseSettings::default());
        assert_eq!(d.len(), 200);
        assert_eq!(d[10], 0.0);
        assert!(d[100] > 30.0);
        // Inside the feature the waveform itself is kept, not its smoothed copy.
        assert_eq!(d[100], f64::from(wave[100]) - 100.0);
        assert!(d.iter().all(|&v| v >= 0.0));
        assert!(denoise(&[], Noise { mean: 0.0, stddev: 1.0 }, DenoiseSettings::default()).is_empty());
    }
}
