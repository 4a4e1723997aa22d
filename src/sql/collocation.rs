//! The collocation kernel ([`crate::kernels::collocate`]) driven from a dataset: the shots of `shots/`,
//! the points of `als/`, into offset rows (`crate::ops::collocate` writes them to
//! `<dataset>/offsets/offsets.parquet`; on a cluster, `crate::sql::collocate` runs a granule per partition).
//!
//! Per granule file of `shots/`: (A) the cheap columns of every shot are read and each shot is
//! classified (waveform, position, geoid offset, stale flag, ALS coverage from the row-group
//! extents of `als/`); the segments of the chosen level are planned from that. (B) Unit by unit
//! (a segment, or at the shot level a block of consecutive shots), the waveforms of its shots are
//! read (those rows only), and the kernel asks for the ALS points of sub-batches of 16 shots
//! (only x, y, z of the row groups their search squares meet). Memory is bounded by a unit, never
//! by the tiles or the granule. Granules are independent: solving them together or one at a time gives
//! the same rows.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow::array::{Array, AsArray};
use arrow::datatypes::{Float64Type, UInt32Type, UInt64Type, UInt8Type};
use parquet::arrow::ProjectionMask;
use serde::{Deserialize, Serialize};

use crate::dataset::als::{AlsTable, BBox};
use crate::dataset::offsets::OffsetRow;
use crate::dataset::shots::col;
use crate::dataset::{self, tables, Dataset};
use crate::error::{Error, Result};
use crate::kernels::collocate::profile::{real_profile, ProfileError};
use crate::kernels::collocate::segments::{plan, Level, SegmentPlan, Slot, MIN_SEGMENT};
use crate::kernels::collocate::{collocate_unit, CollocateConfig, PointCloud, ShotInput};
use crate::kernels::sim::{PulseModel, PulseReference};

/// Options of `gedisim collocate`.
#[derive(Debug, Clone, PartialEq)]
pub struct CollocateOptions {
    /// Level at which offsets are solved.
    pub level: Level,
    /// Longest segment (shots at the beam level, along-track steps at the granule level).
    pub segment: usize,
    /// Largest horizontal shift searched (m).
    pub max_shift: f64,
    /// Horizontal grid step (m).
    pub step: f64,
    /// Fewest shots (beam) or steps (granule) of a segment ([`MIN_SEGMENT`] by default); a
    /// shorter run is reported and not solved. 1 solves every run, however short.
    pub min_segment: usize,
    /// The pulse the ALS waveforms are simulated with: by default each shot's recorded pulse, so
    /// that the vertical offset refers to the pulse's reference point, not its peak (docs/pulse.md).
    pub pulse: PulseModel,
}

impl Default for CollocateOptions {
    fn default() -> Self {
        CollocateOptions {
            level: Level::Beam,
            segment: 40,
            max_shift: 10.0,
            step: 1.0,
            min_segment: MIN_SEGMENT,
            pulse: PulseModel::Recorded(PulseReference::default()),
        }
    }
}

/// What a collocation did.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CollocateReport {
    /// Shots read.
    pub shots: usize,
    /// Rows written.
    pub segments: usize,
    /// Shots not used, by reason (`no_als`, `no_waveform`, `partly_covered`, …).
    pub skipped: BTreeMap<String, usize>,
    /// Runs too short to be solved: `<granule>:<beam>: <n> shots from <first shot>`.
    pub short_runs: Vec<String>,
    /// The table written.
    pub table: PathBuf,
    /// ALS points read (x, y, z) and kept inside the shots' search squares.
    pub als_points_read: u64,
    /// ALS row groups decoded (a row group read for two sub-batches counts twice).
    pub als_row_groups_read: u64,
}

impl CollocateReport {
    /// Adds what the collocation of other granules did (`table` is kept).
    pub fn merge(&mut self, other: CollocateReport) {
        self.shots += other.shots;
        self.segments += other.segments;
        for (reason, n) in other.skipped {
            *self.skipped.entry(reason).or_default() += n;
        }
        self.short_runs.extend(other.short_runs);
        self.als_points_read += other.als_points_read;
        self.als_row_groups_read += other.als_row_groups_read;
    }
}

/// The cheap columns of one shot (pass A).
#[derive(Debug, Clone)]
struct ShotRecord {
    row: usize,
    shot_number: u64,
    beam: String,
    delta_time: Option<f64>,
    x: f64,
    y: f64,
    z_top: f64,
    z_bottom: f64,
    geoid: f64,
    /// Why the shot cannot be used, if so.
    skip: Option<&'static str>,
    covered: bool,
}

/// One granule file of `shots/` after pass A.
struct GranulePlan {
    path: PathBuf,
    granule: String,
    shots: Vec<ShotRecord>,
    units: Vec<Unit>,
}

/// Plans solved together (their shots read at once).
struct Unit {
    /// Beam of the unit's segments (`ALL` at the granule level).
    beam: String,
    plans: Vec<SegmentPlan>,
}

/// A planned collocation: pass A done for every granule.
pub struct Collocation {
    opts: CollocateOptions,
    cfg: CollocateConfig,
    als: AlsTable,
    granules: Vec<GranulePlan>,
    report: CollocateReport,
}

/// Shot-level plans solved together.
const SHOT_UNIT: usize = 64;

impl Collocation {
    /// Reads the shots' cheap columns and plans the segments (pass A).
    pub fn plan(ds: &Dataset, opts: &CollocateOptions) -> Result<Collocation> {
        Self::plan_some(ds, opts, None)
    }

    /// [`plan`](Self::plan) restricted to some files of `shots/` (one granule each): what `run`
    /// uses to collocate only the granules that arrived since the last run.
    pub fn plan_files(ds: &Dataset, opts: &CollocateOptions, files: Vec<PathBuf>) -> Result<Collocation> {
        Self::plan_some(ds, opts, Some(files))
    }

    /// The given files of `shots/`, or all of them.
    fn plan_some(ds: &Dataset, opts: &CollocateOptions, files: Option<Vec<PathBuf>>) -> Result<Collocation> {
        if opts.segment == 0 {
            return Err(Error::Usage("--segment must be at least 1".into()));
        }
        let mut cfg = CollocateConfig::new(opts.max_shift, opts.step)?;
        if let Some(p) = crate::io::pulse::fixed_pulse(&opts.pulse, cfg.model.res)? {
            cfg.model.pulse = p;
        }
        cfg.validate()?;
        let als = AlsTable::open(ds)?;
        let files = match files {
            Some(f) => f,
            None => {
                let dir = ds.root().join(tables::SHOTS);
                dataset::table_files(&dir)
                    .map_err(|e| Error::file(&dir, format!("no shots table ({e}): run `gedisim ingest gedi`")))?
            }
        };
        let mut report =
            CollocateReport { table: ds.root().join(tables::OFFSETS).join("offsets.parquet"), ..Default::default() };
        let mut granules = Vec::new();
        for path in files {
            let (granule, mut shots) = read_shot_records(&path)?;
            report.shots += shots.len();
            for s in &mut shots {
                // Where a COPC tile was read only in windows, the search's points must all be there.
                s.covered = s.x.is_finite()
                    && s.y.is_finite()
                    && als.covers(s.x, s.y, cfg.model.fsigma as f64)
                    && als.unread_window(s.x, s.y, cfg.support_half_width()).is_none();
                if s.skip.is_none() && !s.covered {
                    s.skip = Some("no_als");
                }
                if let Some(r) = s.skip {
                    *report.skipped.entry(r.to_string()).or_default() += 1;
                }
            }
            let units = plan_units(&granule, &shots, opts, &mut report.short_runs);
            granules.push(GranulePlan { path, granule, shots, units });
        }
        Ok(Collocation { opts: opts.clone(), cfg, als, granules, report })
    }

    /// The granule files planned (files of `shots/`).
    pub fn files(&self) -> Vec<PathBuf> {
        self.granules.iter().map(|g| g.path.clone()).collect()
    }

    /// Shots whose waveforms will be correlated (the progress total).
    pub fn shots_to_process(&self) -> usize {
        self.granules.iter().flat_map(|g| &g.units).map(|u| support_of(&u.plans).len()).sum()
    }

    /// Solves every unit (pass B): the rows, granule after granule, and the report (whose `table` is
    /// `offsets/offsets.parquet`, where they are written); `on_shot` is called once per shot correlated.
    pub fn solve(mut self, on_shot: &(dyn Fn() + Sync)) -> Result<(Vec<OffsetRow>, CollocateReport)> {
        let mut rows = Vec::new();
        let mut skipped = std::mem::take(&mut self.report.skipped);
        let mut read = (0u64, 0u64);
        for g in &self.granules {
            for unit in &g.units {
                rows.extend(self.solve_unit(g, unit, &mut skipped, &mut read, on_shot)?);
            }
        }
        self.report.skipped = skipped;
        (self.report.als_points_read, self.report.als_row_groups_read) = read;
        self.report.segments = rows.len();
        Ok((rows, self.report))
    }

    fn solve_unit(
        &self,
        g: &GranulePlan,
        unit: &Unit,
        skipped: &mut BTreeMap<String, usize>,
        read: &mut (u64, u64),
        on_shot: &(dyn Fn() + Sync),
    ) -> Result<Vec<OffsetRow>> {
        let mut skip = |reason: &str| *skipped.entry(reason.to_string()).or_default() += 1;
        let support = support_of(&unit.plans);
        let recorded = match self.opts.pulse {
            PulseModel::Recorded(r) => Some(r),
            _ => None,
        };
        let waves = read_waveforms(&g.path, support.iter().map(|&i| g.shots[i].row), recorded.is_some())?;
        // The shots whose real waveform is usable, in the kernel's numbering.
        let mut inputs = Vec::new();
        let mut kernel_index = vec![None; g.shots.len()];
        for (&i, (wave, tx)) in support.iter().zip(waves) {
            let s = &g.shots[i];
            // A shot without a usable transmit record keeps the Gaussian pulse.
            let pulse = recorded
                .zip(tx)
                .and_then(|(r, tx)| crate::sql::pulses::recorded_pulse(&tx, r, self.cfg.model.res))
                .map(Arc::new);
            let Some(wave) = wave else {
                skip("no_waveform");
                continue;
            };
            match real_profile(&wave, s.z_top - s.geoid, s.z_bottom - s.geoid, self.cfg.model.res) {
                Ok(real) => {
                    kernel_index[i] = Some(inputs.len());
                    inputs.push((i, ShotInput { x: s.x, y: s.y, real, pulse }));
                }
                Err(e) => skip(match e {
                    ProfileError::BadGeometry => "bad_waveform_geometry",
                    ProfileError::TooShort => "record_too_short",
                    ProfileError::NonFinite => "non_finite_waveform",
                    ProfileError::NoSignal => "no_signal",
                }),
            }
        }
        let plans: Vec<SegmentPlan> = unit
            .plans
            .iter()
            .map(|p| SegmentPlan {
                support: p.support.iter().filter_map(|&i| kernel_index[i]).collect(),
                applies_to: p.applies_to.iter().filter_map(|&i| kernel_index[i]).collect(),
            })
            .collect();
        let shots: Vec<ShotInput> = inputs.iter().map(|(_, s)| s.clone()).collect();
        let half = self.cfg.support_half_width();
        let als = &self.als;
        let mut points_for = |idx: &[usize]| -> Result<PointCloud> {
            let boxes: Vec<BBox> = idx
                .iter()
                .map(|&k| [shots[k].x - half, shots[k].y - half, shots[k].x + half, shots[k].y + half])
                .collect();
            let (cloud, stats) = als.xyz_in_boxes(&boxes)?;
            read.0 += cloud.len() as u64;
            read.1 += stats.row_groups_read as u64;
            Ok(cloud)
        };
        let (solutions, skips) = collocate_unit(&shots, &plans, &self.cfg, &mut points_for, on_shot)?;
        for s in skips.iter().flatten() {
            skip(s.reason());
        }
        let mut rows = Vec::new();
        for (p, sol) in plans.iter().zip(solutions) {
            let Some(sol) = sol else { continue };
            let record = |k: usize| &g.shots[inputs[k].0];
            let applies: Vec<usize> = match self.opts.level {
                Level::Shot => p.applies_to.clone(),
                _ => sol.used.clone(),
            };
            if applies.is_empty() || (self.opts.level == Level::Shot && !sol.used.contains(&applies[0])) {
                continue;
            }
            let shot_numbers: Vec<u64> = applies.iter().map(|&k| record(k).shot_number).collect();
            let geoid = sol.used.iter().map(|&k| record(k).geoid).sum::<f64>() / sol.used.len() as f64;
            let o = sol.optimum;
            rows.push(OffsetRow {
                segment_id: format!("{}:{}:{}", g.granule, unit.beam, shot_numbers[0]),
                granule: g.granule.clone(),
                beam: unit.beam.clone(),
                level: self.opts.level.name().to_string(),
                shot_numbers,
                n_shots: sol.used.len() as u32,
                dx: o.dx,
                dy: o.dy,
                dz: o.dz,
                geoid_offset: geoid,
                r_before: sol.r_before,
                r_after: o.r,
                dx_halfwidth: o.dx_halfwidth,
                dy_halfwidth: o.dy_halfwidth,
                dz_halfwidth: o.dz_halfwidth,
            });
        }
        Ok(rows)
    }
}

/// Sorted union of the plans' supports.
fn support_of(plans: &[SegmentPlan]) -> Vec<usize> {
    let mut s: Vec<usize> = plans.iter().flat_map(|p| p.support.iter().copied()).collect();
    s.sort_unstable();
    s.dedup();
    s
}

/// The units of one granule at the chosen level; short runs are described in `short`.
fn plan_units(granule: &str, shots: &[ShotRecord], opts: &CollocateOptions, short: &mut Vec<String>) -> Vec<Unit> {
    let mut beams: BTreeMap<&str, Vec<usize>> = BTreeMap::new();
    for (i, s) in shots.iter().enumerate() {
        beams.entry(s.beam.as_str()).or_default().push(i);
    }
    for v in beams.values_mut() {
        v.sort_by_key(|&i| shots[i].shot_number);
    }
    let slot = |i: usize, step: i64| Slot {
        step,
        covered: shots[i].covered,
        usable: shots[i].covered && shots[i].skip.is_none(),
    };
    // (beam label, shots in slot order, slots)
    let groups: Vec<(String, Vec<usize>, Vec<Slot>)> = match opts.level {
        Level::Beam | Level::Shot => beams
            .iter()
            .map(|(b, idx)| {
                (b.to_string(), idx.clone(), idx.iter().enumerate().map(|(k, &i)| slot(i, k as i64)).collect())
            })
            .collect(),
        Level::Granule => {
            let steps = along_track_steps(shots, &beams);
            let mut order: Vec<usize> = (0..shots.len()).collect();
            order.sort_by_key(|&i| (steps[i], shots[i].shot_number));
            let slots = order.iter().map(|&i| slot(i, steps[i])).collect();
            vec![("ALL".to_string(), order, slots)]
        }
    };
    let mut units = Vec::new();
    for (beam, idx, slots) in groups {
        let (plans, runs) = plan(&slots, opts.level, opts.segment, opts.min_segment);
        for r in runs {
            let first = shots[idx[r.shots[0]]].shot_number;
            short.push(format!("{granule}:{beam}: {} usable shots from shot {first}", r.shots.len()));
        }
        let plans: Vec<SegmentPlan> = plans
            .into_iter()
            .map(|p| SegmentPlan {
                support: p.support.iter().map(|&k| idx[k]).collect(),
                applies_to: p.applies_to.iter().map(|&k| idx[k]).collect(),
            })
            .collect();
        match opts.level {
            Level::Shot => {
                for chunk in plans.chunks(SHOT_UNIT) {
                    units.push(Unit { beam: beam.clone(), plans: chunk.to_vec() });
                }
            }
            _ => units.extend(plans.into_iter().map(|p| Unit { beam: beam.clone(), plans: vec![p] })),
        }
    }
    units
}

/// Along-track step of every shot: shots of all beams fired together share a step. From
/// `delta_time` and the median interval between consecutive shots of a beam; the rank within the
/// beam when times are missing.
fn along_track_steps(shots: &[ShotRecord], beams: &BTreeMap<&str, Vec<usize>>) -> Vec<i64> {
    let mut gaps: Vec<f64> = Vec::new();
    for idx in beams.values() {
        for w in idx.windows(2) {
            if let (Some(a), Some(b)) = (shots[w[0]].delta_time, shots[w[1]].delta_time) {
                if b > a {
                    gaps.push(b - a);
                }
            }
        }
    }
    gaps.sort_by(f64::total_cmp);
    let interval = gaps.get(gaps.len() / 2).copied();
    let t0 = shots.iter().filter_map(|s| s.delta_time).fold(f64::INFINITY, f64::min);
    let mut steps = vec![0i64; shots.len()];
    for idx in beams.values() {
        for (k, &i) in idx.iter().enumerate() {
            steps[i] = match (interval, shots[i].delta_time) {
                (Some(dt), Some(t)) => ((t - t0) / dt).round() as i64,
                _ => k as i64,
            };
        }
    }
    steps
}

/// Pass A: the cheap columns of every shot of one `shots/` file, classified.
fn read_shot_records(path: &Path) -> Result<(String, Vec<ShotRecord>)> {
    let builder = crate::dataset::read::open(path)?;
    let schema = builder.schema().clone();
    for required in [
        col::SHOT_NUMBER,
        col::X,
        col::Y,
        col::RX_WAVEFORM,
        col::ELEVATION_BIN0,
        col::ELEVATION_LASTBIN,
        col::GEOID_OFFSET_USED,
    ] {
        if schema.field_with_name(required).is_err() {
            return Err(Error::field(
                path,
                required,
                "column missing from the shots table (collocate needs ingested L1B waveforms)",
            ));
        }
    }
    let wanted: Vec<&str> = [
        col::SHOT_NUMBER,
        col::X,
        col::Y,
        col::GRANULE,
        col::BEAM,
        col::DELTA_TIME,
        col::ELEVATION_BIN0,
        col::ELEVATION_LASTBIN,
        col::GEOID_OFFSET_USED,
        col::GEOID,
        col::RX_SAMPLE_COUNT,
        col::STALE_RETURN_FLAG,
    ]
    .into_iter()
    .filter(|c| schema.field_with_name(c).is_ok())
    .collect();
    let mask = ProjectionMask::columns(builder.parquet_schema(), wanted.iter().copied());
    let reader = builder.with_projection(mask).build().map_err(|e| Error::table(path, e))?;
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let mut granule = None;
    let mut out = Vec::new();
    for b in reader {
        let b = b.map_err(|e| Error::table(path, e))?;
        let f64s = |n: &str| -> Result<Option<arrow::array::Float64Array>> {
            match b.column_by_name(n) {
                None => Ok(None),
                Some(c) => c
                    .as_primitive_opt::<Float64Type>()
                    .cloned()
                    .map(Some)
                    .ok_or_else(|| Error::field(path, n, "not float64")),
            }
        };
        let sn = b
            .column_by_name(col::SHOT_NUMBER)
            .and_then(|c| c.as_primitive_opt::<UInt64Type>().cloned())
            .ok_or_else(|| Error::field(path, col::SHOT_NUMBER, "not uint64"))?;
        let (x, y, dt) = (f64s(col::X)?, f64s(col::Y)?, f64s(col::DELTA_TIME)?);
        let (e0, e1) = (f64s(col::ELEVATION_BIN0)?, f64s(col::ELEVATION_LASTBIN)?);
        // The table's one geoid policy (`ShotColumns::geoid_offset`): the offset ingest applied, else `geoid`.
        let (geoid_used, geoid) = (f64s(col::GEOID_OFFSET_USED)?, f64s(col::GEOID)?);
        let count = b.column_by_name(col::RX_SAMPLE_COUNT).and_then(|c| c.as_primitive_opt::<UInt32Type>().cloned());
        let stale = b.column_by_name(col::STALE_RETURN_FLAG).and_then(|c| c.as_primitive_opt::<UInt8Type>().cloned());
        let beams = b.column_by_name(col::BEAM).and_then(|c| c.as_string_opt::<i32>().cloned());
        if granule.is_none() {
            granule = b.column_by_name(col::GRANULE).and_then(|c| {
                c.as_string_opt::<i32>().filter(|a| !a.is_empty() && a.is_valid(0)).map(|a| a.value(0).to_string())
            });
        }
        let get = |a: &Option<arrow::array::Float64Array>, i: usize| {
            a.as_ref().filter(|a| a.is_valid(i)).map(|a| a.value(i)).filter(|v| v.is_finite())
        };
        for i in 0..b.num_rows() {
            let (px, py) = (get(&x, i), get(&y, i));
            let (z_top, z_bottom) = (get(&e0, i), get(&e1, i));
            let n = get(&geoid_used, i).or(get(&geoid, i));
            let has_wave = count.as_ref().is_none_or(|c| c.is_valid(i) && c.value(i) >= 2);
            let skip = if px.is_none() || py.is_none() {
                Some("no_position")
            } else if !has_wave || z_top.is_none() || z_bottom.is_none() {
                Some("no_waveform")
            } else if n.is_none() {
                Some("no_geoid_offset")
            } else if stale.as_ref().is_some_and(|s| s.is_valid(i) && s.value(i) == 1) {
                Some("stale_return")
            } else {
                None
            };
            out.push(ShotRecord {
                row: out.len(),
                shot_number: sn.value(i),
                beam: beams
                    .as_ref()
                    .filter(|a| a.is_valid(i))
                    .map_or_else(|| "ALL".to_string(), |a| a.value(i).to_string()),
                delta_time: get(&dt, i),
                x: px.unwrap_or(f64::NAN),
                y: py.unwrap_or(f64::NAN),
                z_top: z_top.unwrap_or(f64::NAN),
                z_bottom: z_bottom.unwrap_or(f64::NAN),
                geoid: n.unwrap_or(f64::NAN),
                skip,
                covered: false,
            });
        }
    }
    Ok((granule.unwrap_or(stem), out))
}

/// Pass B: `rx_waveform` (and `tx_waveform` when `with_tx`) of the given rows (ascending) of one
/// `shots/` file; `None` for a null.
#[allow(clippy::type_complexity)]
fn read_waveforms(
    path: &Path,
    rows: impl Iterator<Item = usize>,
    with_tx: bool,
) -> Result<Vec<(Option<Vec<f32>>, Option<Vec<f32>>)>> {
    let rows: Vec<usize> = rows.collect();
    if rows.is_empty() {
        return Ok(Vec::new());
    }
    let mut out = Vec::with_capacity(rows.len());
    let columns: &[&str] = if with_tx { &[col::RX_WAVEFORM, col::TX_WAVEFORM] } else { &[col::RX_WAVEFORM] };
    crate::dataset::read::for_each_batch(path, Some(columns), Some(&rows), |c| {
        for i in 0..c.num_rows() {
            let tx = if with_tx { c.f32_list(col::TX_WAVEFORM, i)? } else { None };
            out.push((c.f32_list(col::RX_WAVEFORM, i)?, tx));
        }
        Ok(())
    })?;
    if out.len() != rows.len() {
        return Err(Error::field(
            path,
            col::RX_WAVEFORM,
            format!("read {} waveforms for {} rows", out.len(), rows.len()),
        ));
    }
    Ok(out)
}
