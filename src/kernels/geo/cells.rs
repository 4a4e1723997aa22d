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

    /// The cells that meet the box [xmin, ymin, xmax, ymax] (edges included).
    pub fn within(&self, b: [f64; 4]) -> Cells {
        let (x0, x1, y0, y1) = (index(b[0]), index(b[2]), index(b[1]), index(b[3]));
        let set = self.set.iter().filter(|&&(ix, iy)| (x0..=x1).contains(&ix) && (y0..=y1).contains(&iy));
        Cells { set: set.copied().collect() }
    }

    /// The cells of `self` that are not in `other`.
    pub fn without(&self, other: &Cells) -> Cells {
        Cells { set: self.set.difference(&other.set).copied().collect() }
    }

    /// The cells of `self` and of `other`.
    pub fn union(&self, other: &Cells) -> Cells {
        Cells { set: self.set.union(&other.set).copied().collect() }
    }

    /// The cells as text, row by row, each row's columns as runs: `row:col0-col1,col2;row:…`
    /// (as stored in the dataset, docs/schemas.md). [`Cells::parse`] reads it back.
    pub fn to_text(&self) -> String {
        let mut keys: Vec<(i64, i64)> = self.set.iter().map(|&(ix, iy)| (iy, ix)).collect();
        keys.sort_unstable();
        let mut rows: Vec<String> = Vec::new();
        let mut i = 0;
        while i < keys.len() {
            let row = keys[i].0;
            let mut runs: Vec<String> = Vec::new();
            while i < keys.len() && keys[i].0 == row {
                let start = keys[i].1;
                let mut end = start;
                while i + 1 < keys.len() && keys[i + 1] == (row, end + 1) {
                    end += 1;
                    i += 1;
                }
                i += 1;
                runs.push(if end == start { start.to_string() } else { format!("{start}-{end}") });
            }
            rows.push(format!("{row}:{}", runs.join(",")));
        }
        rows.join(";")
    }

    /// The cells written by [`Cells::to_text`]; `None` if `text` is not in that form or holds more
    /// than `max_cells` cells.
    pub fn parse(text: &str, max_cells: usize) -> Option<Cells> {
        let mut set = HashSet::new();
        for row in text.split(';').filter(|r| !r.is_empty()) {
            let (iy, runs) = row.split_once(':')?;
            let iy: i64 = iy.trim().parse().ok()?;
            for run in runs.split(',') {
                // A run's end may be negative: split at the '-' that follows the first digit.
                let cut = run.char_indices().skip(1).find(|&(_, c)| c == '-').map(|(k, _)| k);
                let (a, b) = match cut {
                    Some(k) => (run[..k].trim().parse().ok()?, run[k + 1..].trim().parse().ok()?),
                    None => {
                        let v: i64 = run.trim().parse().ok()?;
                        (v, v)
                    }
                };
                if b < a || (b - a) as u64 >= max_cells as u64 {
                    return None;
                }
                for ix in a..=b {
                    set.insert((ix, iy));
                    if set.len() > max_cells {
                        return None;
                    }
                }
            }
        }
        Some(Cells { set })
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

/// The squares of half-width `half` around a set of centres (shots), from which the cells of one
/// tile are drawn without going through every centre: the centres are kept sorted by x.
#[derive(Debug, Clone, Default)]
pub struct Windows {
    centres: Vec<(f64, f64)>,
    half: f64,
}

impl Windows {
    /// The windows around `centres` (positions that are not finite are left out).
    pub fn new(centres: impl IntoIterator<Item = (f64, f64)>, half: f64) -> Self {
        let mut centres: Vec<(f64, f64)> =
            centres.into_iter().filter(|(x, y)| x.is_finite() && y.is_finite()).collect();
        centres.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        Windows { centres, half }
    }

    /// Half-width of each window (m).
    pub fn half(&self) -> f64 {
        self.half
    }

    /// Number of centres.
    pub fn len(&self) -> usize {
        self.centres.len()
    }

    pub fn is_empty(&self) -> bool {
        self.centres.is_empty()
    }

    /// The cells of the windows that meet the box [xmin, ymin, xmax, ymax].
    pub fn cells_in(&self, b: [f64; 4]) -> Cells {
        let h = self.half;
        let from = self.centres.partition_point(|c| c.0 < b[0] - h);
        let to = self.centres.partition_point(|c| c.0 <= b[2] + h);
        let near = self.centres[from..to].iter().filter(|c| c.1 >= b[1] - h && c.1 <= b[3] + h);
        Cells::around(near.copied(), h).within(b)
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

    #[test]
    fn text_round_trip_and_set_operations() {
        let a = Cells::around([(5.0, 5.0), (-35.0, 5.0)], 12.0);
        let text = a.to_text();
        assert_eq!(text, "-1:-5--3,-1-1;0:-5--3,-1-1;1:-5--3,-1-1");
        assert_eq!(Cells::parse(&text, 100), Some(a.clone()));
        assert_eq!(Cells::parse("", 10), Some(Cells::default()));
        assert_eq!(Cells::parse(&text, 10), None); // 18 cells > 10
        for bad in ["x", "1:2-1", "1:a", "1", "1:0-99999999999"] {
            assert_eq!(Cells::parse(bad, 1000), None, "{bad}");
        }
        let b = Cells::around([(5.0, 5.0)], 1.0); // cell (0, 0)
        assert_eq!(a.without(&b).len(), a.len() - 1);
        assert_eq!(a.without(&b).union(&b), a);
        assert_eq!(a.within([0.0, 0.0, 9.0, 9.0]).keys(), vec![(0, 0)]);
    }

    #[test]
    fn windows_give_the_cells_of_one_box() {
        let w = Windows::new([(500.0, 500.0), (2500.0, 500.0), (f64::NAN, 0.0), (995.0, 10.0)], 10.0);
        assert_eq!(w.len(), 3);
        let tile = [0.0, 0.0, 999.99, 999.99];
        let cells = w.cells_in(tile);
        assert_eq!(cells, Cells::around([(500.0, 500.0), (995.0, 10.0)], 10.0).within(tile));
        assert!(cells.contains(999.0, 5.0) && !cells.contains(1001.0, 5.0));
        assert!(w.cells_in([3000.0, 0.0, 3999.0, 999.0]).is_empty());
    }
}
