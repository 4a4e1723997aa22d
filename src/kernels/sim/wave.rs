//! Waveform arrays of one footprint: binning of weighted returns, pulse convolution, outlier
//! cleaning and unit-integral normalisation (docs/simulator-reference.md §1.4, §1.7–§1.10).
//!
//! The arrays are generic over the accumulator type: the `gedirat` profile sums in f32 in the
//! reference's order (bit parity), the `default` profile sums in f64, so its results (rounded to
//! f32 at the end) do not depend on the order in which points arrive.

use std::ops::{AddAssign, Div, DivAssign, Mul, Sub};

use super::{Weighting, N_WEIGHTINGS};

/// Accumulator type of the waveform arrays (f32 or f64).
pub trait Sample:
    Copy + Default + PartialOrd + AddAssign + DivAssign + Mul<Output = Self> + Div<Output = Self> + Sub<Output = Self>
{
    /// Converts an f32 weight or pulse sample.
    fn from_f32(v: f32) -> Self;
    /// Rounds to the output type.
    fn to_f32(self) -> f32;
    /// Multiplies by a double constant the way C does for `float * double` stored in a float.
    fn scale(self, k: f64) -> Self;
}

impl Sample for f32 {
    fn from_f32(v: f32) -> Self {
        v
    }
    fn to_f32(self) -> f32 {
        self
    }
    fn scale(self, k: f64) -> Self {
        (self as f64 * k) as f32
    }
}

impl Sample for f64 {
    fn from_f32(v: f32) -> Self {
        v as f64
    }
    fn to_f32(self) -> f32 {
        self as f32
    }
    fn scale(self, k: f64) -> Self {
        self * k
    }
}

/// The arrays of a footprint: total, ground (class 2) and canopy (other classes) waves per
/// weighting, bin 0 at the top. [`Weighting::Share`]'s are empty unless it is simulated.
#[derive(Debug, Clone)]
pub struct WaveSet<T> {
    /// Total waveforms, indexed by [`Weighting`].
    pub total: [Vec<T>; N_WEIGHTINGS],
    /// Ground-return waveforms.
    pub ground: [Vec<T>; N_WEIGHTINGS],
    /// Canopy (non-ground) waveforms.
    pub canopy: [Vec<T>; N_WEIGHTINGS],
}

/// Weights of one contributing return, in f32 as the reference forms them.
#[derive(Debug, Clone, Copy)]
pub struct Contribution {
    /// Elevation (m).
    pub z: f64,
    /// Per-weighting weights, indexed by [`Weighting`].
    pub w: [f32; N_WEIGHTINGS],
    /// Ground (class 2) or canopy.
    pub ground: bool,
}

impl<T: Sample> WaveSet<T> {
    /// Zeroed arrays of `n` bins: nine, and three more for [`Weighting::Share`] if `share`.
    pub fn zeros(n: usize, share: bool) -> WaveSet<T> {
        let len = |k: usize| if k != Weighting::Share as usize || share { n } else { 0 };
        let z = || std::array::from_fn(|k| vec![T::default(); len(k)]);
        WaveSet { total: z(), ground: z(), canopy: z() }
    }

    /// Number of bins.
    pub fn len(&self) -> usize {
        self.total[0].len()
    }

    /// Whether the arrays hold no bin.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Adds `scale ×` the weights of `c` to bin `bin` (ignored outside the arrays).
    pub fn add(&mut self, bin: i64, c: &Contribution, scale: f32) {
        if bin < 0 || bin as usize >= self.len() {
            return;
        }
        let b = bin as usize;
        let part = if c.ground { &mut self.ground } else { &mut self.canopy };
        // Products in f32 as in the reference (`rScale*fracHit*y`), then added.
        for k in [Weighting::Int, Weighting::Count, Weighting::Frac] {
            let v = T::from_f32(c.w[k as usize] * scale);
            self.total[k as usize][b] += v;
            part[k as usize][b] += v;
        }
        let share = Weighting::Share as usize;
        if let Some(t) = self.total[share].get_mut(b) {
            let v = T::from_f32(c.w[share] * scale);
            *t += v;
            part[share][b] += v;
        }
    }

    /// Range of bins holding a non-zero value in any array (empty range if none).
    fn support(&self) -> std::ops::Range<usize> {
        let arrays = self.total.iter().chain(&self.ground).chain(&self.canopy);
        let (mut lo, mut hi) = (usize::MAX, 0);
        for a in arrays {
            if let Some(f) = a.iter().position(|v| *v != T::default()) {
                lo = lo.min(f);
                hi = hi.max(a.iter().rposition(|v| *v != T::default()).unwrap_or(f) + 1);
            }
        }
        if lo == usize::MAX {
            0..0
        } else {
            lo..hi
        }
    }

    /// Convolves every array with pulse taps (`offsets[j]` bins, weight `y[j]`):
    /// out[i] = Σⱼ in[i + offsets[j]]·y[j], over in-range taps, divided by their number when
    /// `divide_by_taps` (the reference's `applyPulseShape`, Q17).
    pub fn convolve(&mut self, offsets: &[i64], y: &[f32], divide_by_taps: bool) {
        let n = self.len() as i64;
        let support = self.support();
        if support.is_empty() {
            return;
        }
        // Outside [support − max offset, support − min offset] every tap reads zeros.
        let (omin, omax) = (*offsets.iter().min().unwrap_or(&0), *offsets.iter().max().unwrap_or(&0));
        let lo = (support.start as i64 - omax).max(0);
        let hi = (support.end as i64 - omin).min(n);
        let taps: Vec<(i64, T)> = offsets.iter().zip(y).map(|(&o, &y)| (o, T::from_f32(y))).collect();
        let arrays = self.total.iter_mut().chain(&mut self.ground).chain(&mut self.canopy);
        for a in arrays.filter(|a| !a.is_empty()) {
            let mut out = vec![T::default(); a.len()];
            for i in lo..hi {
                let (mut sum, mut count) = (T::default(), 0f32);
                for &(o, y) in &taps {
                    let b = i + o;
                    if b >= 0 && b < n {
                        sum += a[b as usize] * y;
                        count += 1.0;
                    }
                }
                if divide_by_taps && count > 0.0 {
                    sum /= T::from_f32(count);
                }
                out[i as usize] = sum;
            }
            *a = out;
        }
    }

    /// Removes outliers with the reference's `cleanOutliers` (§1.9), tested on the count
    /// waveforms: everything below a gap of more than 10 m in the ground return, and everything
    /// above 50 m of near-zero signal over the ground's top. Totals are always cleaned; ground and
    /// canopy arrays of the weightings in `split_cleaned` only (the reference omits frac, Q5).
    pub fn clean_outliers(&mut self, res: f32, split_cleaned: &[Weighting]) {
        let n = self.len();
        if n == 0 {
            return;
        }
        let count = Weighting::Count as usize;
        let (mut max_ground, mut max) = (T::default(), T::default());
        for i in 0..n {
            if self.ground[count][i] > max_ground {
                max_ground = self.ground[count][i];
            }
            if self.total[count][i] > max {
                max = self.total[count][i];
            }
        }
        let g_thresh = max_ground.scale(0.01);
        let thresh = max.scale(0.001);

        let mut g_start = 0;
        let mut past_ground = false;
        let mut gap = 0f32;
        for i in 0..n {
            if self.ground[count][i] >= g_thresh {
                if !past_ground {
                    g_start = i;
                }
                past_ground = true;
                gap = 0.0;
            } else if past_ground {
                gap += res;
            }
            if gap > 10.0 {
                self.zero(i..n, split_cleaned);
                break;
            }
        }

        gap = 0.0;
        for i in (0..=g_start).rev() {
            if self.total[count][i] >= thresh {
                gap = 0.0;
            }
            gap += res;
            if gap >= 50.0 {
                self.zero(0..i + 1, split_cleaned);
                break;
            }
        }
    }

    fn zero(&mut self, bins: std::ops::Range<usize>, split_cleaned: &[Weighting]) {
        for a in self.total.iter_mut().filter(|a| !a.is_empty()) {
            a[bins.clone()].fill(T::default());
        }
        for &k in split_cleaned.iter().filter(|&&k| !self.total[k as usize].is_empty()) {
            self.ground[k as usize][bins.clone()].fill(T::default());
            self.canopy[k as usize][bins.clone()].fill(T::default());
        }
    }

    /// Divides each weighting's three arrays by the integral Σ total·res of its total (left as
    /// is when that integral is not positive, as for arrays not simulated).
    pub fn normalise(&mut self, res: f32) {
        let r = T::from_f32(res);
        for k in 0..N_WEIGHTINGS {
            let mut tot = T::default();
            for &v in &self.total[k] {
                tot += v * r;
            }
            if tot > T::default() {
                for a in [&mut self.total[k], &mut self.ground[k], &mut self.canopy[k]] {
                    a.iter_mut().for_each(|v| *v /= tot);
                }
            }
        }
    }

    /// Σ (w − min w)·res of the total of `k`: the reference drops footprints where this is
    /// below 10⁻⁵ (gediIO `TOL`).
    pub fn signal_integral(&self, k: Weighting, res: f32) -> T {
        let a = &self.total[k as usize];
        let mut min = T::from_f32(10000.0);
        for &v in a {
            if v < min {
                min = v;
            }
        }
        let mut tot = T::default();
        for &v in a {
            tot += (v - min) * T::from_f32(res);
        }
        tot
    }
}
