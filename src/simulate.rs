//! `simulate`: the simulation kernels driven from files — direct mode (one LAS/LAZ file and a
//! footprint CSV) and dataset mode (every ingested shot against the `als/` table).

use std::path::Path;

use arrow::array::{Array, AsArray};
use arrow::datatypes::{Float64Type, UInt64Type};

use crate::als_table::{AlsTable, BBox};
use crate::dataset::{self, tables, AtomicParquet, Dataset};
use crate::error::{Error, Result};
use crate::ingest::als::{cell_key, DROPPED_CLASSES};
use crate::sim::{self, AlsPoints, Footprint, Profile, SimConfig, Weighting};
use crate::tables::offsets::{read_offsets, AppliedOffset};
use crate::tables::sim::{sim_batch, sim_metadata, sim_schema};

/// Footprints simulated together in dataset mode (bounds memory: their points are read at once).
pub const DATASET_BATCH: usize = 256;

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
/// any) on the `als/` table into
/// `<dataset>/sim/shots.parquet`, batch by batch (shots sorted by spatial cell, each batch
/// reading only the row groups its footprints touch). `on_batch(n)` reports progress.
pub fn simulate_dataset(ds: &Dataset, cfg: &SimConfig, profile: Profile, on_batch: &dyn Fn(usize)) -> Result<(usize, usize)> {
    let mut shots = shot_footprints(ds)?;
    shots.sort_by_key(|(f, _)| cell_key(f.x, f.y));
    let als = AlsTable::open(ds)?;
    let half = sim::footprint::gauss_sep(cfg.fsigma, sim::footprint::I_THRESH) as f64 + 1.0;
    let dest = ds.table_file(tables::SIM, "shots")?;
    let mut writer = AtomicParquet::create(&dest, sim_schema(), dataset::writer_properties(&sim_metadata(profile), 1 << 14))?;
    let (mut ok, mut skipped) = (0, 0);
    for chunk in shots.chunks(DATASET_BATCH) {
        let (batch, applied): (Vec<Footprint>, Vec<Option<AppliedOffset>>) = chunk.iter().cloned().unzip();
        let boxes: Vec<BBox> = batch.iter().map(|f| [f.x - half, f.y - half, f.x + half, f.y + half]).collect();
        let (points, _) = als.points_near(&boxes)?;
        let results = sim::simulate(&points, &batch, cfg)?;
        let n_ok = results.iter().filter(|r| r.is_ok()).count();
        ok += n_ok;
        skipped += results.len() - n_ok;
        writer.write(&sim_batch(&batch, &results, &Weighting::ALL, &applied)?)?;
        on_batch(batch.len());
    }
    writer.finish()?;
    Ok((ok, skipped))
}
