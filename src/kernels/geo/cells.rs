//! The windows of a tile that a piece of work needs, as a set of square cells of [`READ_CELL_M`]:
//! each footprint or shot asks for the square of ALS around it, and a COPC tile is read only
//! where its octree nodes meet one of these cells (docs/copc.md). A set of cells, unlike a list of
//! overlapping squares, can be tested per point in constant time.

use std::collections::HashSet;

/// Side of the square cells in which reads of a COPC tile are planned (m): small against a
/// footprint's square (≈ 37 m across), so that the cells add at most one cell's width around it.
pub const READ_CELL_M: f64 = 10.0;

/// A set of [`READ_CELL_M`] cells, keyed by their integer column and row.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Cells {
    set: HashSet<(i64, i64)>,
}

fn index(v: f64) -> i64 {
    (v / READ_CELL_M).floor() as i64
}

impl Cells {
    /// The cells met by the square of half-width `half` around each of `centres`; positions that
    /// are not finite ask for nothing.
    pub fn around(centres: impl IntoIterator<Item = (f64, f64)>, half: f64) -> Self {
        let mut set = HashSet::new();
        for (x, y) in centres {
            if !(x.is_finite() && y.is_finite() && half.is_finite()) {
                continue;
            }
            for ix in index(x - half)..=index(x + half) {
                for iy in index(y - half)..=index(y + half) {
                    set.insert((ix, iy));
                }
            }
        }
        Cells { set }
    }

    /// Every cell's (column, row), sorted.
    pub fn keys(&self) -> Vec<(i64, i64)> {
        let mut k: Vec<_> = self.set.iter().copied().collect();
        k.sort_unstable();
        k
    }

    pub fn len(&self) -> usize {
        self.set.len()
    }

    pub fn is_empty(&self) -> bool {
        self.set.is_empty()
    }

    /// Whether the point (x, y) lies in one of the cells.
    pub fn contains(&self, x: f64, y: f64) -> bool {
        self.set.contains(&(index(x), index(y)))
    }

    /// Whether one of the cells meets the box [xmin, ymin, xmax, ymax] (edges included).
    pub fn meets(&self, b: [f64; 4]) -> bool {
        if !(b[0] <= b[2] && b[1] <= b[3]) {
            return false;
        }
        let (x0, x1, y0, y1) = (index(b[0]), index(b[2]), index(b[1]), index(b[3]));
        let span = (x1 - x0 + 1).saturating_mul(y1 - y0 + 1);
        if span > self.set.len() as i64 {
            self.set.iter().any(|&(ix, iy)| (x0..=x1).contains(&ix) && (y0..=y1).contains(&iy))
        } else {
            (x0..=x1).any(|ix| (y0..=y1).any(|iy| self.set.contains(&(ix, iy))))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_square_asks_for_the_cells_it_meets() {
        // 5 m around (25, 25): x and y from 20 to 30 → cells 2 and 3 on each axis.
        let c = Cells::around([(25.0, 25.0)], 5.0);
        assert_eq!(c.keys(), vec![(2, 2), (2, 3), (3, 2), (3, 3)]);
        assert!(c.contains(20.0, 39.99) && !c.contains(19.99, 25.0) && !c.contains(25.0, 40.0));
        // Negative coordinates floor, not truncate.
        assert_eq!(Cells::around([(-1.0, -1.0)], 0.5).keys(), vec![(-1, -1)]);
        assert!(Cells::around([(f64::NAN, 0.0)], 5.0).is_empty());
    }

    #[test]
    fn meets_boxes_small_and_large() {
        let c = Cells::around([(105.0, 5.0)], 1.0); // cell (10, 0)
        assert!(c.meets([100.0, 0.0, 100.0, 0.0]));
        assert!(c.meets([0.0, -1000.0, 1000.0, 1000.0])); // larger than the set: walks the set
        assert!(!c.meets([0.0, 0.0, 99.9, 50.0]));
        assert!(!c.meets([110.0, 0.0, 100.0, 10.0])); // empty box
    }
}
