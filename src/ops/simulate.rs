//! `simulate`: the simulation kernels driven from files — direct mode (one LAS/LAZ file and a
//! footprint CSV) and dataset mode (every ingested shot against the `als/` table).

use std::collections::HashMap;
use std::path::Path;

use arrow::array::{Array, AsArray};
use arrow::datatypes::{Float64Type, UInt64Type};

use crate::dataset::als::{AlsTable, BBox};
use crate::dataset::{self, tables, AtomicParquet, Dataset};
use crate::error::{Error, Result};
use crate::ops::ingest_als::{cell_key, DROPPED_CLASSES};
use crate::kernels::sim::{self, AlsPoints, Footprint, Profile, SimConfig, Weighting};
use crate::dataset::offsets::{read_offsets, AppliedOffset};
use crate::dataset::sim::{sim_batch, sim_metadata, sim_schema};

/// Side of the square blocks of footprints simulated together in dataset mode (m): a block's
/// points (plus the footprint radius around it) are read at once, so memory is bounded by the
/// block, and the next block is read while one is simulated.
pub const BLOCK_M: f64 = 200.0;

/// Keep only the points whose class the ingest keeps (so that direct mode with the `default`
/// profile sees the same points as the dataset path).
pub fn drop_ingest_classes(p: &AlsPoints) -> AlsPoints {
    let keep: Vec<u32> = (0..p.len() as u32).filter(|&i| !DROPPED_CLASSES.contains(&p.classification[i as usize])).collect();
    p.permuted(&keep)
}

/// Direct mode: simulate `footprints` on `points` and write the `sim` rows to `out` (atomically).
/// Returns the number of footprints simulated and skipped.
pub fn simulate_direct(points: &AlsPoints, footprints: &[Footprint], cfg: &SimConfig, profile: Profile, out: &Path) -> Result<(usize, usize)> {
    let results = sim::simulate(points, footprints, cfg)?;
    let ok = results.iter().filter(|r| r.is_ok()).count();
    let batch = sim_batch(footprints, &results, &Weighting::ALL, &[])?;
    dataset::write_parquet(out, sim_schema(), &[batch], &sim_metadata(profile))?;
    Ok((ok, results.len() - ok))
}

/// The shots' ids and positions (`shot_number`, `x`, `y`) from the `shots/` table, each moved by
/// its collocation offset when `<dataset>/offsets/` has one (position + (dx, dy)), with the
/// offset applied.
pub fn shot_footprints(ds: &Dataset) -> Result<Vec<(Footprint, Option<AppliedOffset>)>> {
    let offsets = read_offsets(ds)?;
    let dir = ds.root().join(tables::SHOTS);
    let files = dataset::table_files(&dir).map_err(|e| Error::file(&dir, format!("no shots table ({e}): run `gedisim ingest gedi`")))?;
    let mut out = Vec::new();
    for f in files {
        let file = std::fs::File::open(&f).map_err(|e| Error::file(&f, e))?;
        let builder = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file).map_err(|e| Error::table(&f, e))?;
        let mask = parquet::arrow::ProjectionMask::columns(builder.parquet_schema(), ["shot_number", "x", "y"]);
        let reader = builder.with_projection(mask).build().map_err(|e| Error::table(&f, e))?;
        for b in reader {
            let b = b.map_err(|e| Error::table(&f, e))?;
            let get = |n: &str| b.column_by_name(n).ok_or_else(|| Error::field(&f, n, "column missing from the shots table"));
            let (sn, x, y) = (get("shot_number")?, get("x")?, get("y")?);
            let (sn, x, y) = (sn.as_primitive::<UInt64Type>(), x.as_primitive::<Float64Type>(), y.as_primitive::<Float64Type>());
            for i in 0..b.num_rows() {
                if x.is_null(i) || y.is_null(i) {
                    continue;
                }
                let off = offsets.get(&sn.value(i)).cloned();
                let (dx, dy) = off.as_ref().map_or((0.0, 0.0), |o| (o.dx, o.dy));
                out.push((Footprint { id: sn.value(i).to_string(), x: x.value(i) + dx, y: y.value(i) + dy }, off));
            }
        }
    }
    Ok(out)
}

/// Dataset mode: simulate every shot of `<dataset>/shots/` (moved by its collocation offset, if
/// any) on the `als/` table into `<dataset>/sim/shots.parquet`. `on_batch(n)` reports progress.
pub fn simulate_dataset(ds: &Dataset, cfg: &SimConfig, profile: Profile, on_batch: &dyn Fn(usize)) -> Result<(usize, usize)> {
    let shots = shot_footprints(ds)?;
    let dest = ds.table_file(tables::SIM, "shots")?;
    simulate_on_dataset(ds, shots, cfg, profile, &dest, on_batch)
}

/// Simulate `footprints` (each with the collocation offset already applied to it, if any) on the
/// dataset's `als/` table into `dest` (atomically), block by block (see [`BlockSimulation`]).
/// `on_batch(n)` reports progress.
pub fn simulate_on_dataset(
    ds: &Dataset,
    footprints: Vec<(Footprint, Option<AppliedOffset>)>,
    cfg: &SimConfig,
    profile: Profile,
    dest: &Path,
    on_batch: &dyn Fn(usize),
) -> Result<(usize, usize)> {
    simulate_on_dataset_with(ds, footprints, cfg, profile, dest, &HashMap::new(), on_batch)
}

/// [`simulate_on_dataset`] with `extra` key-value metadata in the written file (beside the
/// profile and bin-label keys): `run` records there what the file was made from.
pub fn simulate_on_dataset_with(
    ds: &Dataset,
    footprints: Vec<(Footprint, Option<AppliedOffset>)>,
    cfg: &SimConfig,
    profile: Profile,
    dest: &Path,
    extra: &HashMap<String, String>,
    on_batch: &dyn Fn(usize),
) -> Result<(usize, usize)> {
    let mut metadata = sim_metadata(profile);
    metadata.extend(extra.iter().map(|(k, v)| (k.clone(), v.clone())));
    let mut writer = AtomicParquet::create(dest, sim_schema(), dataset::writer_properties(&metadata, 1 << 14))?;
    let (mut ok, mut skipped) = (0, 0);
    for block in BlockSimulation::new(ds, footprints, cfg.clone())? {
        let block = block?;
        let n_ok = block.results.iter().filter(|r| r.is_ok()).count();
        ok += n_ok;
        skipped += block.results.len() - n_ok;
        writer.write(&block.batch()?)?;
        on_batch(block.footprints.len());
    }
    writer.finish()?;
    Ok((ok, skipped))
}

/// The simulation of footprints against a dataset's `als/` table as a stream of blocks
/// ([`BLOCK_M`] squares of footprints, row-major): each block reads only the points within the
/// footprint radius of its footprints, so memory is bounded by the block, never by the table,
/// and the next block is read while one is simulated.
pub struct BlockSimulation {
    als: AlsTable,
    cfg: SimConfig,
    half: f64,
    blocks: std::vec::IntoIter<Vec<(Footprint, Option<AppliedOffset>)>>,
    current: Option<(Vec<(Footprint, Option<AppliedOffset>)>, Result<AlsPoints>)>,
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
        sim_batch(&self.footprints, &self.results, &Weighting::ALL, &self.applied)
    }
}

impl BlockSimulation {
    /// Prepare the blocks of `footprints` (the first block is read now).
    pub fn new(ds: &Dataset, footprints: Vec<(Footprint, Option<AppliedOffset>)>, cfg: SimConfig) -> Result<Self> {
        let als = AlsTable::open(ds)?;
        let half = sim::footprint::gauss_sep(cfg.fsigma, sim::footprint::I_THRESH) as f64 + 1.0;
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
        Some(results.map(|results| SimulatedBlock { footprints, applied, results }))
    }
}

/// Footprints grouped by [`BLOCK_M`] square, blocks in row-major order (footprints without a
/// finite position form a block of their own, simulated as skipped).
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
        if out.is_empty() || k != last {
            out.push(Vec::new());
            last = k;
        }
        out.last_mut().expect("a block").push((f, t));
    }
    out
}
