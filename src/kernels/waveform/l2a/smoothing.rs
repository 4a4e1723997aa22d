//! Gaussian smoothing of a waveform as L2A does it before locating the signal and its modes.
//!
//! NASA stores only a nominal "width" (6.5 or 3.5 samples); the exact kernel is not public.
//! Two constants, fitted on the shared V1 granule (docs/l2a.md "Smoothing"), make a discrete
//! Gaussian reproduce NASA's positions to the quarter sample in 86–97 % of shots.

/// σ of the effective Gaussian = nominal width − this offset (samples). Fitted: σ 6.1 for width
/// 6.5 and σ 3.1 for width 3.5 maximise exact ¼-sample agreement of toploc/botloc and zcross.
pub const SIGMA_OFFSET: f64 = 0.4;

/// The kernel keeps the taps whose weight is at least this fraction of the centre weight. Fitted:
/// gives half-widths of 14 (width 6.5) and 7 (width 3.5) samples, the only ones that fit both.
pub const TRUNCATION_RATIO: f64 = 0.05;

/// A normalised, symmetric, truncated discrete Gaussian kernel.
#[derive(Debug, Clone, PartialEq)]
pub struct GaussianKernel {
    width: f64,
    taps: Vec<f64>,
}

impl GaussianKernel {
    /// The effective kernel for a nominal L2A smoothing `width` (samples); a width at or below
    /// [`SIGMA_OFFSET`] (or not finite) gives the identity kernel.
    pub fn for_width(width: f64) -> Self {
        let sigma = width - SIGMA_OFFSET;
        if !sigma.is_finite() || sigma <= 0.0 {
            return Self { width, taps: vec![1.0] };
        }
        let reach = sigma * (2.0 * (1.0 / TRUNCATION_RATIO).ln()).sqrt();
        let half = reach.floor() as usize;
        let mut taps: Vec<f64> = (0..=2 * half)
            .map(|j| {
                let x = j as f64 - half as f64;
                (-0.5 * (x / sigma).powi(2)).exp()
            })
            .collect();
        let sum: f64 = taps.iter().sum();
        taps.iter_mut().for_each(|t| *t /= sum);
        Self { width, taps }
    }

    /// The nominal width this kernel was built for.
    pub fn width(&self) -> f64 {
        self.width
    }

    /// Number of taps on each side of the centre.
    pub fn half_width(&self) -> usize {
        self.taps.len() / 2
    }

    /// Smooth `wave` into `out` (resized to the same length), padding with the edge values.
    pub fn smooth_into(&self, wave: &[f32], out: &mut Vec<f64>) {
        let n = wave.len();
        out.clear();
        out.resize(n, 0.0);
        let h = self.half_width();
        // Interior: every tap falls inside the waveform. The kernel is symmetric, so samples at
        // ±j share tap j (one multiply for two samples). Tap by tap over all interior samples:
        // each sample still sums centre, tap 1, tap 2 … in that order, and the loop over samples
        // vectorises.
        if n > 2 * h {
            let centre = self.taps[h];
            let interior = h..n - h;
            for i in interior.clone() {
                out[i] = f64::from(wave[i]) * centre;
            }
            for (j, &t) in self.taps[h + 1..].iter().enumerate() {
                let d = j + 1;
                let before = &wave[interior.start - d..interior.end - d];
                let after = &wave[interior.start + d..interior.end + d];
                for ((o, &b), &a) in out[interior.clone()].iter_mut().zip(before).zip(after) {
                    *o += (f64::from(b) + f64::from(a)) * t;
                }
            }
        }
        // Edges: indices clamped to the first/last sample (nearest-edge padding).
        let last = n as isize - 1;
        let edge = |i: usize| -> f64 {
            self.taps
                .iter()
                .enumerate()
                .map(|(j, &t)| {
                    let k = (i as isize + j as isize - h as isize).clamp(0, last) as usize;
                    f64::from(wave[k]) * t
                })
                .sum()
        };
        for i in (0..h.min(n)).chain(n.saturating_sub(h).max(h.min(n))..n) {
            out[i] = edge(i);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kernel_half_widths_match_the_fitted_values() {
        assert_eq!(GaussianKernel::for_width(6.5).half_width(), 14);
        assert_eq!(GaussianKernel::for_width(3.5).half_width(), 7);
        assert_eq!(GaussianKernel::for_width(0.2).half_width(), 0);
    }

    #[test]
    fn smoothing_preserves_a_constant_and_the_area_of_a_spike() {
        let k = GaussianKernel::for_width(3.5);
        let mut out = Vec::new();
        k.smooth_into(&[7.0; 40], &mut out);
        assert!(out.iter().all(|v| (v - 7.0).abs() < 1e-9));
        let mut spike = vec![0.0f32; 41];
        spike[20] = 1.0;
        k.smooth_into(&spike, &mut out);
        assert!((out.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        assert!((out[19] - out[21]).abs() < 1e-15);
        // Interior samples equal the direct weighted sum of the taps.
        let wave: Vec<f32> = (0..60).map(|i| ((i * 37) % 11) as f32).collect();
        k.smooth_into(&wave, &mut out);
        let h = k.half_width();
        for i in h..60 - h {
            let direct: f64 = (0..=2 * h).map(|j| f64::from(wave[i + j - h]) * k.taps[j]).sum();
            assert!((out[i] - direct).abs() < 1e-12, "sample {i}");
        }
        // Short waveforms: every sample is an edge sample (lengths around 2·half + 1 included).
        k.smooth_into(&[1.0, 2.0, 3.0], &mut out);
        assert_eq!(out.len(), 3);
        assert!(out[0] < out[1] && out[1] < out[2]);
        for n in [0, 1, 2 * h, 2 * h + 1, 2 * h + 2] {
            k.smooth_into(&vec![5.0; n], &mut out);
            assert_eq!(out.len(), n);
            assert!(out.iter().all(|v| (v - 5.0).abs() < 1e-9), "length {n}");
        }
    }
}
