//! Pearson correlation of the real waveform with every offset's simulated waveform, at every
//! vertical lag of a window: the vertical offset is solved by cross-correlation, not searched by
//! re-simulation.
//!
//! Both waveforms sit on the same absolute grid of bins of `dz` and are zero outside their signal
//! extents. At lag λ (bins) the real bin m + λ is paired with the simulated bin m, i.e. the real
//! waveform lies λ·dz higher than the ALS surface it matches: λ·dz is the vertical offset. As in
//! collocateWaves (docs/simulator-reference.md §3) the correlation window is the union of the two signal
//! extents and the means are taken over that window, so for N window bins
//! r = (Σab − ΣaΣb/N) / √((Σa² − (Σa)²/N)(Σb² − (Σb)²/N)); only Σab and N depend on the lag.

use super::profile::{GridProfile, EXTENT_FRACTION};
use super::raster::OffsetWaves;

/// Consecutive vertical lags `first, first + 1, …, first + len − 1` (bins).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LagWindow {
    /// First lag (bins).
    pub first: i64,
    /// Number of lags.
    pub len: usize,
}

impl LagWindow {
    /// The lags `centre − half … centre + half`.
    pub fn around(centre: i64, half: usize) -> LagWindow {
        LagWindow { first: centre - half as i64, len: 2 * half + 1 }
    }

    /// Lag of index `i`.
    pub fn lag(&self, i: usize) -> i64 {
        self.first + i as i64
    }
}

/// The simulated waveforms of one shot cut to their signal extents, with their sums.
#[derive(Debug, Clone)]
pub struct SimulatedProfiles {
    waves: OffsetWaves,
    /// Per offset: first and last absolute bin of the extent (`None` for an empty waveform).
    extent: Vec<Option<(i64, i64)>>,
    sum: Vec<f64>,
    sum_sq: Vec<f64>,
}

impl SimulatedProfiles {
    /// Cuts every column of `waves` to its bins above [`EXTENT_FRACTION`] of its total.
    pub fn new(mut waves: OffsetWaves) -> SimulatedProfiles {
        let (rows, n) = (waves.rows(), waves.n_offsets);
        let mut total = vec![0f64; n];
        for r in 0..rows {
            for (t, &v) in total.iter_mut().zip(&waves.values[r * n..(r + 1) * n]) {
                *t += v as f64;
            }
        }
        let mut extent = vec![None; n];
        for (c, e) in extent.iter_mut().enumerate() {
            let thr = EXTENT_FRACTION * total[c];
            if !(total[c] > 0.0) {
                continue;
            }
            let first = (0..rows).find(|&r| waves.values[r * n + c] as f64 > thr);
            let last = (0..rows).rev().find(|&r| waves.values[r * n + c] as f64 > thr);
            if let (Some(f), Some(l)) = (first, last) {
                *e = Some((f, l));
            }
        }
        let (mut sum, mut sum_sq) = (vec![0f64; n], vec![0f64; n]);
        for r in 0..rows {
            let row = &mut waves.values[r * n..(r + 1) * n];
            for c in 0..n {
                match extent[c] {
                    Some((f, l)) if r >= f && r <= l => {
                        let v = row[c] as f64;
                        sum[c] += v;
                        sum_sq[c] += v * v;
                    }
                    _ => row[c] = 0.0,
                }
            }
        }
        let first_bin = waves.first_bin;
        let extent = extent.into_iter().map(|e| e.map(|(f, l)| (first_bin + f as i64, first_bin + l as i64))).collect();
        SimulatedProfiles { waves, extent, sum, sum_sq }
    }

    /// Number of offsets.
    pub fn n_offsets(&self) -> usize {
        self.waves.n_offsets
    }

    /// Signal extent (absolute bins) of offset `c`.
    pub fn extent(&self, c: usize) -> Option<(i64, i64)> {
        self.extent[c]
    }

    /// Range of lags at which the real profile and offset `c`'s waveform overlap.
    pub fn overlap_lags(&self, real: &GridProfile, c: usize) -> Option<(i64, i64)> {
        let (s0, s1) = self.extent[c]?;
        Some((real.first_bin - s1, real.last_bin() - s0))
    }

    /// Pearson r of `real` with every offset at every lag of `window`, laid out `[offset][lag]`.
    pub fn correlate(&self, real: &GridProfile, window: LagWindow) -> Vec<f32> {
        let n = self.waves.n_offsets;
        let rows = self.waves.rows() as i64;
        let mut cross = vec![0f32; window.len * n];
        for li in 0..window.len {
            let lag = window.lag(li);
            let acc = &mut cross[li * n..(li + 1) * n];
            for (k, &a) in real.values.iter().enumerate() {
                if a == 0.0 {
                    continue;
                }
                // Real bin m + λ pairs with simulated bin m.
                let row = real.first_bin + k as i64 - lag - self.waves.first_bin;
                if row < 0 || row >= rows {
                    continue;
                }
                let src = &self.waves.values[row as usize * n..(row as usize + 1) * n];
                for (c, &s) in acc.iter_mut().zip(src) {
                    *c += a * s;
                }
            }
        }
        let mut r = vec![0f32; n * window.len];
        for c in 0..n {
            for li in 0..window.len {
                r[c * window.len + li] = self.pearson(real, c, window.lag(li), cross[li * n + c] as f64) as f32;
            }
        }
        r
    }

    /// Pearson r of `real` with offset `c` at one lag.
    pub fn correlate_one(&self, real: &GridProfile, c: usize, lag: i64) -> f64 {
        let n = self.waves.n_offsets;
        let rows = self.waves.rows() as i64;
        let mut cross = 0f64;
        for (k, &a) in real.values.iter().enumerate() {
            let row = real.first_bin + k as i64 - lag - self.waves.first_bin;
            if row >= 0 && row < rows {
                cross += a as f64 * self.waves.values[row as usize * n + c] as f64;
            }
        }
        self.pearson(real, c, lag, cross)
    }

    /// r from the cross sum at `lag` (0 for an empty simulated waveform or a constant window).
    fn pearson(&self, real: &GridProfile, c: usize, lag: i64, cross: f64) -> f64 {
        let Some((s0, s1)) = self.extent[c] else { return 0.0 };
        let (a0, a1) = (real.first_bin - lag, real.last_bin() - lag);
        let len = (a1.max(s1) - a0.min(s0) + 1) as f64;
        let (sa, sb) = (real.sum, self.sum[c]);
        let va = real.sum_sq - sa * sa / len;
        let vb = self.sum_sq[c] - sb * sb / len;
        if !(va > 0.0 && vb > 0.0) {
            return 0.0;
        }
        (cross - sa * sb / len) / (va * vb).sqrt()
    }
}

/// Sub-bin position and value of the maximum of a sampled curve around its sample `i`, by a
/// parabola through `i − 1, i, i + 1` (offset clamped to ±½; none at the ends or where the three
/// points are not concave).
pub fn parabolic_peak(values: &[f64], i: usize) -> (f64, f64) {
    if i == 0 || i + 1 >= values.len() {
        return (i as f64, values[i]);
    }
    let (a, b, c) = (values[i - 1], values[i], values[i + 1]);
    let denom = a - 2.0 * b + c;
    if !(denom < 0.0) {
        return (i as f64, b);
    }
    let d = (0.5 * (a - c) / denom).clamp(-0.5, 0.5);
    (i as f64 + d, b - 0.25 * (a - c) * d)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Plain Pearson r of two series on a common window.
    fn pearson(a: &[f64], b: &[f64]) -> f64 {
        let n = a.len() as f64;
        let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
        let cov: f64 = a.iter().zip(b).map(|(x, y)| (x - ma) * (y - mb)).sum();
        let va: f64 = a.iter().map(|x| (x - ma).powi(2)).sum();
        let vb: f64 = b.iter().map(|y| (y - mb).powi(2)).sum();
        cov / (va * vb).sqrt()
    }

    #[test]
    fn lagged_r_is_the_pearson_r_on_the_union_window() {
        // One offset; simulated bump at bins 100..110, real bump at bins 103..115.
        let sim: Vec<f32> =
            (0..40).map(|r| if (10..20).contains(&r) { 1.0 + (r as f32 - 14.0).abs() } else { 0.0 }).collect();
        let waves = OffsetWaves { first_bin: 90, dz: 0.15, n_offsets: 1, values: sim.clone() };
        let p = SimulatedProfiles::new(waves);
        let real_vals: Vec<f64> = (0..12).map(|k| 1.0 + ((k * 7) % 5) as f64).collect();
        let real = GridProfile::from_bins(103, &real_vals).unwrap();
        let window = LagWindow::around(2, 6);
        let r = p.correlate(&real, window);
        #[allow(clippy::needless_range_loop)] // `li` is also the lag index of `window`
        for li in 0..window.len {
            let lag = window.lag(li);
            // Union window in simulated bins.
            let (lo, hi) = ((103 - lag).min(100), (114 - lag).max(109));
            let a: Vec<f64> = (lo..=hi)
                .map(|m| {
                    let k = m + lag - 103;
                    if (0..12).contains(&k) {
                        real.values[k as usize] as f64
                    } else {
                        0.0
                    }
                })
                .collect();
            let b: Vec<f64> =
                (lo..=hi).map(|m| if (90..130).contains(&m) { sim[(m - 90) as usize] as f64 } else { 0.0 }).collect();
            let want = pearson(&a, &b);
            assert!((r[li] as f64 - want).abs() < 1e-5, "lag {lag}: {} vs {want}", r[li]);
            assert!((p.correlate_one(&real, 0, lag) - want).abs() < 1e-9);
        }
    }

    #[test]
    fn parabola_finds_the_vertex() {
        let v: Vec<f64> = (0..7).map(|i| 1.0 - (i as f64 - 3.3).powi(2)).collect();
        let (x, y) = parabolic_peak(&v, 3);
        assert!((x - 3.3).abs() < 1e-12 && (y - 1.0).abs() < 1e-12);
        assert_eq!(parabolic_peak(&v, 0), (0.0, v[0]));
    }
}
