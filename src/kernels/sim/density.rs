//! ALS sampling density: the 1.5 m grid of pulses (last returns) used to normalise the footprint
//! weights (docs/simulator-reference.md §1.5), the coverage it implies, and the header densities.

use super::points::AlsPoints;

/// Cell size of the normalisation grid (m).
pub const GRID_RES: f32 = 1.5;

/// Pulse counts on a 1.5 m grid over one footprint's square box.
#[derive(Debug, Clone)]
pub struct DensityGrid {
    origin: (f64, f64),
    n: (usize, usize),
    /// Reference quirk: cell index by truncation toward zero from an origin one cell inside the
    /// box, so cell 0 is 3 m wide (Q4); otherwise floor from the box corner.
    truncate: bool,
    counts: Vec<u32>,
}

impl DensityGrid {
    /// Empty grid over the box [x0 ± half] × [y0 ± half], with the reference's shifted origin
    /// and truncation when `shifted` (Q4).
    pub fn new(x0: f64, y0: f64, half: f64, shifted: bool) -> DensityGrid {
        let (min_x, min_y) = (x0 - half, y0 - half);
        let span = ((x0 + half) - min_x) as f32;
        let (n, origin, truncate) = if shifted {
            ((span / GRID_RES) as usize + 2, (min_x + GRID_RES as f64, min_y + GRID_RES as f64), true)
        } else {
            ((span / GRID_RES).ceil() as usize + 1, (min_x, min_y), false)
        };
        DensityGrid { origin, n: (n, n), truncate, counts: vec![0; n * n] }
    }

    /// Index of the cell holding (x, y), if any.
    pub fn cell(&self, x: f64, y: f64) -> Option<usize> {
        let idx = |v: f64, o: f64| {
            let t = (v - o) / GRID_RES as f64;
            if self.truncate {
                t.trunc()
            } else {
                t.floor()
            }
        };
        let (i, j) = (idx(x, self.origin.0), idx(y, self.origin.1));
        (i >= 0.0 && j >= 0.0 && (i as usize) < self.n.0 && (j as usize) < self.n.1)
            .then(|| j as usize * self.n.0 + i as usize)
    }

    /// Counts one pulse at (x, y).
    pub fn add_pulse(&mut self, x: f64, y: f64) {
        if let Some(c) = self.cell(x, y) {
            self.counts[c] += 1;
        }
    }

    /// Forgets every count (the reference does this when no point lies within 2σ of the centre).
    pub fn clear(&mut self) {
        self.counts.fill(0);
    }

    /// Number of pulses in the cell of (x, y) (0 outside the grid).
    pub fn pulses_at(&self, x: f64, y: f64) -> u32 {
        self.cell(x, y).map_or(0, |c| self.counts[c])
    }

    /// Fraction of the cells whose centre lies within `radius` of (x0, y0) that hold a pulse
    /// (1 when no cell centre is that close).
    pub fn covered_fraction(&self, x0: f64, y0: f64, radius: f64) -> f32 {
        let (mut within, mut covered) = (0u32, 0u32);
        let centre = |k: usize, o: f64| o + (k as f64 + 0.5) * GRID_RES as f64;
        for j in 0..self.n.1 {
            for i in 0..self.n.0 {
                let (dx, dy) = (centre(i, self.origin.0) - x0, centre(j, self.origin.1) - y0);
                if dx * dx + dy * dy < radius * radius {
                    within += 1;
                    covered += u32::from(self.counts[j * self.n.0 + i] > 0);
                }
            }
        }
        if within == 0 {
            1.0
        } else {
            covered as f32 / within as f32
        }
    }
}

/// Point and pulse densities (per m²) within `radius_sq` of a footprint centre, as the
/// reference's header "density point … beam …".
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Densities {
    /// Returns per m².
    pub point: f32,
    /// Last returns (pulses) per m².
    pub beam: f32,
}

/// Whether point `i` is the last return of its pulse (so counts once per pulse).
pub fn is_last_return(points: &AlsPoints, i: usize) -> bool {
    points.return_number[i] == points.number_of_returns[i]
}

/// How the density normalisation counts pulses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DensityCount {
    /// gediRat (§1.5): every return is divided by the last returns of its own 1.5 m cell.
    LastReturns,
    /// Every pulse is counted once, at its first return, and all its returns are divided by the
    /// count of that cell. On a slanted ALS ray a pulse's returns lie metres apart, so dividing
    /// each return by its own cell's count weighs the canopy (counting last returns) or the ground
    /// (counting first returns) up (docs/diagnosis.md, "Density normalisation"). Pulses are found
    /// by GPS time and flight line; a return whose pulse is not found (no GPS time, first return
    /// outside the box, two pulses with one key) uses its own cell.
    Pulses,
}

/// Identity of a return's pulse: GPS time and flight line (`None` without a GPS time).
pub fn pulse_key(points: &AlsPoints, i: usize) -> Option<(u64, u16)> {
    let t = points.gps_time[i];
    (t.is_finite() && t != 0.0).then(|| (t.to_bits(), points.point_source_id[i]))
}

/// The first returns of the pulses in a footprint's box, by [`pulse_key`], while the grid counts.
#[derive(Debug, Default)]
pub struct PulseFirsts(Vec<((u64, u16), (f64, f64))>);

impl PulseFirsts {
    /// Records the first return of a pulse.
    pub fn add(&mut self, key: (u64, u16), x: f64, y: f64) {
        self.0.push((key, (x, y)));
    }

    /// The pulse count of each recorded pulse's cell in `grid` (counting done); a key recorded
    /// twice (two pulses, one key) is dropped.
    pub fn counts(mut self, grid: &DensityGrid) -> PulseCounts {
        self.0.sort_unstable_by_key(|a| a.0);
        let f = &self.0;
        PulseCounts(
            (0..f.len())
                .filter(|&k| (k == 0 || f[k - 1].0 != f[k].0) && (k + 1 == f.len() || f[k + 1].0 != f[k].0))
                .map(|k| (f[k].0, grid.pulses_at(f[k].1 .0, f[k].1 .1)))
                .collect(),
        )
    }
}

/// Pulse count of the cell of each pulse's first return, sorted by [`pulse_key`].
#[derive(Debug, Default)]
pub struct PulseCounts(Vec<((u64, u16), u32)>);

impl PulseCounts {
    /// Pulse count of the cell of this pulse's first return, if the pulse was recorded once.
    pub fn get(&self, key: (u64, u16)) -> Option<u32> {
        self.0.binary_search_by(|e| e.0.cmp(&key)).ok().map(|k| self.0[k].1)
    }
}
