//! Footprints simulated against the `als/` table as a stream of blocks: footprints grouped by
//! [`BLOCK_M`] square (at most [`BLOCK_FOOTPRINTS`] a block), each block's ALS points (within the
//! footprint radius) read while the block before is simulated. Memory is bounded by one block,
//! never by the table or the number of footprints. `simulate --dataset`,
//! `run` and the SQL table function `gedi_simulate` read through it.

use crate::dataset::als::{cell_key, AlsTable, BBox};
use crate::dataset::offsets::AppliedOffset;
use crate::dataset::sim::sim_batch;
use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::kernels::sim::{self, AlsPoints, Footprint, SimConfig, Weighting};

/// Side of the square blocks of footprints simulated together in dataset mode (m): a block's
/// points (plus the footprint radius around it) are read at once, so memory is bounded by the
/// block, and the next block is read while one is simulated.
pub const BLOCK_M: f64 = 200.0;

/// The most footprints of a block: a square holding more (a dense plot grid, or a million
/// footprints on one tile) is cut into blocks of this many, in cell order, so that memory holds
/// their waveforms (≈ 70 KB a footprint), never a square's whole.
pub const BLOCK_FOOTPRINTS: usize = 1024;

/// The simulation of footprints against a dataset's `als/` table as a stream of blocks
/// ([`BLOCK_M`] squares of footprints, row-major): each block reads only the points within the
/// footprint radius of its footprints, so memory is bounded by the block, never by the table,
/// and the next block is read while one is simulated.
pub struct BlockSimulation {
    als: AlsTable,
    cfg: SimConfig,
    half: f64,
    blocks: std::vec::IntoIter<Block>,
    current: Option<(Block, Result<AlsPoints>)>,
}

/// The footprints of one block, each with the collocation offset applied to it.
type Block = Vec<(Footprint, Option<AppliedOffset>)>;

impl BlockSimulation {
    /// Prepare the blocks of `footprints` (the first block is read now).
    pub fn new(ds: &Dataset, footprints: Vec<(Footprint, Option<AppliedOffset>)>, cfg: SimConfig) -> Result<Self> {
        let als = AlsTable::open(ds)?;
        let half = sim::footprint::read_radius(cfg.fsigma);
        for (f, _) in &footprints {
            if let Some(file) = als.unread_window(f.x, f.y, half) {
                return Err(Error::file(
                    file,
                    format!(
                        "footprint {} at ({:.1}, {:.1}) lies where this COPC tile was not read (it was read only \
                         around the dataset's shots): ingest it with `gedisim ingest als --whole-tiles`, or simulate \
                         with `--als <tile>.copc.laz`",
                        f.id, f.x, f.y
                    ),
                ));
            }
        }
        let mut blocks = blocks(footprints).into_iter();
        let first = blocks.next();
        let mut this = BlockSimulation { als, cfg, half, blocks, current: None };
        this.current = first.map(|b| {
            let points = this.read(&b);
            (b, points)
        });
        Ok(this)
    }

    /// The points within the footprint radius of `block`'s footprints.
    fn read(&self, block: &[(Footprint, Option<AppliedOffset>)]) -> Result<AlsPoints> {
        let h = self.half;
        let mut b: BBox = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
        for (f, _) in block.iter().filter(|(f, _)| f.x.is_finite() && f.y.is_finite()) {
            b = [b[0].min(f.x - h), b[1].min(f.y - h), b[2].max(f.x + h), b[3].max(f.y + h)];
        }
        if b[0] > b[2] {
            return Ok(AlsPoints::default());
        }
        Ok(self.als.points_in(b)?.0)
    }
}

impl Iterator for BlockSimulation {
    type Item = Result<SimulatedBlock>;

    fn next(&mut self) -> Option<Self::Item> {
        let (block, points) = self.current.take()?;
        let next = self.blocks.next();
        let points = match points {
            Ok(p) => p,
            Err(e) => return Some(Err(e)),
        };
        let (footprints, applied): (Vec<Footprint>, Vec<Option<AppliedOffset>>) = block.into_iter().unzip();
        let this = &*self;
        let (results, ahead) =
            rayon::join(|| sim::simulate(&points, &footprints, &this.cfg), || next.as_ref().map(|b| this.read(b)));
        self.current = next.zip(ahead);
        Some(results.map(|results| SimulatedBlock { footprints, applied, results }).map_err(Into::into))
    }
}

/// One simulated block: its footprints, the offsets applied to them and their outcomes, in the
/// same order.
pub struct SimulatedBlock {
    pub footprints: Vec<Footprint>,
    pub applied: Vec<Option<AppliedOffset>>,
    pub results: Vec<std::result::Result<sim::SimulatedFootprint, sim::SkipReason>>,
}

impl SimulatedBlock {
    /// The block's `sim` rows.
    pub fn batch(&self) -> Result<arrow::record_batch::RecordBatch> {
        sim_batch(&self.footprints, &self.results, &Weighting::STUDY, &self.applied)
    }
}

/// Footprints grouped by [`BLOCK_M`] square, blocks in row-major order, at most
/// [`BLOCK_FOOTPRINTS`] each (footprints without a finite position form blocks of their own,
/// simulated as skipped).
pub fn blocks<T>(mut footprints: Vec<(Footprint, T)>) -> Vec<Vec<(Footprint, T)>> {
    let key = |f: &Footprint| {
        if f.x.is_finite() && f.y.is_finite() {
            Some(((f.y / BLOCK_M).floor() as i64, (f.x / BLOCK_M).floor() as i64))
        } else {
            None
        }
    };
    footprints.sort_by_key(|(f, _)| (key(f), cell_key(f.x, f.y)));
    let mut out: Vec<Vec<(Footprint, T)>> = Vec::new();
    let mut last = None;
    for (f, t) in footprints {
        let k = key(&f);
        if out.last().is_none_or(|b| b.len() >= BLOCK_FOOTPRINTS) || k != last {
            out.push(Vec::new());
            last = k;
        }
        out.last_mut().expect("a block").push((f, t));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_crowded_square_is_cut_into_blocks_of_at_most_block_footprints_in_the_same_order() {
        // 2,500 footprints in one 200 m square, 10 in the next square east, and one without a position.
        let mut fps: Vec<(Footprint, usize)> = (0..2500)
            .map(|i| (Footprint::at(format!("a{i}"), 10.0 + (i % 50) as f64 * 3.0, 10.0 + (i / 50) as f64 * 3.0), i))
            .collect();
        fps.extend((0..10).map(|i| (Footprint::at(format!("b{i}"), 250.0 + i as f64, 50.0), 2500 + i)));
        fps.push((Footprint::at("nowhere", f64::NAN, 0.0), 9999));
        let cut = blocks(fps.clone());
        let sizes: Vec<usize> = cut.iter().map(Vec::len).collect();
        assert_eq!(sizes, vec![1, 1024, 1024, 452, 10]);
        // The order is that of the squares, uncut.
        let mut whole = fps;
        whole.sort_by_key(|(f, _)| {
            let key = f.x.is_finite().then(|| ((f.y / BLOCK_M).floor() as i64, (f.x / BLOCK_M).floor() as i64));
            (key, cell_key(f.x, f.y))
        });
        let order: Vec<usize> = cut.iter().flatten().map(|(_, i)| *i).collect();
        assert_eq!(order, whole.iter().map(|(_, i)| *i).collect::<Vec<_>>());
    }
}
