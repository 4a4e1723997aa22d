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
        // Floor or truncation as an integer cast (the libm calls dominated the simulation): the
        // cast agrees with both from 0 up, and truncation also maps (−1, 0) to cell 0.
        let idx = |v: f64, o: f64| {
            let t = (v - o) / GRID_RES as f64;
            (t >= 0.0 || (self.truncate && t > -1.0)).then_some(t as usize)
        };
        let (i, j) = (idx(x, self.origin.0)?, idx(y, self.origin.1)?);
        (i < self.n.0 && j < self.n.1).then_some(j * self.n.0 + i)
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

/// Whether point `i` is the last return of its pulse (so counts once per pulse). A return numbered
/// 0 or beyond its pulse's number of returns (a corrupt or mis-written tile; ingest warns) counts as
/// its last: otherwise a tile of such points has no pulse at all, and every footprint over it would
/// be `partly_covered`.
pub fn is_last_return(points: &AlsPoints, i: usize) -> bool {
    let rn = points.return_number[i];
    rn == 0 || rn >= points.number_of_returns[i]
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

/// A footprint's square box [x0 ± half] × [y0 ± half], bounds included.
#[derive(Debug, Clone, Copy)]
pub struct Square {
    pub x0: f64,
    pub y0: f64,
    pub half: f64,
}

impl Square {
    /// Whether (x, y) lies in the box.
    pub fn contains(&self, x: f64, y: f64) -> bool {
        x >= self.x0 - self.half && x <= self.x0 + self.half && y >= self.y0 - self.half && y <= self.y0 + self.half
    }
}

/// The first returns of one pulse key found in a square.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Found {
    None,
    One((f64, f64)),
    Several,
}

/// Every point's pulse (by [`pulse_key`]) and the first returns of each pulse, over one point set:
/// built once per simulation so that a footprint finds a return's first return without sorting.
#[derive(Debug)]
pub struct PulseIndex {
    /// Per point: the first returns of its pulse within twice `half` (plus a metre against
    /// rounding) of it; `Several` also for a point without a pulse key. Read in the points' order,
    /// it answers the common case (`None` or `One`) without another lookup.
    near: Vec<Found>,
    /// The largest box half-width for which `near` decides.
    half: f64,
    /// Pulse of each point ([`NO_PULSE`] without a GPS time).
    pulse: Vec<u32>,
    /// Positions of the first returns of pulse k, by increasing x: `firsts[starts[k]..starts[k + 1]]`
    /// (more than one when two pulses share a key, e.g. the same tile mosaicked twice).
    starts: Vec<u32>,
    firsts: Vec<(f64, f64)>,
    /// Per point: its intensity over its pulse's (0 read as 1; NaN without a pulse key), the
    /// weight [`crate::sim::Weighting::Share`] gives it.
    share: Vec<f32>,
}

/// [`PulseIndex`] value of a point without a pulse key.
const NO_PULSE: u32 = u32::MAX;

impl PulseIndex {
    /// Groups the points by [`pulse_key`], for footprint boxes of half-width up to `half`.
    pub fn build(points: &AlsPoints, half: f64) -> PulseIndex {
        let n = points.len();
        let mut keyed: Vec<((u64, u16), u32)> =
            (0..n).filter_map(|i| pulse_key(points, i).map(|k| (k, i as u32))).collect();
        keyed.sort_unstable_by_key(|e| e.0);
        let mut index = PulseIndex {
            near: vec![Found::Several; n],
            half,
            pulse: vec![NO_PULSE; n],
            starts: vec![0],
            firsts: Vec::new(),
            share: vec![f32::NAN; n],
        };
        let intensity = |i: u32| f64::from(points.intensity_or_one(i as usize));
        for group in keyed.chunk_by(|a, b| a.0 == b.0) {
            let id = (index.starts.len() - 1) as u32;
            let start = index.firsts.len();
            let total: f64 = group.iter().map(|&(_, i)| intensity(i)).sum();
            for &(_, i) in group {
                index.share[i as usize] = (intensity(i) / total) as f32;
                index.pulse[i as usize] = id;
                if points.return_number[i as usize] == 1 {
                    index.firsts.push((points.x[i as usize], points.y[i as usize]));
                }
            }
            let firsts = &mut index.firsts[start..];
            firsts.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
            for &(_, i) in group {
                let (x, y) = (points.x[i as usize], points.y[i as usize]);
                index.near[i as usize] = in_square(firsts, Square { x0: x, y0: y, half: 2.0 * half + 1.0 });
            }
            index.starts.push(index.firsts.len() as u32);
        }
        index
    }

    /// Point `i`'s share of its pulse's intensity; `None` without a pulse key.
    pub fn intensity_share(&self, i: usize) -> Option<f32> {
        self.share.get(i).copied().filter(|s| !s.is_nan())
    }

    /// Position of the first return of point `i`, at (x, y), if exactly one of its pulse's first
    /// returns lies in `square`: none there, or two pulses with one key, give `None`.
    pub fn first_return(&self, i: usize, xy: (f64, f64), square: Square) -> Option<(f64, f64)> {
        match self.first_returns(i, xy, square) {
            Found::One(xy) => Some(xy),
            _ => None,
        }
    }

    /// The first returns of point `i`'s pulse in `square` (`One` only if it lies there): what
    /// [`PulseIndex::first_return`] answers from. In a smaller square inside it, `None` stays
    /// `None` and `One` is that return if the smaller square holds it; `Several` must be asked again.
    pub fn first_returns(&self, i: usize, (x, y): (f64, f64), square: Square) -> Found {
        let Some(&near) = self.near.get(i) else { return Found::None };
        // Every first return in a box holding (x, y) lies within twice its half-width of (x, y).
        let found = if near != Found::Several && square.half <= self.half && square.contains(x, y) {
            near
        } else {
            let firsts = self.pulse.get(i).and_then(|&k| {
                let k = k as usize;
                self.firsts.get(*self.starts.get(k)? as usize..*self.starts.get(k + 1)? as usize)
            });
            match firsts {
                Some(f) => in_square(f, square),
                None => return Found::None,
            }
        };
        match found {
            Found::One(xy) if !square.contains(xy.0, xy.1) => Found::None,
            other => other,
        }
    }
}

/// Which of the positions (sorted by x) lie in `square`.
fn in_square(sorted: &[(f64, f64)], square: Square) -> Found {
    let from = sorted.partition_point(|p| p.0 < square.x0 - square.half);
    let mut inside =
        sorted[from..].iter().take_while(|p| p.0 <= square.x0 + square.half).filter(|p| square.contains(p.0, p.1));
    match (inside.next(), inside.next()) {
        (None, _) => Found::None,
        (Some(&xy), None) => Found::One(xy),
        _ => Found::Several,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand_chacha::rand_core::{RngCore, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Uniform in [0, 1).
    struct Stream(ChaCha8Rng);

    impl Stream {
        fn uniform(&mut self) -> f64 {
            (self.0.next_u64() >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// Points of `pulses` pulses of 1–3 returns, the returns of a pulse up to 4 m apart; each
    /// pulse copied (same key) 0–2 more times, some copies 5 m away, some 150 m; some returns without
    /// GPS time; some pulses without a first return.
    fn mosaic(pulses: usize, rng: &mut Stream) -> AlsPoints {
        let mut p = AlsPoints::default();
        for k in 0..pulses {
            let (x, y) = (rng.uniform() * 80.0, rng.uniform() * 80.0);
            let n = 1 + (rng.uniform() * 3.0) as u8;
            let copies = (rng.uniform() * 3.0) as usize;
            let t = if rng.uniform() < 0.05 { f64::NAN } else { 1000.0 + k as f64 };
            let no_first = rng.uniform() < 0.05;
            for c in 0..=copies {
                let shift = if c == 0 {
                    0.0
                } else if rng.uniform() < 0.5 {
                    5.0
                } else {
                    150.0
                };
                for r in 1..=n {
                    p.x.push(x + shift + rng.uniform() * 4.0);
                    p.y.push(y + rng.uniform() * 4.0);
                    p.z.push(0.0);
                    p.intensity.push(1);
                    p.return_number.push(if no_first { r + 1 } else { r });
                    p.number_of_returns.push(n);
                    p.classification.push(1);
                    p.scan_angle_deg.push(0.0);
                    p.gps_time.push(t);
                    p.point_source_id.push(7);
                }
            }
        }
        p
    }

    /// The definition: the first returns in the box with the point's key, if exactly one.
    fn brute(p: &AlsPoints, i: usize, square: Square) -> Option<(f64, f64)> {
        let key = pulse_key(p, i)?;
        let found: Vec<usize> = (0..p.len())
            .filter(|&f| p.return_number[f] == 1 && pulse_key(p, f) == Some(key) && square.contains(p.x[f], p.y[f]))
            .collect();
        (found.len() == 1).then(|| (p.x[found[0]], p.y[found[0]]))
    }

    #[test]
    fn a_returns_first_return_is_the_only_one_of_its_key_in_the_box() {
        let mut rng = Stream(ChaCha8Rng::seed_from_u64(5));
        let p = mosaic(400, &mut rng);
        let half = 12.0;
        let index = PulseIndex::build(&p, half);
        let (mut shared, mut alone, mut found) = (0, 0, 0);
        for _ in 0..40 {
            let square = Square { x0: rng.uniform() * 100.0, y0: rng.uniform() * 80.0, half };
            for i in (0..p.len()).filter(|&i| square.contains(p.x[i], p.y[i])) {
                let expected = brute(&p, i, square);
                assert_eq!(index.first_return(i, (p.x[i], p.y[i]), square), expected, "point {i}");
                found += usize::from(expected.is_some());
                shared += usize::from(index.near[i] == Found::Several);
                alone += usize::from(index.near[i] != Found::Several);
            }
        }
        // Both paths were taken, and returns found their first return.
        assert!(shared > 0 && alone > 0 && found > 0, "shared {shared}, alone {alone}, found {found}");
    }
}
