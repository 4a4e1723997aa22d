//! The separable-Gaussian raster: every horizontal offset's simulated waveform of one shot,
//! built in one pass over the shot's ALS points.
//!
//! The footprint weight of a return at (x, y) for a footprint centred at (cx, cy) is
//! G(d) = g(x − cx)·g(y − cy)/(σ√(2π)) with g(u) = exp(−u²/(2σ²)) (simulator-reference.md §1.3).
//! For the offsets cx = x₀ + i·step, cy = y₀ + j·step each return needs 2n values gx[i], gy[j]
//! (n offsets per axis) instead of n² distances and exponentials, and its weight for offset (i, j)
//! is the product, added to W[bin][i][j] where bin is the return's bin on the absolute vertical
//! grid. The weight cut-off of the simulator (G > `I_THRESH`, d < 17.03 m for σ = 5.5 m) is kept
//! exactly: for each i the range of j inside the cut-off circle is computed, then its two ends are
//! checked with the simulator's own f32 test. The pulse convolution is linear and the same for every
//! offset, so it is applied once to the whole raster. The result equals the brute-force simulation
//! of each offset (count weighting, no density normalisation, no cleaning) to f32 rounding:
//! `tests/collocate.rs` checks it against [`crate::sim::simulate`].

use crate::sim::footprint::{footprint_weight, I_THRESH};
use crate::sim::{absolute_bin, tap_offsets, SimConfig};

use super::OffsetGrid;

/// Simulated count waveforms of one shot at every horizontal offset of an [`OffsetGrid`], on the
/// absolute vertical grid (row r holds bin `first_bin + r`, i.e. heights
/// [(first_bin + r)·dz, (first_bin + r + 1)·dz); rows ascend in height).
#[derive(Debug, Clone, PartialEq)]
pub struct OffsetWaves {
    /// Absolute bin index of row 0.
    pub first_bin: i64,
    /// Bin size (m).
    pub dz: f64,
    /// Number of offsets (columns of a row): `grid.n()²`, offset (i, j) at column i·n + j.
    pub n_offsets: usize,
    /// Row-major values, `rows × n_offsets` (arbitrary scale: unnormalised weights).
    pub values: Vec<f32>,
}

impl OffsetWaves {
    /// Number of rows (bins).
    pub fn rows(&self) -> usize {
        if self.n_offsets == 0 { 0 } else { self.values.len() / self.n_offsets }
    }

    /// The waveform of offset column `c`, bottom to top (row order).
    pub fn column(&self, c: usize) -> Vec<f32> {
        self.values.iter().skip(c).step_by(self.n_offsets).copied().collect()
    }
}

/// Radius (m) beyond which the simulator's footprint weight is certainly below the cut-off
/// (slightly larger than the exact radius; the exact test is applied at the boundary).
fn cut_off_radius(fsigma: f32) -> f64 {
    let s = fsigma as f64;
    let peak_ratio = I_THRESH as f64 * s * (2.0 * std::f64::consts::PI).sqrt();
    if peak_ratio >= 1.0 {
        return 0.0;
    }
    s * (-2.0 * peak_ratio.ln()).sqrt() + 1e-3
}

/// Half-width (m) of the square around a shot holding every return that can contribute at some
/// offset of `grid`: the cut-off radius plus the largest shift.
pub fn support_half_width(grid: &OffsetGrid, model: &SimConfig) -> f64 {
    cut_off_radius(model.fsigma) + grid.max_offset()
}

/// The simulator's contribution test for a return at squared distance `d_sq`.
fn contributes(d_sq: f64, fsigma: f32) -> bool {
    footprint_weight(d_sq.sqrt(), fsigma) > I_THRESH
}

/// Builds the waveforms of every offset of `grid` around (x0, y0) from the returns `candidates`
/// (indices into `x`, `y`, `z`; returns beyond the support are ignored), with the footprint,
/// bin size and pulse of `model`. `None` when no return contributes at any offset.
pub fn offset_waves(
    x: &[f64],
    y: &[f64],
    z: &[f64],
    candidates: &[u32],
    (x0, y0): (f64, f64),
    grid: &OffsetGrid,
    model: &SimConfig,
) -> Option<OffsetWaves> {
    let n = grid.n();
    let n_off = n * n;
    let sigma = model.fsigma as f64;
    let dz = model.res;
    let r_cut = cut_off_radius(model.fsigma);
    let r_cut_sq = r_cut * r_cut;
    let reach = r_cut + grid.max_offset();
    let centres: Vec<(f64, f64)> = (0..n).map(|i| (x0 + grid.offset(i), y0 + grid.offset(i))).collect();

    // Returns that reach at least one offset, with their bins.
    let mut kept: Vec<(u32, i64)> = Vec::with_capacity(candidates.len());
    let (mut lo, mut hi) = (i64::MAX, i64::MIN);
    for &c in candidates {
        let p = c as usize;
        let (ex, ey) = ((x[p] - x0).abs() - grid.max_offset(), (y[p] - y0).abs() - grid.max_offset());
        let (ex, ey) = (ex.max(0.0), ey.max(0.0));
        if !(ex <= reach && ey <= reach && ex * ex + ey * ey <= r_cut_sq) || !z[p].is_finite() {
            continue;
        }
        let b = absolute_bin(z[p], dz);
        lo = lo.min(b);
        hi = hi.max(b);
        kept.push((c, b));
    }
    if kept.is_empty() {
        return None;
    }
    let raw_rows = (hi - lo + 1) as usize;
    let mut w = vec![0f32; raw_rows * n_off];
    let norm = 1.0 / (sigma * (2.0 * std::f64::consts::PI).sqrt());
    let two_var = 2.0 * sigma * sigma;
    let mut gx = vec![0f32; n];
    let mut gy = vec![0f32; n];
    let mut any = false;
    for &(c, b) in &kept {
        let p = c as usize;
        let (px, py) = (x[p], y[p]);
        for i in 0..n {
            let ex = px - centres[i].0;
            gx[i] = ((-ex * ex / two_var).exp() * norm) as f32;
            let ey = py - centres[i].1;
            gy[i] = (-ey * ey / two_var).exp() as f32;
        }
        let row = &mut w[(b - lo) as usize * n_off..(b - lo + 1) as usize * n_off];
        for i in 0..n {
            let ex = px - centres[i].0;
            let rem = r_cut_sq - ex * ex;
            if rem < 0.0 {
                continue;
            }
            // Offsets j with |py − cy_j| ≤ √rem, then the exact test at both ends.
            let s = rem.sqrt();
            let rel = |v: f64| v / grid.step + grid.half() as f64;
            let mut j0 = rel(py - y0 - s).ceil().max(0.0) as i64;
            let mut j1 = rel(py - y0 + s).floor().min((n - 1) as f64) as i64;
            let d_sq = |j: i64| {
                let ey = py - centres[j as usize].1;
                ex * ex + ey * ey
            };
            while j0 <= j1 && !contributes(d_sq(j0), model.fsigma) {
                j0 += 1;
            }
            while j1 >= j0 && !contributes(d_sq(j1), model.fsigma) {
                j1 -= 1;
            }
            if j0 > j1 {
                continue;
            }
            any = true;
            let g = gx[i];
            let dst = &mut row[i * n + j0 as usize..=i * n + j1 as usize];
            for (d, &gyj) in dst.iter_mut().zip(&gy[j0 as usize..=j1 as usize]) {
                *d += g * gyj;
            }
        }
    }
    if !any {
        return None;
    }

    // Pulse convolution on the absolute grid: the simulator's tap j moves a bin's energy
    // `offsets[j]` bins up (its bins count downwards: out[i] = Σⱼ in[i + offⱼ]·yⱼ).
    let offsets = tap_offsets(&model.pulse, model);
    let (omin, omax) = (*offsets.iter().min().unwrap_or(&0), *offsets.iter().max().unwrap_or(&0));
    // Row r of the output is absolute bin lo + omin + r.
    let rows = raw_rows + (omax - omin) as usize;
    let mut out = vec![0f32; rows * n_off];
    for (&o, &yj) in offsets.iter().zip(&model.pulse.y) {
        // Input row r (bin lo + r) lands on bin lo + r + o, i.e. output row r + o − omin.
        let shift = (o - omin) as usize;
        for r in 0..raw_rows {
            let src = &w[r * n_off..(r + 1) * n_off];
            let dst = &mut out[(r + shift) * n_off..(r + shift + 1) * n_off];
            for (d, &s) in dst.iter_mut().zip(src) {
                *d += s * yj;
            }
        }
    }
    Some(OffsetWaves { first_bin: lo + omin, dz, n_offsets: n_off, values: out })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::{Profile, SimConfig};

    #[test]
    fn cut_off_radius_brackets_the_simulator_test() {
        let r = cut_off_radius(5.5);
        assert!(contributes((r - 2e-3) * (r - 2e-3), 5.5));
        assert!(!contributes(r * r, 5.5));
    }

    #[test]
    fn one_return_gives_the_pulse_at_its_bin() {
        let mut model = SimConfig::new(Profile::Default);
        model.normalise_density = false;
        let grid = OffsetGrid::new(1.0, 1.0).unwrap();
        let w = offset_waves(&[0.0], &[0.0], &[10.0], &[0], (0.0, 0.0), &grid, &model).unwrap();
        assert_eq!(w.n_offsets, 9);
        let centre = w.column(4);
        let peak = centre.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)).unwrap().0;
        assert_eq!(w.first_bin + peak as i64, absolute_bin(10.0, 0.15));
        // The corner offsets (distance √2 m) weigh less than the centre.
        let corner = w.column(0);
        assert!(corner[peak] < centre[peak] && corner[peak] > 0.0);
        assert!(offset_waves(&[100.0], &[0.0], &[10.0], &[0], (0.0, 0.0), &grid, &model).is_none());
    }
}
