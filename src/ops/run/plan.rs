//! Plan (pass A of a granule): the shots' positions and ALS coverage, and whether the granule's
//! simulation and results are current.

use std::collections::HashMap;
use std::path::PathBuf;

use sha2::{Digest, Sha256};

use super::granules::GranuleFile;
use super::{GranuleRun, META_COUNTS, META_INPUT, RUN_FORMAT};
use crate::dataset::als::{tiles_col, AlsTable};
use crate::dataset::offsets::{read_offsets, read_r_after, AppliedOffset};
use crate::dataset::shots::col;
use crate::dataset::{self, read, tables, Dataset};
use crate::error::{Error, Result};
use crate::kernels::sim::{Footprint, Profile, SimConfig};
use crate::kernels::study::select::{FilterCounts, StudyRules, TileWindow};

/// What every granule's planning and results read once.
pub(super) struct StudyInputs {
    pub(super) als: AlsTable,
    pub(super) cfg: SimConfig,
    /// Radius (m) the ALS extents must cover around a footprint centre: 2 σ_f.
    pub(super) cover_radius: f64,
    /// Half-width (m) of the ALS read around a footprint (the simulator's cut-off).
    pub(super) read_radius: f64,
    pub(super) offsets: HashMap<u64, AppliedOffset>,
    pub(super) r_after: HashMap<String, f64>,
    /// Every tile's extent and acquisition window, and its content hash (same order).
    pub(super) tiles: Vec<TileWindow>,
    pub(super) tile_hashes: Vec<String>,
    pub(super) strata: HashMap<u64, String>,
}

impl StudyInputs {
    pub(super) fn read(ds: &Dataset) -> Result<Self> {
        let cfg = SimConfig::new(Profile::Default);
        let (tiles, tile_hashes) = read_tiles(ds)?.into_iter().unzip();
        Ok(StudyInputs {
            als: AlsTable::open(ds)?,
            cover_radius: 2.0 * cfg.fsigma as f64,
            read_radius: crate::kernels::sim::footprint::read_radius(cfg.fsigma),
            cfg,
            offsets: read_offsets(ds)?,
            r_after: read_r_after(ds)?,
            tiles,
            tile_hashes,
            strata: crate::dataset::strata::read_forest_types(ds)?,
        })
    }
}

/// Extent, acquisition window and content hash of every ingested tile.
pub(super) fn read_tiles(ds: &Dataset) -> Result<Vec<(TileWindow, String)>> {
    let dir = ds.root().join(tables::TILES);
    let mut out = Vec::new();
    for path in dataset::table_files(&dir).map_err(|e| Error::file(&dir, e))? {
        read::for_each_batch(&path, None, None, |c| {
            for i in 0..c.num_rows() {
                let w = TileWindow {
                    xmin: c.f64(tiles_col::XMIN, i)?.unwrap_or(f64::NAN),
                    ymin: c.f64(tiles_col::YMIN, i)?.unwrap_or(f64::NAN),
                    xmax: c.f64(tiles_col::XMAX, i)?.unwrap_or(f64::NAN),
                    ymax: c.f64(tiles_col::YMAX, i)?.unwrap_or(f64::NAN),
                    start_us: c.timestamp(tiles_col::ACQUISITION_START, i)?,
                    end_us: c.timestamp(tiles_col::ACQUISITION_END, i)?,
                };
                out.push((w, c.string(tiles_col::CONTENT_HASH, i)?.unwrap_or_default()));
            }
            Ok(())
        })?;
    }
    Ok(out)
}

/// A shot whose footprint the ALS covers: simulated at its collocated position.
#[derive(Debug, Clone)]
pub(super) struct CoveredShot {
    /// Row in its `shots/` file.
    pub(super) row: usize,
    pub(super) footprint: Footprint,
    pub(super) offset: Option<AppliedOffset>,
}

/// One granule after planning.
pub(super) struct GranulePlan {
    pub(super) file: GranuleFile,
    pub(super) covered: Vec<CoveredShot>,
    pub(super) sim_path: PathBuf,
    pub(super) results_path: PathBuf,
    pub(super) sim_input: String,
    pub(super) results_input: String,
    pub(super) needs_sim: bool,
    pub(super) needs_results: bool,
    pub(super) run: GranuleRun,
}

/// Pass A of a granule: positions, coverage, and whether its simulation and results are current.
pub(super) fn plan_granule(
    ds: &Dataset,
    file: GranuleFile,
    inputs: &StudyInputs,
    rules: &StudyRules,
) -> Result<GranulePlan> {
    let mut covered = Vec::new();
    let mut n = 0;
    read::for_each_batch(&file.path, Some(&[col::SHOT_NUMBER, col::X, col::Y]), None, |c| {
        for i in 0..c.num_rows() {
            let row = n + i;
            let Some(sn) = c.u64(col::SHOT_NUMBER, i)? else { continue };
            let (Some(x), Some(y)) = (c.f64(col::X, i)?, c.f64(col::Y, i)?) else { continue };
            let offset = inputs.offsets.get(&sn).cloned();
            let (dx, dy) = offset.as_ref().map_or((0.0, 0.0), |o| (o.dx, o.dy));
            let (x, y) = (x + dx, y + dy);
            // Where a COPC tile was read only in windows, its points must all have been read.
            let als = &inputs.als;
            if als.covers(x, y, inputs.cover_radius) && als.unread_window(x, y, inputs.read_radius).is_none() {
                covered.push(CoveredShot { row, footprint: Footprint::at(sn.to_string(), x, y), offset });
            }
        }
        n += c.num_rows();
        Ok(())
    })?;
    // What the simulation depends on: the granule's content, the simulated positions and
    // offsets, the tiles under them, the simulator.
    let mut h = Sha256::new();
    let mut line = |s: String| {
        h.update(s.as_bytes());
        h.update(b"\n");
    };
    line(format!("{RUN_FORMAT} sim {} {:?}", file.inputs, inputs.cfg));
    let r = inputs.read_radius;
    let mut tiles: Vec<&str> = inputs
        .tiles
        .iter()
        .zip(&inputs.tile_hashes)
        .filter(|(t, _)| {
            covered.iter().any(|c| {
                c.footprint.x + r >= t.xmin
                    && c.footprint.x - r <= t.xmax
                    && c.footprint.y + r >= t.ymin
                    && c.footprint.y - r <= t.ymax
            })
        })
        .map(|(_, hash)| hash.as_str())
        .collect();
    tiles.sort_unstable();
    line(format!("tiles {}", tiles.join(",")));
    for c in &covered {
        let o = c.offset.as_ref().map_or("-".to_string(), |o| format!("{} {:?}", o.segment_id, o.dz.to_bits()));
        line(format!("{} {} {} {o}", c.footprint.id, c.footprint.x.to_bits(), c.footprint.y.to_bits()));
    }
    let sim_input = hex::encode(h.finalize());
    // What the results add: strata, collocation quality, the filters' bounds.
    let mut h = Sha256::new();
    h.update(format!("{RUN_FORMAT} results {sim_input} {rules:?}\n").as_bytes());
    for c in &covered {
        let sn: u64 = c.footprint.id.parse().unwrap_or_default();
        let forest = inputs.strata.get(&sn).map_or("-", String::as_str);
        let r = c.offset.as_ref().and_then(|o| inputs.r_after.get(&o.segment_id)).map_or(0, |r| r.to_bits());
        h.update(format!("{sn} {forest} {r}\n").as_bytes());
    }
    let results_input = hex::encode(h.finalize());

    let sim_path = ds.table_file(tables::SIM, &file.key)?;
    let results_path = ds.table_file(tables::RESULTS, &file.key)?;
    let sim_meta = read::key_value_metadata(&sim_path);
    let needs_sim = !covered.is_empty() && sim_meta.as_ref().and_then(|m| m.get(META_INPUT)) != Some(&sim_input);
    if covered.is_empty() && sim_meta.is_some_and(|m| m.contains_key(META_INPUT)) {
        // This run's own simulation of shots no longer covered: stale.
        std::fs::remove_file(&sim_path)
            .map_err(|e| Error::file(&sim_path, format!("cannot remove a stale simulation: {e}")))?;
    }
    let results_meta = read::key_value_metadata(&results_path);
    let previous = results_meta
        .filter(|m| m.get(META_INPUT) == Some(&results_input))
        .and_then(|m| FilterCounts::from_json(&serde_json::from_str(m.get(META_COUNTS)?).ok()?));
    let needs_results = needs_sim || previous.is_none();
    let run = GranuleRun {
        key: file.key.clone(),
        granule: file.name.clone(),
        shots: n,
        covered: covered.len(),
        simulated: None,
        results_written: false,
        counts: previous.unwrap_or_default(),
    };
    Ok(GranulePlan { file, covered, sim_path, results_path, sim_input, results_input, needs_sim, needs_results, run })
}
