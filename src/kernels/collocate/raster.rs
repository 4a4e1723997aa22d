//! The separable-Gaussian raster: every horizontal offset's simulated waveform of one shot,
//! built in one pass over the shot's ALS points.
//!
//! The footprint weight of a return at (x, y) for a footprint centred at (cx, cy) is
//! G(d) = g(x − cx)·g(y − cy)/(σ√(2π)) with g(u) = exp(−u²/(2σ²)) (docs/simulator-reference.md §1.3).
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
use crate::sim::{absolute_bin, tap_offsets, Pulse, SimConfig};

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
        self.values.len().checked_div(self.n_offsets).unwrap_or(0)
    }

    /// The waveform of offset column `c`, bottom to top (row order).
    pub fn column(&self, c: usize) -> Vec<f32> {
        self.values.iter().skip(c).step_by(self.n_offsets).copied().collect()
    }
}

/// Why no raster was built.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RasterError {
    /// No return contributes at any offset.
    NoReturns,
    /// The returns span more than [`MAX_HEIGHT_BINS`] bins.
    HeightRange,
}

/// Most bins a shot's returns may span (3 km at 0.15 m): beyond, the heights are corrupt and the
/// raster is not built (it would take 441 × 4 bytes per bin).
pub const MAX_HEIGHT_BINS: i64 = 20_000;

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

/// The largest squared distance that passes the simulator's contribution test (the test is
/// monotone in the distance): found once by bisection on the f64 values, so that each return
/// needs a comparison instead of a square root and an exponential.
fn contributing_d_sq_max(fsigma: f32) -> f64 {
    let r = cut_off_radius(fsigma) + 1.0;
    if !contributes(0.0, fsigma) {
        return -1.0;
    }
    // Positive f64 values order like their bit patterns.
    let (mut lo, mut hi) = (0f64.to_bits(), (r * r).to_bits());
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        if contributes(f64::from_bits(mid), fsigma) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    f64::from_bits(lo)
}

/// exp(−(e − k·s)²/(2σ²)) for k = 0, 1, …, out.len() − 1, by the recurrence
/// g_{k+1} = g_k·ρ_k, ρ_{k+1} = ρ_k·q (three exponentials instead of one per offset).
#[inline(always)]
fn gaussian_ladder(e: f64, s: f64, two_var: f64, q: f64, out: &mut [f32]) {
    let mut g = (-e * e / two_var).exp();
    let mut rho = ((2.0 * s * e - s * s) / two_var).exp();
    for o in out.iter_mut() {
        *o = g as f32;
        g *= rho;
        rho *= q;
    }
}

/// Builds the waveforms of every offset of `grid` around (x0, y0) from the returns `candidates`
/// (indices into `x`, `y`, `z`; returns beyond the support are ignored), with the footprint,
/// bin size of `model` and `pulse` (the shot's own, or the model's).
#[allow(clippy::too_many_arguments)]
pub fn offset_waves(
    x: &[f64],
    y: &[f64],
    z: &[f64],
    candidates: &[u32],
    (x0, y0): (f64, f64),
    grid: &OffsetGrid,
    model: &SimConfig,
    pulse: &Pulse,
) -> Result<OffsetWaves, RasterError> {
    let n = grid.n();
    let n_off = n * n;
    let sigma = model.fsigma as f64;
    let dz = model.res;
    let r_cut = cut_off_radius(model.fsigma);
    let r_cut_sq = r_cut * r_cut;
    let d_sq_max = contributing_d_sq_max(model.fsigma);
    let reach = r_cut + grid.max_offset();
    let centres: Vec<(f64, f64)> = (0..n).map(|i| (x0 + grid.offset(i), y0 + grid.offset(i))).collect();

    // Returns that reach at least one offset, with their bins.
    let mut kept: Vec<(u32, i64)> = Vec::with_capacity(candidates.len());
    let (mut lo, mut hi) = (i64::MAX, i64::MIN);
    for &c in candidates {
        let p = c as usize;
        let (ex, ey) = ((x[p] - x0).abs() - grid.max_offset(), (y[p] - y0).abs() - grid.max_offset());
        let (ex, ey) = (ex.max(0.0), ey.max(0.0));
        let reaches = ex <= reach && ey <= reach && ex * ex + ey * ey <= r_cut_sq;
        if !reaches || !z[p].is_finite() {
            continue;
        }
        let b = absolute_bin(z[p], dz);
        lo = lo.min(b);
        hi = hi.max(b);
        kept.push((c, b));
    }
    if kept.is_empty() {
        return Err(RasterError::NoReturns);
    }
    if hi - lo >= MAX_HEIGHT_BINS {
        return Err(RasterError::HeightRange);
    }
    let raw_rows = (hi - lo + 1) as usize;
    let mut w = vec![0f32; raw_rows * n_off];
    let norm = 1.0 / (sigma * (2.0 * std::f64::consts::PI).sqrt());
    let two_var = 2.0 * sigma * sigma;
    let step = grid.step;
    let q = (-2.0 * step * step / two_var).exp();
    let first = grid.offset(0);
    let mut gx = vec![0f32; n];
    let mut gy = vec![0f32; n];
    let mut ey_sq = vec![0f64; n];
    let mut any = false;
    for &(c, b) in &kept {
        let p = c as usize;
        let (px, py) = (x[p], y[p]);
        // Offsets advance by +step, so the distances to the centres shrink by step.
        gaussian_ladder(px - (x0 + first), step, two_var, q, &mut gx);
        gaussian_ladder(py - (y0 + first), step, two_var, q, &mut gy);
        for (e, c) in ey_sq.iter_mut().zip(&centres) {
            // Distances as the simulator forms them: return minus footprint centre.
            let ey = py - c.1;
            *e = ey * ey;
        }
        let row = &mut w[(b - lo) as usize * n_off..(b - lo + 1) as usize * n_off];
        let (gy, ey_sq) = (&gy[..n], &ey_sq[..n]);
        for (i, dst) in row.chunks_exact_mut(n).enumerate() {
            let ex = px - centres[i].0;
            let ex_sq = ex * ex;
            if !(ex_sq <= d_sq_max) {
                continue;
            }
            any = true;
            let g = (gx[i] as f64 * norm) as f32;
            // Branch-free over every offset j, masked by the simulator's cut-off test on
            // d² = ex² + ey² (the same f64 operations as the simulator). The product is formed
            // before the select so that optimised builds vectorise the loop; an indexed `while`
            // over equal-length slices keeps the unoptimised profiles fast too (no iterator calls,
            // no bounds checks left at opt-level 3).
            let mut j = 0;
            while j < dst.len() {
                let v = g * gy[j];
                dst[j] += if ex_sq + ey_sq[j] <= d_sq_max { v } else { 0.0 };
                j += 1;
            }
        }
    }
    if !any {
        return Err(RasterError::NoReturns);
    }

    // Pulse convolution on the absolute grid: the simulator's tap j moves a bin's energy
    // `offsets[j]` bins up (its bins count downwards: out[i] = Σⱼ in[i + offⱼ]·yⱼ).
    let offsets = tap_offsets(pulse, model);
    let (omin, omax) = (*offsets.iter().min().unwrap_or(&0), *offsets.iter().max().unwrap_or(&0));
    // Row r of the output is absolute bin lo + omin + r.
    let rows = raw_rows + (omax - omin) as usize;
    let mut out = vec![0f32; rows * n_off];
    for (&o, &yj) in offsets.iter().zip(&pulse.y) {
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
    Ok(OffsetWaves { first_bin: lo + omin, dz, n_offsets: n_off, values: out })
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
        let m = contributing_d_sq_max(5.5);
        assert!(contributes(m, 5.5) && !contributes(f64::from_bits(m.to_bits() + 1), 5.5));
        // Monotone around the boundary: a thousand values either side agree with the comparison.
        for k in 1..1000u64 {
            assert!(contributes(f64::from_bits(m.to_bits() - k * 1_000_000), 5.5));
            assert!(!contributes(f64::from_bits(m.to_bits() + k * 1_000_000), 5.5));
        }
    }

    #[test]
    fn gaussian_ladder_matches_direct_exponentials() {
        let mut g = vec![0f32; 21];
        gaussian_ladder(13.7, 1.0, 60.5, (-2.0f64 / 60.5).exp(), &mut g);
        for (k, v) in g.iter().enumerate() {
            let e = 13.7 - k as f64;
            let want = (-e * e / 60.5).exp() as f32;
            assert!((v - want).abs() <= want * 1e-6, "{k}: {v} vs {want}");
        }
    }

    #[test]
    fn one_return_gives_the_pulse_at_its_bin() {
        let mut model = SimConfig::new(Profile::Default);
        model.normalise_density = false;
        let grid = OffsetGrid::new(1.0, 1.0).unwrap();
        let w = offset_waves(&[0.0], &[0.0], &[10.0], &[0], (0.0, 0.0), &grid, &model, &model.pulse).unwrap();
        assert_eq!(w.n_offsets, 9);
        let centre = w.column(4);
        let peak = centre.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)).unwrap().0;
        assert_eq!(w.first_bin + peak as i64, absolute_bin(10.0, 0.15));
        // The corner offsets (distance √2 m) weigh less than the centre.
        let corner = w.column(0);
        assert!(corner[peak] < centre[peak] && corner[peak] > 0.0);
        assert_eq!(
            offset_waves(&[100.0], &[0.0], &[10.0], &[0], (0.0, 0.0), &grid, &model, &model.pulse),
            Err(RasterError::NoReturns)
        );
        let far =
            offset_waves(&[0.0, 0.0], &[0.0, 0.0], &[10.0, 5000.0], &[0, 1], (0.0, 0.0), &grid, &model, &model.pulse);
        assert_eq!(far, Err(RasterError::HeightRange));
    }
}
