//! Candidate selection: which ALS points are visited for a footprint, and in which order.
//!
//! * [`Octree`] reproduces the gediRat batch (`-listCoord`, docs/simulator-reference.md §1.1, §1.4):
//!   only points inside some footprint's square box are kept; they are filed, in file order, into
//!   a 40 × 40 top-level grid over the batch's bounding box; a footprint visits the cells of its
//!   box (upper index rounded up by 0.5), x outer and y inner. The waveform's extent and the f32
//!   summation order follow from these candidates, so they depend on the whole batch.
//! * [`CellGrid`] is the default index: square cells anchored at absolute multiples of the cell
//!   size, so a footprint's candidates depend on that footprint alone.

use super::points::AlsPoints;

/// Items filed into the cells of an unbounded grid of cells keyed (row, column), in key order
/// (row-major; each cell in filing order): cell k holds `items[start[k]..start[k + 1]]`.
/// When the occupied keys span a compact rectangle (at most [`DENSE_CELLS_PER_ITEM`] cells per
/// item) every cell of it is stored, built by counting and looked up by index; otherwise only
/// the occupied cells, found by binary search, so items kilometres apart (tiles scattered along
/// a track) cost no grid over their bounding box.
#[derive(Debug, Clone)]
struct Cells {
    layout: Layout,
    start: Vec<usize>,
    items: Vec<u32>,
}

#[derive(Debug, Clone)]
enum Layout {
    /// Every cell of rows `first.0..first.0 + ny` × columns `first.1..first.1 + nx`.
    Dense { first: (i64, i64), nx: usize, ny: usize },
    /// The occupied cells' keys, sorted.
    Sparse { keys: Vec<(i64, i64)> },
}

/// Cells per filed item up to which the rectangle of occupied keys is stored whole (plus
/// [`DENSE_CELLS_MIN`]): counting is three times faster than sorting, and a lookup by index
/// twice as fast as a binary search (10 M points, 5 m cells over 1 km²).
const DENSE_CELLS_PER_ITEM: usize = 4;
const DENSE_CELLS_MIN: usize = 4096;

impl Cells {
    /// Files `(cell, item)` pairs given in increasing item order; a cell keeps that order.
    fn build(mut filed: Vec<((i64, i64), u32)>) -> Cells {
        let (mut lo, mut hi) = ((i64::MAX, i64::MAX), (i64::MIN, i64::MIN));
        for &((j, i), _) in &filed {
            lo = (lo.0.min(j), lo.1.min(i));
            hi = (hi.0.max(j), hi.1.max(i));
        }
        let span = |a: i64, b: i64| usize::try_from(b.checked_sub(a)?.checked_add(1)?).ok();
        let dense = match (span(lo.0, hi.0), span(lo.1, hi.1)) {
            (Some(ny), Some(nx)) => nx
                .checked_mul(ny)
                .filter(|&n| n <= DENSE_CELLS_PER_ITEM * filed.len() + DENSE_CELLS_MIN)
                .map(|n| (nx, ny, n)),
            _ => None,
        };
        if let Some((nx, ny, n_cells)) = dense {
            let index = |(j, i): (i64, i64)| (j - lo.0) as usize * nx + (i - lo.1) as usize;
            let mut start = vec![0usize; n_cells + 1];
            for &(key, _) in &filed {
                start[index(key) + 1] += 1;
            }
            for c in 0..n_cells {
                start[c + 1] += start[c];
            }
            let mut fill = start.clone();
            let mut items = vec![0u32; filed.len()];
            for &(key, item) in &filed {
                let c = index(key);
                items[fill[c]] = item;
                fill[c] += 1;
            }
            return Cells { layout: Layout::Dense { first: lo, nx, ny }, start, items };
        }
        filed.sort_unstable();
        let mut keys: Vec<(i64, i64)> = Vec::new();
        let mut start = Vec::new();
        for (k, &(key, _)) in filed.iter().enumerate() {
            if keys.last() != Some(&key) {
                keys.push(key);
                start.push(k);
            }
        }
        start.push(filed.len());
        Cells { layout: Layout::Sparse { keys }, start, items: filed.into_iter().map(|(_, item)| item).collect() }
    }

    /// Positions in `items` of the cells (row, i0..=i1): one contiguous range.
    fn row_span(&self, row: i64, i0: i64, i1: i64) -> std::ops::Range<usize> {
        let (a, b) = match &self.layout {
            Layout::Dense { first, nx, ny } => {
                let (i0, i1) = (i0.max(first.1), i1.min(first.1 + *nx as i64 - 1));
                if row < first.0 || row >= first.0 + *ny as i64 || i1 < i0 {
                    return 0..0;
                }
                let r = (row - first.0) as usize * nx;
                (r + (i0 - first.1) as usize, r + (i1 - first.1) as usize + 1)
            }
            Layout::Sparse { keys } => {
                let a = keys.partition_point(|&k| k < (row, i0));
                (a, keys.partition_point(|&k| k <= (row, i1)).max(a))
            }
        };
        self.start[a]..self.start[b]
    }

    fn cell(&self, (row, column): (i64, i64)) -> &[u32] {
        &self.items[self.row_span(row, column, column)]
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
        let filed: Vec<((i64, i64), u32)> = (0..points.len())
            .filter(|&i| kept.contains(points.x[i], points.y[i]))
            .filter_map(|i| {
                let xb = ((points.x[i] - min_x) / res as f64) as i64;
                let yb = ((points.y[i] - min_y) / res as f64) as i64;
                ((0..nx as i64).contains(&xb) && (0..ny as i64).contains(&yb)).then_some(((yb, xb), i as u32))
            })
            .collect();
        Some(Octree { min_x, min_y, res, nx, ny, cells: Cells::build(filed) })
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
                out.extend_from_slice(self.cells.cell((j, i)));
            }
        }
    }
}

/// Which points fall in the square box of at least one footprint (gediRat `checkMultiPoints`,
/// inclusive bounds), answered through a coarse grid of footprints instead of a linear scan.
struct BoxLookup<'a> {
    centres: &'a [(f64, f64)],
    half: f64,
    /// Cells of `size` m anchored at multiples of `size`.
    size: f64,
    cells: Cells,
}

impl<'a> BoxLookup<'a> {
    fn new(centres: &'a [(f64, f64)], half: f64) -> BoxLookup<'a> {
        let size = (2.0 * half).max(1.0);
        let cell = |v: f64| (v / size).floor() as i64;
        // A box covers the cells between those of its corners.
        let mut filed = Vec::new();
        for (f, &(x, y)) in centres.iter().enumerate().filter(|(_, c)| c.0.is_finite() && c.1.is_finite()) {
            for j in cell(y - half)..=cell(y + half) {
                for i in cell(x - half)..=cell(x + half) {
                    filed.push(((j, i), f as u32));
                }
            }
        }
        BoxLookup { centres, half, size, cells: Cells::build(filed) }
    }

    fn contains(&self, x: f64, y: f64) -> bool {
        if !(x.is_finite() && y.is_finite()) {
            return false;
        }
        let key = ((y / self.size).floor() as i64, (x / self.size).floor() as i64);
        self.cells.cell(key).iter().any(|&f| {
            let (cx, cy) = self.centres[f as usize];
            x >= cx - self.half && x <= cx + self.half && y >= cy - self.half && y <= cy + self.half
        })
    }
}

/// Default spatial index: points sorted into square cells anchored at multiples of `size`
/// (a compact rectangle of cells, or only the occupied ones when the points lie far apart).
#[derive(Debug, Clone)]
pub struct CellGrid {
    size: f64,
    cells: Cells,
}

impl CellGrid {
    /// Files every point with finite coordinates into cells of `size` m.
    pub fn build(points: &AlsPoints, size: f64) -> CellGrid {
        CellGrid::from_xy(&points.x, &points.y, size)
    }

    /// Files every point (x[i], y[i]) with finite coordinates into cells of `size` m.
    pub fn from_xy(x: &[f64], y: &[f64], size: f64) -> CellGrid {
        let cell = |v: f64| (v / size).floor() as i64;
        let filed: Vec<((i64, i64), u32)> = x
            .iter()
            .zip(y)
            .enumerate()
            .filter(|(_, (x, y))| x.is_finite() && y.is_finite())
            .map(|(i, (&x, &y))| ((cell(y), cell(x)), i as u32))
            .collect();
        CellGrid { size, cells: Cells::build(filed) }
    }

    /// Point indices in cell order (row by row), i.e. the order [`CellGrid::candidates`] reads.
    pub fn order(&self) -> &[u32] {
        &self.cells.items
    }

    /// Appends to `out` the positions (in [`CellGrid::order`]) of the points of every cell that
    /// meets the box [x0 ± half] × [y0 ± half], row by row.
    pub fn candidates(&self, x0: f64, y0: f64, half: f64, out: &mut Vec<u32>) {
        if !(x0.is_finite() && y0.is_finite() && half.is_finite()) {
            return;
        }
        let cell = |v: f64| (v / self.size).floor() as i64;
        let (i0, i1) = (cell(x0 - half), cell(x0 + half));
        for j in cell(y0 - half)..=cell(y0 + half) {
            // Cells of a row are contiguous in `order`: one range per row.
            let span = self.cells.row_span(j, i0, i1);
            out.extend(span.start as u32..span.end as u32);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Brute force: indices of the points inside the cells meeting the box, row by row.
    fn brute(x: &[f64], y: &[f64], size: f64, (x0, y0, half): (f64, f64, f64)) -> Vec<u32> {
        let c = |v: f64| (v / size).floor() as i64;
        let mut hits: Vec<((i64, i64), u32)> = (0..x.len())
            .filter(|&i| {
                (c(x0 - half)..=c(x0 + half)).contains(&c(x[i])) && (c(y0 - half)..=c(y0 + half)).contains(&c(y[i]))
            })
            .map(|i| ((c(y[i]), c(x[i])), i as u32))
            .collect();
        hits.sort();
        hits.into_iter().map(|(_, i)| i).collect()
    }

    fn candidates(grid: &CellGrid, query: (f64, f64, f64)) -> Vec<u32> {
        let mut out = Vec::new();
        grid.candidates(query.0, query.1, query.2, &mut out);
        out.into_iter().map(|k| grid.order()[k as usize]).collect()
    }

    #[test]
    fn cell_grid_matches_brute_force_in_row_order() {
        // A pseudo-random cloud (LCG), some points on cell edges, one non-finite; then the same
        // with one point 1000 km away, which makes the cells sparse.
        let mut state = 12345u64;
        let mut next = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut x, mut y): (Vec<f64>, Vec<f64>) =
            (0..2000).map(|_| (700_000.0 + 80.0 * next(), 6_500_000.0 + 80.0 * next())).unzip();
        x.extend([700_010.0, 700_015.0, f64::NAN]);
        y.extend([6_500_020.0, 6_500_025.0, 6_500_030.0]);
        for far in [false, true] {
            if far {
                x.push(1_700_000.0);
                y.push(7_500_000.0);
            }
            let grid = CellGrid::from_xy(&x, &y, 5.0);
            assert_eq!(matches!(grid.cells.layout, Layout::Sparse { .. }), far);
            assert_eq!(grid.order().len(), x.len() - 1, "the non-finite point is not filed");
            for query in [
                (700_040.0, 6_500_040.0, 12.5),
                (700_010.0, 6_500_020.0, 5.0),
                (699_990.0, 6_500_001.0, 3.0),
                (800_000.0, 0.0, 10.0),
                (1_700_001.0, 7_500_001.0, 2.0),
            ] {
                assert_eq!(candidates(&grid, query), brute(&x, &y, 5.0, query), "{query:?} far {far}");
            }
        }
    }

    #[test]
    fn far_apart_points_need_no_grid_over_their_bounding_box() {
        // Two tiles 900 km apart along a track: a dense 5 m grid over their bounding box would
        // hold 3·10^10 cells.
        let x = [100_000.0, 100_003.5, 1_000_000.0, 1_000_001.0];
        let y = [6_000_000.0, 6_000_001.0, 6_900_000.0, 6_900_004.0];
        let grid = CellGrid::from_xy(&x, &y, 5.0);
        assert_eq!(candidates(&grid, (100_001.0, 6_000_000.0, 6.0)), vec![0, 1]);
        assert_eq!(candidates(&grid, (1_000_000.5, 6_900_002.0, 6.0)), vec![2, 3]);
        let centres = [(100_001.0, 6_000_000.0), (1_000_000.0, 6_900_000.0)];
        let boxes = BoxLookup::new(&centres, 2.0);
        let inside: Vec<bool> = x.iter().zip(&y).map(|(&x, &y)| boxes.contains(x, y)).collect();
        assert_eq!(inside, vec![true, false, true, false], "boxes are inclusive: 100 003.5 lies 0.5 m outside");
    }
}
