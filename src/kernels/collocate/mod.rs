//! Collocation: the 3-D geolocation offset of GEDI shots against ALS, as a pure kernel (no I/O).
//!
//! For a set of shots sharing one offset, find the horizontal offset (dx, dy) on a grid of
//! ±`max_shift` m at `step` m and the vertical offset dz that maximise the mean Pearson
//! correlation between each real waveform (denoised as collocateWaves does) and the waveform
//! simulated from the ALS at the shifted position (count weighting). Unlike the reference, which
//! re-simulates every footprint at every grid node (docs/simulator-reference.md §3):
//! * all horizontal offsets of a shot come from one pass over its points ([`raster`]: the
//!   footprint Gaussian is separable, the pulse convolution linear);
//! * the vertical offset is solved by cross-correlation along z ([`correlation`]), after a coarse
//!   full-range search at zero horizontal offset, so a datum gap of tens of metres costs nothing;
//! * the segment's mean r over offsets × lags ([`surface`]) gives the optimum (parabolic
//!   sub-node refinement) and the half-extents of the region within 0.005 of it.
//!
//! Which shots share an offset is decided by [`segments`]; the real waveform is prepared by
//! [`profile`]. `crate::sql::collocation` drives it from a dataset. `docs/collocation.md` has the method.

pub mod correlation;
pub mod profile;
pub mod raster;
pub mod segments;
pub mod surface;

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::sim::index::CellGrid;
use crate::sim::{Profile, Pulse, SimConfig};

use correlation::{LagWindow, SimulatedProfiles};
use profile::GridProfile;
use raster::{offset_waves, support_half_width, RasterError};
use segments::SegmentPlan;
use surface::{Optimum, Surface};

/// The horizontal offsets searched along each axis: `(i − half)·step` for i = 0 … 2·half.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OffsetGrid {
    /// Spacing (m).
    pub step: f64,
    half: usize,
}

impl OffsetGrid {
    /// Offsets −max_shift … +max_shift (m) every `step` m (the largest multiple of `step` not
    /// beyond `max_shift`); a usage error for a non-positive step, a negative shift or more than
    /// 101 offsets per axis (a shot's raster holds every offset: 101² × its bins).
    pub fn new(max_shift: f64, step: f64) -> Result<OffsetGrid> {
        if !(step > 0.0) || !step.is_finite() || !(max_shift >= 0.0) || !max_shift.is_finite() {
            return Err(Error::Usage(format!(
                "--max-shift {max_shift} / --step {step}: need a shift ≥ 0 and a step > 0"
            )));
        }
        let half = (max_shift / step + 1e-9).floor() as usize;
        if half > 50 {
            return Err(Error::Usage(format!(
                "--max-shift {max_shift} / --step {step}: more than 101 offsets per axis"
            )));
        }
        Ok(OffsetGrid { step, half })
    }

    /// Offsets per axis.
    pub fn n(&self) -> usize {
        2 * self.half + 1
    }

    /// Index of the zero offset.
    pub fn half(&self) -> usize {
        self.half
    }

    /// Offset (m) of index `i`.
    pub fn offset(&self, i: usize) -> f64 {
        (i as f64 - self.half as f64) * self.step
    }

    /// Offset (m) at a fractional index.
    pub fn offset_at(&self, i: f64) -> f64 {
        (i - self.half as f64) * self.step
    }

    /// The largest offset (m).
    pub fn max_offset(&self) -> f64 {
        self.half as f64 * self.step
    }

    /// Column of the zero offset in an [`raster::OffsetWaves`] row.
    pub fn zero_column(&self) -> usize {
        self.half * self.n() + self.half
    }
}

/// Settings of a collocation.
#[derive(Debug, Clone, PartialEq)]
pub struct CollocateConfig {
    /// The simulation model: footprint σ, bin size and pulse (count weighting, no density
    /// normalisation, no cleaning, pulse after binning, exact taps; see [`CollocateConfig::model`]).
    pub model: SimConfig,
    /// Horizontal offsets searched.
    pub grid: OffsetGrid,
    /// Half-width (m) of the vertical window searched around the coarse estimate (moved when the
    /// optimum falls on its edge).
    pub vertical_half_window: f64,
    /// Tolerance on r defining the region whose half-extents are reported.
    pub tolerance: f64,
    /// Shots whose footprint (cells of 1.5 m within σ_f of the reported position) holds ALS
    /// returns in less than this fraction of cells are skipped.
    pub min_covered_fraction: f32,
}

/// Shots whose points are read and rasterised together (bounds memory).
pub const SUB_BATCH: usize = 16;

/// Times the vertical window may move to follow an optimum on its edge.
const MAX_RECENTRES: usize = 3;

impl CollocateConfig {
    /// The defaults for a search of ±`max_shift` m at `step` m: gedisim's `default` simulation
    /// model (σ_f 5.5 m, 0.15 m bins, 15 ns Gaussian pulse, cut-off 0.0006) with count weighting
    /// and without density normalisation or cleaning (as collocateWaves), vertical window ±6 m,
    /// tolerance 0.005, coverage ≥ 2/3.
    pub fn new(max_shift: f64, step: f64) -> Result<CollocateConfig> {
        Ok(CollocateConfig {
            model: CollocateConfig::model(),
            grid: OffsetGrid::new(max_shift, step)?,
            vertical_half_window: 6.0,
            tolerance: 0.005,
            min_covered_fraction: 2.0 / 3.0,
        })
    }

    /// The simulation model of the collocation, as a [`SimConfig`] that the brute-force simulator
    /// ([`crate::sim::simulate`]) accepts: `default` profile, no density normalisation, no
    /// cleaning, no coverage check.
    pub fn model() -> SimConfig {
        let mut m = SimConfig::new(Profile::Default);
        m.normalise_density = false;
        m.clean_outliers = false;
        m.min_covered_fraction = None;
        m
    }

    /// Checks that the model is one the raster reproduces exactly.
    pub fn validate(&self) -> Result<()> {
        let m = &self.model;
        let q = m.quirks;
        if m.normalise_density
            || m.clean_outliers
            || m.pulse_timing != crate::sim::PulseTiming::AfterBinning
            || q.batch_grid
            || q.divide_by_taps
        {
            return Err(Error::Usage(
                "collocation model: density normalisation, cleaning, pulse-before-binning, batch grids and tap \
                    division are not supported"
                    .into(),
            ));
        }
        if !(m.fsigma > 0.0) || !(m.res > 0.0) || !(self.vertical_half_window >= 0.0) || !(self.tolerance > 0.0) {
            return Err(Error::Usage(
                "collocation model: σ_f, bin size, vertical window and tolerance must be positive".into(),
            ));
        }
        Ok(())
    }

    /// Half-width (m) of the square of ALS around a shot that its search needs.
    pub fn support_half_width(&self) -> f64 {
        support_half_width(&self.grid, &self.model)
    }

    fn lag_half(&self) -> usize {
        (self.vertical_half_window / self.model.res).ceil() as usize
    }
}

/// ALS returns as the collocation reads them (heights as stored).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PointCloud {
    pub x: Vec<f64>,
    pub y: Vec<f64>,
    pub z: Vec<f64>,
}

impl PointCloud {
    /// Number of points.
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// True without points.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }
}

/// A shot to collocate: its reported position and its real waveform on the grid.
#[derive(Debug, Clone, PartialEq)]
pub struct ShotInput {
    /// Reported easting (m, ALS CRS).
    pub x: f64,
    /// Reported northing (m).
    pub y: f64,
    /// Denoised real waveform on orthometric heights ([`profile::real_profile`]).
    pub real: GridProfile,
    /// The shot's recorded transmit pulse (at the model's bin size); `None` = the model's pulse.
    pub pulse: Option<std::sync::Arc<Pulse>>,
}

impl ShotInput {
    /// The pulse the shot's waveforms are simulated with.
    pub fn pulse<'a>(&'a self, cfg: &'a CollocateConfig) -> &'a Pulse {
        self.pulse.as_deref().unwrap_or(&cfg.model.pulse)
    }
}

/// Why a shot with a usable waveform took no part in a segment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ShotSkip {
    /// The ALS covers too little of the footprint at the reported position.
    PartlyCovered {
        /// Fraction of the footprint's 1.5 m cells holding a return.
        covered_fraction: f32,
    },
    /// No return contributes at the reported position.
    NoPoints,
    /// The real and simulated waveforms never overlap in height (within the vertical search).
    NoOverlap,
    /// The returns near the shot span more than 3 km of height (corrupt ALS heights).
    HeightRange,
}

impl ShotSkip {
    /// Short text for reports.
    pub fn reason(&self) -> &'static str {
        match self {
            ShotSkip::PartlyCovered { .. } => "partly_covered",
            ShotSkip::NoPoints => "no_points",
            ShotSkip::NoOverlap => "no_overlap",
            ShotSkip::HeightRange => "als_height_range",
        }
    }
}

/// The offset of one segment.
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentSolution {
    /// Optimum and sharpness of the mean-r surface.
    pub optimum: Optimum,
    /// Mean r at zero offset (dx = dy = dz = 0).
    pub r_before: f64,
    /// The support shots that took part (indices into the unit's shots).
    pub used: Vec<usize>,
}

/// Per shot of a unit: r at zero offset and r over offsets × lags of the unit's window.
type ShotOutcome = std::result::Result<(f64, Vec<f32>), ShotSkip>;

/// One solution per plan (`None`: none of its shots could be used) and each shot's skip reason.
pub type UnitResult = (Vec<Option<SegmentSolution>>, Vec<Option<ShotSkip>>);

/// Solves the segments `plans` of one unit of `shots` (plans index into `shots`). Points are
/// requested through `points_for(shot indices)`, which must return at least the returns within
/// [`CollocateConfig::support_half_width`] of each of those shots; it is called for sub-batches
/// of [`SUB_BATCH`] shots (and again for a segment whose optimum leaves the vertical window).
/// Returns one solution per plan (`None` when none of its shots could be used) and the skip
/// reason of every shot that could not be used. `on_shot` is called as shots are rasterised.
pub fn collocate_unit<E>(
    shots: &[ShotInput],
    plans: &[SegmentPlan],
    cfg: &CollocateConfig,
    points_for: &mut dyn FnMut(&[usize]) -> std::result::Result<PointCloud, E>,
    on_shot: &(dyn Fn() + Sync),
) -> std::result::Result<UnitResult, E> {
    let mut wanted: Vec<usize> = plans.iter().flat_map(|p| p.support.iter().copied()).collect();
    wanted.sort_unstable();
    wanted.dedup();
    let zero = cfg.grid.zero_column();
    let mut states: Vec<Option<ShotOutcome>> = (0..shots.len()).map(|_| None).collect();
    let mut window: Option<LagWindow> = None;
    for chunk in wanted.chunks(SUB_BATCH) {
        let cloud = points_for(chunk)?;
        let index = CellGrid::from_xy(&cloud.x, &cloud.y, INDEX_CELL);
        // One raster per shot (all offsets); its zero-offset column serves r_before and the coarse
        // vertical search, which the first sub-batch with usable shots settles for the unit.
        let rasters: Vec<_> = chunk.par_iter().map(|&s| rasterise(&shots[s], &cloud, &index, cfg)).collect();
        drop((cloud, index));
        if window.is_none() {
            let usable: Vec<(&GridProfile, &SimulatedProfiles)> =
                chunk.iter().zip(&rasters).filter_map(|(&s, r)| r.as_ref().ok().map(|p| (&shots[s].real, p))).collect();
            window = coarse_lag(&usable, zero, cfg.model.res).map(|c| LagWindow::around(c, cfg.lag_half()));
        }
        let outcomes: Vec<ShotOutcome> = chunk
            .par_iter()
            .zip(rasters)
            .map(|(&s, raster)| {
                let real = &shots[s].real;
                let out = raster.and_then(|p| {
                    let w = window.ok_or(ShotSkip::NoOverlap)?;
                    Ok((p.correlate_one(real, zero, 0), p.correlate(real, w)))
                });
                on_shot();
                out
            })
            .collect();
        for (&s, o) in chunk.iter().zip(outcomes) {
            states[s] = Some(o);
        }
    }

    let skips: Vec<Option<ShotSkip>> =
        states.iter().map(|st| st.as_ref().and_then(|o| o.as_ref().err().copied())).collect();
    let mut solutions = Vec::with_capacity(plans.len());
    for plan in plans {
        let used: Vec<usize> = plan.support.iter().copied().filter(|&s| matches!(&states[s], Some(Ok(_)))).collect();
        let Some(mut w) = window.filter(|_| !used.is_empty()) else {
            solutions.push(None);
            continue;
        };
        let mut surface = Surface::new(cfg.grid, w, cfg.model.res);
        let mut r_before = 0.0;
        for &s in &used {
            if let Some(Ok((r, v))) = &states[s] {
                r_before += r / used.len() as f64;
                surface.add(v);
            }
        }
        let Some(mut optimum) = surface.optimum(cfg.tolerance) else {
            solutions.push(None);
            continue;
        };
        // Follow an optimum on the window's edge (steep terrain, or a coarse estimate misled).
        for _ in 0..MAX_RECENTRES {
            if !optimum.at_window_edge {
                break;
            }
            let centre = (optimum.dz / cfg.model.res).round() as i64;
            w = LagWindow::around(centre, cfg.lag_half());
            surface = Surface::new(cfg.grid, w, cfg.model.res);
            for chunk in used.chunks(SUB_BATCH) {
                let cloud = points_for(chunk)?;
                let index = CellGrid::from_xy(&cloud.x, &cloud.y, INDEX_CELL);
                let rs: Vec<Option<Vec<f32>>> =
                    chunk.par_iter().map(|&s| shot_surface(&shots[s], &cloud, &index, w, cfg)).collect();
                for r in rs.into_iter().flatten() {
                    surface.add(&r);
                }
            }
            match surface.optimum(cfg.tolerance) {
                Some(o) => optimum = o,
                None => break,
            }
        }
        solutions.push(Some(SegmentSolution { optimum, r_before, used }));
    }
    Ok((solutions, skips))
}

/// Cell size of the point index (m).
const INDEX_CELL: f64 = 5.0;

/// [`horizontal_offset_at`] of each group of shots (a group shares one offset; `None` when it has
/// none), whole groups about [`SUB_BATCH`] shots at a time sharing one `points_for` request, as
/// [`collocate_unit`] asks for the points of its sub-batches.
pub fn horizontal_offsets_at<E>(
    groups: &[Vec<ShotInput>],
    cfg: &CollocateConfig,
    dz: f64,
    points_for: &mut dyn FnMut(&[&ShotInput]) -> std::result::Result<PointCloud, E>,
) -> std::result::Result<Vec<Option<(f64, f64)>>, E> {
    let mut out = vec![None; groups.len()];
    for batch in whole_groups(groups.iter().map(Vec::len), SUB_BATCH) {
        let shots: Vec<&ShotInput> = groups[batch.clone()].iter().flatten().collect();
        if !shots.is_empty() {
            let cloud = points_for(&shots)?;
            for k in batch.filter(|&k| !groups[k].is_empty()) {
                out[k] = horizontal_offset_at(&groups[k], &cloud, cfg, dz);
            }
        }
    }
    Ok(out)
}

/// Consecutive groups (of the given sizes) taken whole, each batch closed once it holds `max`
/// items or more: the ranges of group indices.
fn whole_groups(sizes: impl Iterator<Item = usize>, max: usize) -> Vec<std::ops::Range<usize>> {
    let (mut out, mut start, mut n, mut len) = (Vec::new(), 0, 0, 0);
    for (k, size) in sizes.enumerate() {
        (n, len) = (n + size, k + 1);
        if n >= max {
            out.push(start..len);
            (start, n) = (len, 0);
        }
    }
    if start < len {
        out.push(start..len);
    }
    out
}

/// The horizontal offset (dx, dy) of `shots`, which share one offset, with the vertical offset
/// given instead of searched: the grid node maximising their summed r at the lag of `dz` (m,
/// GEDI − N − ALS). `cloud` must hold the returns within [`CollocateConfig::support_half_width`]
/// of every shot. On a segment of one or two shots a free vertical offset trades off against the
/// horizontal one on slopes; a vertical reference shared by all segments pins it. `None` when no
/// shot can be rasterised.
pub fn horizontal_offset_at(
    shots: &[ShotInput],
    cloud: &PointCloud,
    cfg: &CollocateConfig,
    dz: f64,
) -> Option<(f64, f64)> {
    let index = CellGrid::from_xy(&cloud.x, &cloud.y, INDEX_CELL);
    let lag = (dz / cfg.model.res).round() as i64;
    let n = cfg.grid.n();
    let rs: Vec<Vec<f64>> = shots
        .par_iter()
        .filter_map(|s| {
            rasterise(s, cloud, &index, cfg)
                .ok()
                .map(|p| (0..n * n).map(|c| p.correlate_one(&s.real, c, lag)).collect())
        })
        .collect();
    let first = rs.first()?;
    let sum: Vec<f64> = (0..first.len()).map(|c| rs.iter().map(|r| r[c]).sum()).collect();
    let best = (0..sum.len()).max_by(|&a, &b| sum[a].total_cmp(&sum[b]))?;
    Some((cfg.grid.offset(best / n), cfg.grid.offset(best % n)))
}

/// Returns within the square of half-width `half` around (x0, y0) (indices into the cloud).
fn candidates(cloud: &PointCloud, index: &CellGrid, (x0, y0): (f64, f64), half: f64) -> Vec<u32> {
    let mut pos = Vec::new();
    index.candidates(x0, y0, half, &mut pos);
    let order = index.order();
    pos.into_iter()
        .map(|p| order[p as usize])
        .filter(|&i| {
            let i = i as usize;
            (cloud.x[i] - x0).abs() <= half && (cloud.y[i] - y0).abs() <= half
        })
        .collect()
}

/// Coverage check and the raster of every offset of one shot, cut to the signal extents.
fn rasterise(
    shot: &ShotInput,
    cloud: &PointCloud,
    index: &CellGrid,
    cfg: &CollocateConfig,
) -> std::result::Result<SimulatedProfiles, ShotSkip> {
    let centre = (shot.x, shot.y);
    let radius = cfg.model.fsigma as f64;
    let near = candidates(cloud, index, centre, radius);
    let covered_fraction = covered_fraction(cloud, &near, centre, radius);
    if covered_fraction < cfg.min_covered_fraction {
        return Err(ShotSkip::PartlyCovered { covered_fraction });
    }
    let cand = candidates(cloud, index, centre, cfg.support_half_width());
    let waves = offset_waves(&cloud.x, &cloud.y, &cloud.z, &cand, centre, &cfg.grid, &cfg.model, shot.pulse(cfg))
        .map_err(|e| match e {
            RasterError::NoReturns => ShotSkip::NoPoints,
            RasterError::HeightRange => ShotSkip::HeightRange,
        })?;
    let profiles = SimulatedProfiles::new(waves);
    if profiles.extent(cfg.grid.zero_column()).is_none() {
        return Err(ShotSkip::NoPoints);
    }
    Ok(profiles)
}

/// r over every offset × lag of `window` for one shot (`None` when nothing contributes).
fn shot_surface(
    shot: &ShotInput,
    cloud: &PointCloud,
    index: &CellGrid,
    window: LagWindow,
    cfg: &CollocateConfig,
) -> Option<Vec<f32>> {
    let centre = (shot.x, shot.y);
    let cand = candidates(cloud, index, centre, cfg.support_half_width());
    let waves =
        offset_waves(&cloud.x, &cloud.y, &cloud.z, &cand, centre, &cfg.grid, &cfg.model, shot.pulse(cfg)).ok()?;
    Some(SimulatedProfiles::new(waves).correlate(&shot.real, window))
}

/// Fraction of the 1.5 m cells whose centre lies within `radius` of `centre` that hold a return.
fn covered_fraction(cloud: &PointCloud, near: &[u32], centre: (f64, f64), radius: f64) -> f32 {
    const CELL: f64 = 1.5;
    let n = (2.0 * radius / CELL).ceil() as usize + 1;
    let origin = (centre.0 - n as f64 * CELL / 2.0, centre.1 - n as f64 * CELL / 2.0);
    let mut hit = vec![false; n * n];
    for &i in near {
        let (cx, cy) =
            (((cloud.x[i as usize] - origin.0) / CELL).floor(), ((cloud.y[i as usize] - origin.1) / CELL).floor());
        if cx >= 0.0 && cy >= 0.0 && (cx as usize) < n && (cy as usize) < n {
            hit[cy as usize * n + cx as usize] = true;
        }
    }
    let (mut within, mut covered) = (0u32, 0u32);
    for j in 0..n {
        for i in 0..n {
            let (dx, dy) =
                (origin.0 + (i as f64 + 0.5) * CELL - centre.0, origin.1 + (j as f64 + 0.5) * CELL - centre.1);
            if dx * dx + dy * dy < radius * radius {
                within += 1;
                covered += u32::from(hit[j * n + i]);
            }
        }
    }
    if within == 0 {
        1.0
    } else {
        covered as f32 / within as f32
    }
}

/// Largest vertical offset (m) the coarse search considers, either way: far beyond any datum gap
/// (tens of metres), it bounds the work when a waveform's heights are corrupt.
pub const MAX_VERTICAL_OFFSET_M: f64 = 1000.0;

/// The vertical lag (bins of `dz`) maximising the summed r of the shots at offset `column` over
/// every lag at which any of them overlaps its simulation (within ±[`MAX_VERTICAL_OFFSET_M`]): the
/// coarse full-range vertical search.
pub fn coarse_lag(shots: &[(&GridProfile, &SimulatedProfiles)], column: usize, dz: f64) -> Option<i64> {
    let limit = (MAX_VERTICAL_OFFSET_M / dz).ceil() as i64;
    let ranges: Vec<(i64, i64)> = shots
        .iter()
        .filter_map(|(real, sim)| sim.overlap_lags(real, column))
        .filter(|&(a, b)| a <= limit && b >= -limit)
        .map(|(a, b)| (a.max(-limit), b.min(limit)))
        .collect();
    let lo = ranges.iter().map(|r| r.0).min()?;
    let hi = ranges.iter().map(|r| r.1).max()?;
    let window = LagWindow { first: lo, len: (hi - lo + 1) as usize };
    let mut sum = vec![0f64; window.len];
    for (real, sim) in shots {
        for (s, li) in sum.iter_mut().zip(0..window.len) {
            *s += sim.correlate_one(real, column, window.lag(li));
        }
    }
    let best = sum.iter().enumerate().fold(0, |b, (i, &v)| if v > sum[b] { i } else { b });
    Some(window.lag(best))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn groups_are_batched_whole_up_to_the_sub_batch() {
        let batches = |sizes: &[usize]| whole_groups(sizes.iter().copied(), 16);
        assert_eq!(batches(&[]), Vec::<std::ops::Range<usize>>::new());
        assert_eq!(batches(&[3, 0, 2]), vec![0..3]);
        // A batch closes once it holds 16 shots or more; a group is never split.
        assert_eq!(batches(&[10, 10, 16, 1, 0]), vec![0..2, 2..3, 3..5]);
        assert_eq!(batches(&[40]), vec![0..1]);
        assert_eq!(batches(&[16, 0]), vec![0..1, 1..2]);
    }

    #[test]
    fn offset_grid_is_symmetric() {
        let g = OffsetGrid::new(10.0, 1.0).unwrap();
        assert_eq!(g.n(), 21);
        assert_eq!(g.offset(0), -10.0);
        assert_eq!(g.offset(20), 10.0);
        assert_eq!(g.zero_column(), 220);
        assert_eq!(OffsetGrid::new(10.0, 3.0).unwrap().n(), 7);
        assert!(OffsetGrid::new(10.0, 0.0).is_err());
        assert!(OffsetGrid::new(-1.0, 1.0).is_err());
        assert!(OffsetGrid::new(1000.0, 0.1).is_err());
    }

    #[test]
    fn the_default_model_is_supported() {
        CollocateConfig::new(10.0, 1.0).unwrap().validate().unwrap();
        let mut c = CollocateConfig::new(10.0, 1.0).unwrap();
        c.model.normalise_density = true;
        assert!(c.validate().is_err());
    }
}
