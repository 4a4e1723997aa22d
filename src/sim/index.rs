//! Candidate selection: which ALS points are visited for a footprint, and in which order.
//!
//! * [`Octree`] reproduces the gediRat batch (`-listCoord`, simulator-reference.md §1.1, §1.4):
//!   only points inside some footprint's square box are kept; they are filed, in file order, into
//!   a 40 × 40 top-level grid over the batch's bounding box; a footprint visits the cells of its
//!   box (upper index rounded up by 0.5), x outer and y inner. The waveform's extent and the f32
//!   summation order follow from these candidates, so they depend on the whole batch.
//! * [`CellGrid`] is the default index: square cells anchored at absolute multiples of the cell
//!   size, so a footprint's candidates depend on that footprint alone.

use super::points::AlsPoints;

/// Points filed into the cells of a regular grid (compressed rows: cell c holds
/// `items[start[c]..start[c + 1]]`, in file order).
#[derive(Debug, Clone)]
struct Cells {
    start: Vec<usize>,
    items: Vec<u32>,
}

impl Cells {
    /// Files `(point, cell)` pairs (in point order) into `n_cells` cells.
    fn build(n_cells: usize, filed: &[(u32, usize)]) -> Cells {
        let mut start = vec![0usize; n_cells + 1];
        for &(_, c) in filed {
            start[c + 1] += 1;
        }
        for c in 0..n_cells {
            start[c + 1] += start[c];
        }
        let mut fill = start.clone();
        let mut items = vec![0u32; filed.len()];
        for &(p, c) in filed {
            items[fill[c]] = p;
            fill[c] += 1;
        }
        Cells { start, items }
    }

    fn cell(&self, c: usize) -> &[u32] {
        &self.items[self.start[c]..self.start[c + 1]]
    }
}

/// The top level of gediRat's octree (0 levels below, 40 cells along the longer side).
#[derive(Debug, Clone)]
pub struct Octree {
    min_x: f64,
    min_y: f64,
    res: f32,
    nx: usize,
    ny: usize,
    cells: Cells,
}

/// Number of top-level octree cells along the longer side (gediRat `-nOctPix` default).
const OCT_TOP: u32 = 40;

impl Octree {
    /// Builds the octree of a batch of footprint centres with search half-width `max_sep`.
    /// Returns `None` when there is no footprint.
    pub fn build(points: &AlsPoints, centres: &[(f64, f64)], max_sep: f64) -> Option<Octree> {
        let (mut min_x, mut max_x, mut min_y, mut max_y) = (1e9f64, -1e9f64, 1e9f64, -1e9f64);
        for &(x, y) in centres {
            min_x = min_x.min(x);
            max_x = max_x.max(x);
            min_y = min_y.min(y);
            max_y = max_y.max(y);
        }
        if centres.is_empty() {
            return None;
        }
        let (min_x, max_x, min_y, max_y) = (min_x - max_sep, max_x + max_sep, min_y - max_sep, max_y + max_sep);
        let dx = (max_x - min_x) as f32;
        let dy = (max_y - min_y) as f32;
        let res = if dx > dy { (dx as f64 / OCT_TOP as f64) as f32 } else { (dy as f64 / OCT_TOP as f64) as f32 };
        let nx = (dx / res) as usize + 1;
        let ny = (dy / res) as usize + 1;
        let kept = BoxLookup::new(centres, max_sep);
        let filed: Vec<(u32, usize)> = (0..points.len())
            .filter(|&i| kept.contains(points.x[i], points.y[i]))
            .filter_map(|i| {
                let xb = ((points.x[i] - min_x) / res as f64) as i64;
                let yb = ((points.y[i] - min_y) / res as f64) as i64;
                ((0..nx as i64).contains(&xb) && (0..ny as i64).contains(&yb))
                    .then(|| (i as u32, yb as usize * nx + xb as usize))
            })
            .collect();
        Some(Octree { min_x, min_y, res, nx, ny, cells: Cells::build(nx * ny, &filed) })
    }

    /// Appends to `out` the candidates of the footprint box [x0 ± half] × [y0 ± half], in the
    /// reference's order (cells i outer, j inner; each cell in file order).
    pub fn candidates(&self, x0: f64, y0: f64, half: f64, out: &mut Vec<u32>) {
        let res = self.res as f64;
        let min_i = ((x0 - half - self.min_x) / res) as i64;
        let max_i = ((x0 + half - self.min_x) / res + 0.5) as i64;
        let min_j = ((y0 - half - self.min_y) / res) as i64;
        let max_j = ((y0 + half - self.min_y) / res + 0.5) as i64;
        for i in min_i.max(0)..=max_i.min(self.nx as i64 - 1) {
            for j in min_j.max(0)..=max_j.min(self.ny as i64 - 1) {
                out.extend_from_slice(self.cells.cell(i as usize + j as usize * self.nx));
            }
        }
    }
}

/// Which points fall in the square box of at least one footprint (gediRat `checkMultiPoints`,
/// inclusive bounds), answered through a coarse grid of footprints instead of a linear scan.
struct BoxLookup<'a> {
    centres: &'a [(f64, f64)],
    half: f64,
    origin: (f64, f64),
    size: f64,
    nx: usize,
    ny: usize,
    cells: Cells,
}

impl<'a> BoxLookup<'a> {
    fn new(centres: &'a [(f64, f64)], half: f64) -> BoxLookup<'a> {
        let size = (2.0 * half).max(1.0);
        let min_x = centres.iter().map(|c| c.0).fold(f64::INFINITY, f64::min) - half;
        let min_y = centres.iter().map(|c| c.1).fold(f64::INFINITY, f64::min) - half;
        let max_x = centres.iter().map(|c| c.0).fold(f64::NEG_INFINITY, f64::max) + half;
        let max_y = centres.iter().map(|c| c.1).fold(f64::NEG_INFINITY, f64::max) + half;
        let nx = ((max_x - min_x) / size) as usize + 1;
        let ny = ((max_y - min_y) / size) as usize + 1;
        let cell = |v: f64, o: f64, n: usize| (((v - o) / size).floor().max(0.0) as usize).min(n - 1);
        // A box covers the cells between those of its corners (the cell map is monotone).
        let mut filed = Vec::new();
        for (f, &(x, y)) in centres.iter().enumerate() {
            for j in cell(y - half, min_y, ny)..=cell(y + half, min_y, ny) {
                for i in cell(x - half, min_x, nx)..=cell(x + half, min_x, nx) {
                    filed.push((f as u32, j * nx + i));
                }
            }
        }
        filed.sort_by_key(|&(_, c)| c);
        BoxLookup { centres, half, origin: (min_x, min_y), size, nx, ny, cells: Cells::build(nx * ny, &filed) }
    }

    fn contains(&self, x: f64, y: f64) -> bool {
        let i = ((x - self.origin.0) / self.size).floor();
        let j = ((y - self.origin.1) / self.size).floor();
        if !(i >= 0.0 && j >= 0.0 && (i as usize) < self.nx && (j as usize) < self.ny) {
            return false;
        }
        self.cells.cell(j as usize * self.nx + i as usize).iter().any(|&f| {
            let (cx, cy) = self.centres[f as usize];
            x >= cx - self.half && x <= cx + self.half && y >= cy - self.half && y <= cy + self.half
        })
    }
}

/// Default spatial index: points sorted into square cells anchored at multiples of `size`.
#[derive(Debug, Clone)]
pub struct CellGrid {
    size: f64,
    /// Absolute index (floor(x/size), floor(y/size)) of cell (0, 0).
    first: (i64, i64),
    nx: usize,
    ny: usize,
    cells: Cells,
}

impl CellGrid {
    /// Files every point with finite coordinates into cells of `size` m.
    pub fn build(points: &AlsPoints, size: f64) -> CellGrid {
        CellGrid::from_xy(&points.x, &points.y, size)
    }

    /// Files every point (x[i], y[i]) with finite coordinates into cells of `size` m.
    pub fn from_xy(x: &[f64], y: &[f64], size: f64) -> CellGrid {
        let abs = |v: f64| (v / size).floor() as i64;
        let n = x.len().min(y.len());
        let finite = |i: &usize| x[*i].is_finite() && y[*i].is_finite();
        let (mut lo, mut hi) = ((i64::MAX, i64::MAX), (i64::MIN, i64::MIN));
        for i in (0..n).filter(finite) {
            let (cx, cy) = (abs(x[i]), abs(y[i]));
            lo = (lo.0.min(cx), lo.1.min(cy));
            hi = (hi.0.max(cx), hi.1.max(cy));
        }
        if lo.0 > hi.0 {
            return CellGrid { size, first: (0, 0), nx: 0, ny: 0, cells: Cells::build(0, &[]) };
        }
        let (nx, ny) = ((hi.0 - lo.0 + 1) as usize, (hi.1 - lo.1 + 1) as usize);
        let filed: Vec<(u32, usize)> = (0..n)
            .filter(finite)
            .map(|i| {
                let (cx, cy) = ((abs(x[i]) - lo.0) as usize, (abs(y[i]) - lo.1) as usize);
                (i as u32, cy * nx + cx)
            })
            .collect();
        CellGrid { size, first: lo, nx, ny, cells: Cells::build(nx * ny, &filed) }
    }

    /// Point indices in cell order (row by row), i.e. the order [`CellGrid::candidates`] reads.
    pub fn order(&self) -> &[u32] {
        &self.cells.items
    }

    /// Appends to `out` the positions (in [`CellGrid::order`]) of the points of every cell that
    /// meets the box [x0 ± half] × [y0 ± half], row by row.
    pub fn candidates(&self, x0: f64, y0: f64, half: f64, out: &mut Vec<u32>) {
        if self.nx == 0 {
            return;
        }
        let rel = |v: f64, first: i64, n: usize| ((v / self.size).floor() as i64 - first).clamp(-1, n as i64);
        let (i0, i1) = (rel(x0 - half, self.first.0, self.nx), rel(x0 + half, self.first.0, self.nx));
        let (j0, j1) = (rel(y0 - half, self.first.1, self.ny), rel(y0 + half, self.first.1, self.ny));
        for j in j0.max(0)..=j1.min(self.ny as i64 - 1) {
            let row = j as usize * self.nx;
            let (a, b) = (i0.max(0) as usize, i1.min(self.nx as i64 - 1));
            if b < a as i64 {
                continue;
            }
            // Cells of a row are contiguous in `order`: one range per row.
            let (s, e) = (self.cells.start[row + a], self.cells.start[row + b as usize + 1]);
            out.extend(s as u32..e as u32);
        }
    }
}
