//! The correlation surface of a segment: mean Pearson r over its shots at every horizontal
//! offset × vertical lag, its maximum and how sharp it is.

use super::correlation::{parabolic_peak, LagWindow};
use super::OffsetGrid;

/// Mean r over shots, laid out `[offset][lag]` (offset (i, j) at i·n + j).
#[derive(Debug, Clone)]
pub struct Surface {
    grid: OffsetGrid,
    window: LagWindow,
    /// Vertical bin size (m).
    dz: f64,
    r: Vec<f64>,
    shots: usize,
}

/// The optimum of a surface and the extent of the region within a tolerance of it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Optimum {
    /// Horizontal offset (m) along x, refined between grid nodes by a parabola.
    pub dx: f64,
    /// Horizontal offset (m) along y.
    pub dy: f64,
    /// Vertical offset (m): lag × dz, refined by a parabola.
    pub dz: f64,
    /// Mean r at the optimum.
    pub r: f64,
    /// Half-extent (m) along x of the region where r ≥ best − tolerance.
    pub dx_halfwidth: f64,
    /// Half-extent (m) along y.
    pub dy_halfwidth: f64,
    /// Half-extent (m) along z.
    pub dz_halfwidth: f64,
    /// The best lag lies on the first or last lag of the window (the window should move).
    pub at_window_edge: bool,
}

impl Surface {
    /// An empty sum over `grid` × `window`.
    pub fn new(grid: OffsetGrid, window: LagWindow, dz: f64) -> Surface {
        let n = grid.n() * grid.n();
        Surface { grid, window, dz, r: vec![0.0; n * window.len], shots: 0 }
    }

    /// Adds one shot's r (`[offset][lag]`, from [`super::correlation::SimulatedProfiles::correlate`]).
    pub fn add(&mut self, shot_r: &[f32]) {
        debug_assert_eq!(shot_r.len(), self.r.len());
        for (s, &v) in self.r.iter_mut().zip(shot_r) {
            *s += v as f64;
        }
        self.shots += 1;
    }

    /// Shots added.
    pub fn shots(&self) -> usize {
        self.shots
    }

    fn mean(&self, c: usize, li: usize) -> f64 {
        self.r[c * self.window.len + li] / self.shots.max(1) as f64
    }

    /// The maximum of the mean r and the half-extents of the region within `tolerance` of it.
    /// `None` before any shot was added.
    pub fn optimum(&self, tolerance: f64) -> Option<Optimum> {
        if self.shots == 0 {
            return None;
        }
        let n = self.grid.n();
        let nl = self.window.len;
        // Best lag (refined) per offset.
        let mut best_c = 0;
        let mut best = (0f64, f64::NEG_INFINITY, 0usize); // (refined lag index, r, node lag index)
        let mut per_offset = vec![f64::NEG_INFINITY; n * n];
        for (c, best_r) in per_offset.iter_mut().enumerate() {
            let curve: Vec<f64> = (0..nl).map(|li| self.mean(c, li)).collect();
            let li = argmax(&curve);
            let (pos, r) = parabolic_peak(&curve, li);
            *best_r = r;
            if r > best.1 {
                best = (pos, r, li);
                best_c = c;
            }
        }
        let (bi, bj) = (best_c / n, best_c % n);
        // Horizontal refinement: parabolas through the neighbours' best r along each axis; the
        // optimum's r adds both parabolas' gains over the node.
        let along = |vals: Vec<f64>, i: usize| parabolic_peak(&vals, i);
        let (xi, rx) = along((0..n).map(|i| per_offset[i * n + bj]).collect(), bi);
        let (yj, ry) = along((0..n).map(|j| per_offset[bi * n + j]).collect(), bj);
        let r_best = best.1 + (rx - best.1) + (ry - best.1);
        let thr = r_best - tolerance;

        // Region {nodes with r ≥ thr} ∪ {best node}; its extent along each axis, with each
        // boundary between a node inside and its neighbour outside placed where the parabola
        // through that neighbour, the node and the node's other neighbour crosses the threshold.
        let mut ext = [(f64::INFINITY, f64::NEG_INFINITY); 3];
        let value = |node: [usize; 3]| self.mean(node[0] * n + node[1], node[2]);
        let dims = [n, n, nl];
        for i in 0..n {
            for j in 0..n {
                for l in 0..nl {
                    let node = [i, j, l];
                    let v = value(node);
                    if !(v >= thr) && node != [bi, bj, best.2] {
                        continue;
                    }
                    for axis in 0..3 {
                        let at = node[axis] as f64;
                        let (mut lo, mut hi) = (at, at);
                        for dir in [-1i64, 1] {
                            let step = |k: i64| {
                                let t = node[axis] as i64 + k * dir;
                                (t >= 0 && t < dims[axis] as i64).then(|| {
                                    let mut o = node;
                                    o[axis] = t as usize;
                                    value(o)
                                })
                            };
                            let Some(w) = step(1) else { continue };
                            if w >= thr {
                                continue;
                            }
                            let f = crossing(step(-1), v, w, thr);
                            if dir < 0 {
                                lo = at - f
                            } else {
                                hi = at + f
                            }
                        }
                        ext[axis].0 = ext[axis].0.min(lo);
                        ext[axis].1 = ext[axis].1.max(hi);
                    }
                }
            }
        }
        let half = |e: (f64, f64), unit: f64| (e.1 - e.0) / 2.0 * unit;
        Some(Optimum {
            dx: self.grid.offset_at(xi),
            dy: self.grid.offset_at(yj),
            dz: (self.window.first as f64 + best.0) * self.dz,
            r: r_best,
            dx_halfwidth: half(ext[0], self.grid.step),
            dy_halfwidth: half(ext[1], self.grid.step),
            dz_halfwidth: half(ext[2], self.dz),
            at_window_edge: best.2 == 0 || best.2 + 1 == nl,
        })
    }
}

/// Where, between a node of value `v` ≥ `thr` (t = 0) and its neighbour `w` < `thr` (t = 1),
/// the curve crosses `thr`: on the parabola through (−1, `before`), (0, v), (1, w) when the node's
/// other neighbour exists, else on the line.
fn crossing(before: Option<f64>, v: f64, w: f64, thr: f64) -> f64 {
    let linear = if v > w { ((v - thr) / (v - w)).clamp(0.0, 1.0) } else { 0.0 };
    let Some(u) = before else { return linear };
    let (a, b, c) = ((w + u) / 2.0 - v, (w - u) / 2.0, v - thr);
    if a.abs() < 1e-12 {
        return linear;
    }
    let disc = b * b - 4.0 * a * c;
    if disc < 0.0 {
        return linear;
    }
    let q = disc.sqrt();
    [(-b + q) / (2.0 * a), (-b - q) / (2.0 * a)]
        .into_iter()
        .filter(|t| (0.0..=1.0).contains(t))
        .fold(None, |m: Option<f64>, t| Some(m.map_or(t, |m| m.min(t))))
        .unwrap_or(linear)
}

/// Index of the largest value (first on ties; NaN never wins).
fn argmax(v: &[f64]) -> usize {
    let mut best = 0;
    for (i, &x) in v.iter().enumerate() {
        if x > v[best] || v[best].is_nan() {
            best = i;
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn optimum_and_halfwidths_of_a_quadratic_bowl() {
        let grid = OffsetGrid::new(3.0, 1.0).unwrap();
        let window = LagWindow::around(300, 10);
        let n = grid.n();
        // r = 1 − 0.01·(dx − 1.2)² − 0.02·(dy + 0.4)² − 0.5·(dz − 45.1)²
        let mut shot = vec![0f32; n * n * window.len];
        for i in 0..n {
            for j in 0..n {
                for l in 0..window.len {
                    let (x, y, z) = (grid.offset(i), grid.offset(j), window.lag(l) as f64 * 0.15);
                    let r = 1.0 - 0.01 * (x - 1.2).powi(2) - 0.02 * (y + 0.4).powi(2) - 0.5 * (z - 45.1).powi(2);
                    shot[(i * n + j) * window.len + l] = r as f32;
                }
            }
        }
        let mut s = Surface::new(grid, window, 0.15);
        assert!(s.optimum(0.005).is_none());
        s.add(&shot);
        s.add(&shot);
        let o = s.optimum(0.005).unwrap();
        assert!((o.dx - 1.2).abs() < 1e-3 && (o.dy + 0.4).abs() < 1e-3, "{o:?}");
        assert!((o.dz - 45.1).abs() < 1e-3, "{o:?}");
        assert!(o.r > 0.9999 && !o.at_window_edge);
        // The best node is (1, 0, lag 301 = 45.15 m), 0.0036 + 0.00125 below the optimum r = 1;
        // it alone lies within 0.005, and the parabolas through it cross r = 0.995 exactly.
        let want = |penalty: f64, k: f64| ((0.005 - penalty) / k).sqrt();
        assert!((o.dx_halfwidth - want(0.0032 + 0.00125, 0.01)).abs() < 1e-3, "{o:?}");
        assert!((o.dy_halfwidth - want(0.0004 + 0.00125, 0.02)).abs() < 1e-3, "{o:?}");
        assert!((o.dz_halfwidth - want(0.0036, 0.5)).abs() < 1e-3, "{o:?}");
    }
}
