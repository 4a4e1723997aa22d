//! Denoising of a received waveform: keep only the signal above the noise, mean removed.
//!
//! Used to turn a real waveform into a "noise-free" one (e.g. to check the noise twin). Follows
//! gediMetric's feature detection (simulator-reference.md §2.4), detecting on a smoothed copy: a
//! feature starts where the smoothed waveform reaches μ + k·σ and is extended both ways while it
//! stays above μ; inside features the output is the **unsmoothed** max(w − μ, 0), as gediMetric
//! writes it, elsewhere 0. The output is not smoothed because L2A smooths again: a smoothed
//! output is smoothed twice, which fills the shallow dips that separate weak modes (docs/l2a.md,
//! "Why a5 and a6 fall short").

use crate::process::l2a::{GaussianKernel, Noise};

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
        Self {
            threshold_sigmas: 3.0,
            smoothing_width: 3.5,
        }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_the_feature_and_zeroes_the_noise() {
        // Baseline 1 count below the noise mean, as where noise pulls the smoothed record below μ.
        let mut wave = vec![99.0f32; 200];
        for (i, w) in wave.iter_mut().enumerate() {
            *w += 50.0 * (-0.5 * ((i as f32 - 100.0) / 4.0).powi(2)).exp();
        }
        wave[10] = 103.0; // a lone noise spike below 3σ after smoothing
        let d = denoise(
            &wave,
            Noise {
                mean: 100.0,
                stddev: 2.0,
            },
            DenoiseSettings::default(),
        );
        assert_eq!(d.len(), 200);
        assert_eq!(d[10], 0.0);
        assert!(d[100] > 30.0);
        // Inside the feature the waveform itself is kept, not its smoothed copy.
        assert_eq!(d[100], f64::from(wave[100]) - 100.0);
        assert!(d.iter().all(|&v| v >= 0.0));
        assert!(denoise(
            &[],
            Noise {
                mean: 0.0,
                stddev: 1.0
            },
            DenoiseSettings::default()
        )
        .is_empty());
    }
}
