//! Which shot × weighting × algorithm rows the study keeps, and why the others go.
//!
//! The study's filters (docs/contracts.md "The study", docs/gedi-products.md §5) are applied in a fixed
//! order and every candidate row (shot × 3 weightings × 7 algorithms) that fails is counted at
//! the **first** filter it fails, so the counts add up: candidates = Σ removed + kept. The order
//! puts the ALS side first (most shots of a real granule are nowhere near the ALS), then the
//! GEDI side, then the simulated truths:
//!
//! 1. `als_coverage` — the ALS covers the footprint and the simulation ran (status `ok`);
//! 2. `acquisition_window` — the shot's date lies in the ALS acquisition window widened by
//!    `max_days_apart` (not applied, and counted apart, when either date is unknown);
//! 3. `quality` — `quality_flag[_aN] = 1` and `degrade_flag = 0` (per shot);
//! 4. `sensitivity` — `sensitivity[_aN] ≥ 0.90`;
//! 5. `gedi_values` — GEDI ground, 101 RH values and the geoid offset are present and finite;
//! 6. `als_cover` — 0 < ALS cover < 1 (this weighting);
//! 7. `sim_rh100` — simulated RH100 of this weighting within [5, 60] m.
//!
//! Pure: plain structs in, [`ResultInput`] rows and counts out.

use crate::gedi::{N_ALGORITHMS, RH_LEN};
use crate::study::align::VerticalReference;
use crate::study::classes::sensitivity_group;

/// Default of `--max-days-apart`: a GEDI shot more than a year before or after the ALS
/// acquisition window is dropped. Within a year canopy growth (< 1 m in these forests) stays
/// well below the RH errors studied, and the season is stratified apart (`phenology`).
pub const DEFAULT_MAX_DAYS_APART: f64 = 365.0;
/// Lowest simulated RH100 kept (m).
pub const MIN_RH100: f64 = 5.0;
/// Highest simulated RH100 kept (m).
pub const MAX_RH100: f64 = 60.0;
/// The weightings of the `sim` and `results` tables, in row order.
pub const WEIGHTINGS: [&str; crate::sim::N_STUDY_WEIGHTINGS] = crate::sim::Weighting::NAMES;
/// `default` then a1 … a6, in row order.
pub const ALGORITHMS: [StudyAlgorithm; N_ALGORITHMS + 1] = [
    StudyAlgorithm::Default,
    StudyAlgorithm::A(1),
    StudyAlgorithm::A(2),
    StudyAlgorithm::A(3),
    StudyAlgorithm::A(4),
    StudyAlgorithm::A(5),
    StudyAlgorithm::A(6),
];
/// GEDI `delta_time` epoch (2018-01-01T00:00:00Z) in Unix microseconds.
pub const GEDI_EPOCH_UNIX_US: i64 = 1_514_764_800_000_000;
const DAY_US: f64 = 86_400e6;

/// The study's tunable bounds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StudyRules {
    /// Days the shot may lie before the ALS window's start or after its end.
    pub max_days_apart: f64,
    /// Simulated RH100 bounds (m, inclusive).
    pub min_rh100: f64,
    pub max_rh100: f64,
}

impl Default for StudyRules {
    fn default() -> Self {
        StudyRules { max_days_apart: DEFAULT_MAX_DAYS_APART, min_rh100: MIN_RH100, max_rh100: MAX_RH100 }
    }
}

/// The study's filters, in the order they are applied.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Filter {
    AlsCoverage,
    AcquisitionWindow,
    Quality,
    Sensitivity,
    GediValues,
    AlsCover,
    SimRh100,
}

impl Filter {
    /// Every filter, in order.
    pub const ALL: [Filter; 7] = [
        Filter::AlsCoverage,
        Filter::AcquisitionWindow,
        Filter::Quality,
        Filter::Sensitivity,
        Filter::GediValues,
        Filter::AlsCover,
        Filter::SimRh100,
    ];

    /// Short name (metadata key, tests).
    pub fn name(self) -> &'static str {
        match self {
            Filter::AlsCoverage => "als_coverage",
            Filter::AcquisitionWindow => "acquisition_window",
            Filter::Quality => "quality",
            Filter::Sensitivity => "sensitivity",
            Filter::GediValues => "gedi_values",
            Filter::AlsCover => "als_cover",
            Filter::SimRh100 => "sim_rh100",
        }
    }

    /// What a row must satisfy to pass, for people.
    pub fn describe(self, rules: &StudyRules) -> String {
        match self {
            Filter::AlsCoverage => "footprint fully covered by ALS and simulated".into(),
            Filter::AcquisitionWindow => {
                format!("shot date within the ALS acquisition window ± {} days", rules.max_days_apart)
            }
            Filter::Quality => "quality_flag = 1 and degrade_flag = 0".into(),
            Filter::Sensitivity => "sensitivity ≥ 0.9".into(),
            Filter::GediValues => "GEDI ground, RH and geoid offset present".into(),
            Filter::AlsCover => "0 < ALS cover < 1".into(),
            Filter::SimRh100 => format!("{} m ≤ simulated RH100 ≤ {} m", rules.min_rh100, rules.max_rh100),
        }
    }

    fn index(self) -> usize {
        self as usize
    }
}

/// Rows counted through the filters.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct FilterCounts {
    /// Shots seen.
    pub shots: u64,
    /// Candidate rows: shots × 3 weightings × 7 algorithms.
    pub candidates: u64,
    /// Rows removed by each filter (first failure), in [`Filter::ALL`] order.
    pub removed: [u64; 7],
    /// Rows kept.
    pub kept: u64,
    /// Shots with at least one row kept.
    pub shots_kept: u64,
    /// Rows that reached the acquisition-window filter without a known window or shot date
    /// (the filter was not applied to them).
    pub window_unknown: u64,
}

impl FilterCounts {
    /// Rows removed by `f`.
    pub fn removed_by(&self, f: Filter) -> u64 {
        self.removed[f.index()]
    }

    /// Add `other`'s counts.
    pub fn add(&mut self, other: &FilterCounts) {
        self.shots += other.shots;
        self.candidates += other.candidates;
        for (a, b) in self.removed.iter_mut().zip(other.removed) {
            *a += b;
        }
        self.kept += other.kept;
        self.shots_kept += other.shots_kept;
        self.window_unknown += other.window_unknown;
    }

    /// Count `n` shots whose every row fails `f` (e.g. shots far from the ALS, never simulated).
    pub fn remove_shots(&mut self, n: u64, f: Filter) {
        let rows = n * (WEIGHTINGS.len() * ALGORITHMS.len()) as u64;
        self.shots += n;
        self.candidates += rows;
        self.removed[f.index()] += rows;
    }

    /// As JSON (stored in each results file's metadata).
    pub fn to_json(&self) -> serde_json::Value {
        let removed: serde_json::Map<String, serde_json::Value> =
            Filter::ALL.iter().map(|f| (f.name().to_string(), self.removed_by(*f).into())).collect();
        serde_json::json!({
            "shots": self.shots,
            "candidates": self.candidates,
            "removed": removed,
            "kept": self.kept,
            "shots_kept": self.shots_kept,
            "window_unknown": self.window_unknown,
        })
    }

    /// Back from [`to_json`](Self::to_json); `None` when a field is missing.
    pub fn from_json(v: &serde_json::Value) -> Option<FilterCounts> {
        let u = |k: &str| v.get(k)?.as_u64();
        let mut removed = [0; 7];
        for f in Filter::ALL {
            removed[f.index()] = v.get("removed")?.get(f.name())?.as_u64()?;
        }
        Some(FilterCounts {
            shots: u("shots")?,
            candidates: u("candidates")?,
            removed,
            kept: u("kept")?,
            shots_kept: u("shots_kept")?,
            window_unknown: u("window_unknown")?,
        })
    }
}

/// One L2A algorithm's products for a shot (the root fields for `default`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct AlgorithmFacts {
    pub quality_flag: Option<u8>,
    pub sensitivity: Option<f64>,
    /// m, WGS84 ellipsoid.
    pub elev_lowestmode: Option<f64>,
    /// RH0…RH100, m above `elev_lowestmode`.
    pub rh: Option<Vec<f32>>,
}

/// What the `shots` table says about one shot.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ShotFacts {
    pub shot_number: u64,
    pub granule: String,
    pub beam: String,
    pub beam_type: String,
    /// s since 2018-01-01 UTC.
    pub delta_time: Option<f64>,
    pub degrade_flag: Option<u8>,
    pub leaf_off_flag: Option<u8>,
    pub selected_algorithm: Option<u8>,
    /// N used for the shot (`geoid_offset_used`), m.
    pub geoid_offset: Option<f64>,
    /// `default`, a1 … a6 (the order of [`ALGORITHMS`]).
    pub algorithms: [AlgorithmFacts; N_ALGORITHMS + 1],
}

/// One weighting of the shot's simulation (a `sim` row).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SimFacts {
    /// `status = ok`.
    pub ok: bool,
    pub als_ground: Option<f64>,
    pub slope_deg: Option<f64>,
    pub als_cover: Option<f64>,
    /// RH0…RH100, m above `als_ground`.
    pub rh: Option<Vec<f32>>,
}

/// The ALS acquisition window at a footprint (Unix µs, inclusive).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AlsWindow {
    pub start_us: i64,
    pub end_us: i64,
}

/// A tile's extent and acquisition window (`tiles` table; `None` when the LAS stores GPS week time).
#[derive(Debug, Clone, PartialEq)]
pub struct TileWindow {
    pub xmin: f64,
    pub ymin: f64,
    pub xmax: f64,
    pub ymax: f64,
    pub start_us: Option<i64>,
    pub end_us: Option<i64>,
}

/// The window of the tiles whose extent holds (x, y): from the earliest start to the latest end.
/// `None` (unknown) when no tile holds the point or one of them has no dates.
pub fn als_window(tiles: &[TileWindow], x: f64, y: f64) -> Option<AlsWindow> {
    let mut out: Option<AlsWindow> = None;
    for t in tiles.iter().filter(|t| x >= t.xmin && x <= t.xmax && y >= t.ymin && y <= t.ymax) {
        let (s, e) = (t.start_us?, t.end_us?);
        out = Some(match out {
            None => AlsWindow { start_us: s, end_us: e },
            Some(w) => AlsWindow { start_us: w.start_us.min(s), end_us: w.end_us.max(e) },
        });
    }
    out
}

/// Whether a shot at `delta_time` (s since 2018-01-01) lies within `w` widened by `max_days`.
pub fn within_window(delta_time: f64, w: AlsWindow, max_days: f64) -> bool {
    let t = GEDI_EPOCH_UNIX_US as f64 + delta_time * 1e6;
    let margin = max_days * DAY_US;
    t >= w.start_us as f64 - margin && t <= w.end_us as f64 + margin
}

/// The collocation segment a shot belongs to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentFacts {
    /// `offsets.dz`, m.
    pub dz: f64,
    /// `offsets.r_after`.
    pub r_after: Option<f64>,
}

/// Everything else known about a shot.
#[derive(Debug, Clone, Default)]
pub struct ShotContext<'a> {
    /// The simulation of each weighting ([`WEIGHTINGS`] order); `None` when the shot was not
    /// simulated (its footprint is not covered by the ALS extents).
    pub sim: Option<&'a [SimFacts; 3]>,
    /// ALS acquisition window at the footprint.
    pub window: Option<AlsWindow>,
    /// The shot's collocation segment, if any.
    pub segment: Option<SegmentFacts>,
    /// Forest type from `strata`.
    pub forest_type: Option<&'a str>,
}

/// The rows of one shot that pass every filter, appended to `out`; every candidate is counted
/// in `counts`.
pub fn select_rows(
    shot: &ShotFacts,
    ctx: &ShotContext,
    rules: &StudyRules,
    counts: &mut FilterCounts,
    out: &mut Vec<ResultInput>,
) {
    counts.shots += 1;
    let before = out.len();
    for (w, weighting) in WEIGHTINGS.iter().enumerate() {
        for (a, algorithm) in ALGORITHMS.iter().enumerate() {
            counts.candidates += 1;
            match row(shot, ctx, rules, w, a, counts) {
                Ok(r) => {
                    debug_assert_eq!(r.weighting, *weighting);
                    debug_assert_eq!(r.algorithm, *algorithm);
                    counts.kept += 1;
                    out.push(r);
                }
                Err(f) => counts.removed[f.index()] += 1,
            }
        }
    }
    if out.len() > before {
        counts.shots_kept += 1;
    }
}

fn finite_rh(rh: &Option<Vec<f32>>) -> Option<&Vec<f32>> {
    rh.as_ref().filter(|v| v.len() == RH_LEN && v.iter().all(|x| x.is_finite()))
}

/// Row (w, a) of the shot, or the first filter it fails.
fn row(
    shot: &ShotFacts,
    ctx: &ShotContext,
    rules: &StudyRules,
    w: usize,
    a: usize,
    counts: &mut FilterCounts,
) -> Result<ResultInput, Filter> {
    let sim = ctx.sim.map(|s| &s[w]).filter(|s| s.ok).ok_or(Filter::AlsCoverage)?;
    match (ctx.window, shot.delta_time.filter(|t| t.is_finite())) {
        (Some(win), Some(t)) => {
            if !within_window(t, win, rules.max_days_apart) {
                return Err(Filter::AcquisitionWindow);
            }
        }
        _ => counts.window_unknown += 1,
    }
    let alg = &shot.algorithms[a];
    if !(alg.quality_flag == Some(1) && shot.degrade_flag == Some(0)) {
        return Err(Filter::Quality);
    }
    let sensitivity = alg.sensitivity.filter(|&s| sensitivity_group(s).is_some()).ok_or(Filter::Sensitivity)?;
    let elev = alg.elev_lowestmode.filter(|z| z.is_finite()).ok_or(Filter::GediValues)?;
    let rh_gedi = finite_rh(&alg.rh).ok_or(Filter::GediValues)?;
    let geoid_offset = shot.geoid_offset.filter(|n| n.is_finite()).ok_or(Filter::GediValues)?;
    let cover = sim.als_cover.filter(|&c| c > 0.0 && c < 1.0).ok_or(Filter::AlsCover)?;
    let als_ground = sim.als_ground.filter(|z| z.is_finite()).ok_or(Filter::SimRh100)?;
    let rh_sim = finite_rh(&sim.rh)
        .filter(|rh| (rules.min_rh100..=rules.max_rh100).contains(&(rh[RH_LEN - 1] as f64)))
        .ok_or(Filter::SimRh100)?;
    let vertical_reference = match ctx.segment.filter(|s| s.dz.is_finite()) {
        Some(s) => VerticalReference::GeoidAndCollocation { geoid_offset, dz: s.dz },
        None => VerticalReference::Geoid { geoid_offset },
    };
    Ok(ResultInput {
        shot_number: shot.shot_number,
        granule: shot.granule.clone(),
        beam: shot.beam.clone(),
        beam_type: shot.beam_type.clone(),
        forest_type: ctx.forest_type.map(str::to_string),
        leaf_off_flag: shot.leaf_off_flag,
        selected_algorithm: shot.selected_algorithm,
        sensitivity,
        slope_deg: sim.slope_deg,
        als_cover: Some(cover),
        weighting: WEIGHTINGS[w].to_string(),
        algorithm: ALGORITHMS[a],
        als_ground,
        elev_lowestmode: elev,
        vertical_reference,
        rh_sim: rh_sim.clone(),
        rh_gedi: rh_gedi.clone(),
        r_collocation: ctx.segment.and_then(|s| s.r_after),
    })
}

/// Which L2A algorithm a row's GEDI ground and RH come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StudyAlgorithm {
    /// The shot's `selected_algorithm` (root `rh`, `elev_lowestmode`, `sensitivity`).
    Default,
    /// Algorithm aN, N = 1…6 (`rh_aN`, `elev_lowestmode_aN`, `sensitivity_aN`).
    A(u8),
}

impl StudyAlgorithm {
    /// `default` or `a1` … `a6`.
    pub fn label(&self) -> String {
        match self {
            StudyAlgorithm::Default => "default".to_string(),
            StudyAlgorithm::A(n) => format!("a{n}"),
        }
    }
}

/// What `run` knows about one shot × weighting × algorithm; `gedisim::ops::run::results_batch` derives the rest.
#[derive(Debug, Clone)]
pub struct ResultInput {
    pub shot_number: u64,
    pub granule: String,
    pub beam: String,
    /// `coverage` | `full_power` (the shots table's `beam_type`).
    pub beam_type: String,
    /// From `strata/`; `None` → `unknown`.
    pub forest_type: Option<String>,
    /// L2A `leaf_off_flag` (V2); `None` for V1 → phenology `unknown`.
    pub leaf_off_flag: Option<u8>,
    pub selected_algorithm: Option<u8>,
    /// Sensitivity of this algorithm (root `sensitivity` for `default`); must be ≥ 0.90.
    pub sensitivity: f64,
    /// ALS truth of this weighting (`sim.slope_deg`, `sim.als_cover`).
    pub slope_deg: Option<f64>,
    pub als_cover: Option<f64>,
    /// `count` | `frac` | `int`.
    pub weighting: String,
    pub algorithm: StudyAlgorithm,
    /// ALS ground of this weighting (`sim.als_ground`), m, ALS datum.
    pub als_ground: f64,
    /// GEDI ground of this algorithm, m, WGS84 ellipsoid (`elev_lowestmode[_aN]`).
    pub elev_lowestmode: f64,
    /// How to bring `elev_lowestmode` into the ALS datum.
    pub vertical_reference: VerticalReference,
    /// Simulated RH0…RH100 (`sim.rh`), m above `als_ground`.
    pub rh_sim: Vec<f32>,
    /// Real RH0…RH100 of this algorithm as stored (m above GEDI's ground).
    pub rh_gedi: Vec<f32>,
    /// Collocation correlation at the optimum (`offsets.r_after`), when collocated.
    pub r_collocation: Option<f64>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::study::classes::passes_quality;

    fn rh(top: f32) -> Vec<f32> {
        (0..RH_LEN).map(|k| top * k as f32 / 100.0).collect()
    }

    fn alg() -> AlgorithmFacts {
        AlgorithmFacts {
            quality_flag: Some(1),
            sensitivity: Some(0.97),
            elev_lowestmode: Some(349.0),
            rh: Some(rh(21.0)),
        }
    }

    /// A shot that passes every filter, dated 2022-06-01 (delta_time of that day).
    fn shot() -> ShotFacts {
        ShotFacts {
            shot_number: 42,
            granule: "g".into(),
            beam: "BEAM0101".into(),
            beam_type: "full_power".into(),
            delta_time: Some(JUNE_2022_S),
            degrade_flag: Some(0),
            leaf_off_flag: Some(0),
            selected_algorithm: Some(1),
            geoid_offset: Some(50.0),
            algorithms: std::array::from_fn(|_| alg()),
        }
    }

    /// 2022-06-01T00:00:00Z as GEDI delta_time.
    const JUNE_2022_S: f64 = (1_654_041_600 - 1_514_764_800) as f64;
    const JUNE_2022_US: i64 = 1_654_041_600_000_000;

    fn sims() -> [SimFacts; 3] {
        std::array::from_fn(|w| SimFacts {
            ok: true,
            als_ground: Some(300.0),
            slope_deg: Some(5.0 + w as f64),
            als_cover: Some(0.8),
            rh: Some(rh(20.0)),
        })
    }

    fn window() -> Option<AlsWindow> {
        Some(AlsWindow { start_us: JUNE_2022_US - 86_400_000_000, end_us: JUNE_2022_US })
    }

    fn run(shot: &ShotFacts, ctx: &ShotContext) -> (Vec<ResultInput>, FilterCounts) {
        let mut counts = FilterCounts::default();
        let mut out = Vec::new();
        select_rows(shot, ctx, &StudyRules::default(), &mut counts, &mut out);
        (out, counts)
    }

    fn balanced(c: &FilterCounts) -> bool {
        c.candidates == c.removed.iter().sum::<u64>() + c.kept
    }

    #[test]
    fn a_good_shot_gives_21_rows_in_order_with_the_right_facts() {
        let s = sims();
        let ctx = ShotContext { sim: Some(&s), window: window(), segment: None, forest_type: Some("mixed") };
        let (rows, c) = run(&shot(), &ctx);
        assert_eq!(rows.len(), 21);
        assert_eq!((c.shots, c.candidates, c.kept, c.shots_kept, c.window_unknown), (1, 21, 21, 1, 0));
        assert!(balanced(&c));
        assert_eq!(rows[0].weighting, "count");
        assert_eq!(rows[0].algorithm, StudyAlgorithm::Default);
        assert_eq!(rows[8].weighting, "frac");
        assert_eq!(rows[8].algorithm, StudyAlgorithm::A(1));
        assert_eq!(rows[8].slope_deg, Some(6.0), "the truths of the row's weighting");
        assert_eq!(rows[0].forest_type.as_deref(), Some("mixed"));
        assert_eq!(rows[0].vertical_reference, VerticalReference::Geoid { geoid_offset: 50.0 });
        // What a results batch requires of every row (`ops::run::results_batch` checks it again).
        assert!(rows.iter().all(|r| r.rh_sim.len() == RH_LEN && r.rh_gedi.len() == RH_LEN && r.sensitivity >= 0.9));
    }

    #[test]
    fn collocated_shot_uses_the_segment_dz_and_r() {
        let s = sims();
        let seg = SegmentFacts { dz: 0.4, r_after: Some(0.97) };
        let ctx = ShotContext { sim: Some(&s), window: window(), segment: Some(seg), forest_type: None };
        let (rows, _) = run(&shot(), &ctx);
        assert_eq!(rows[0].vertical_reference, VerticalReference::GeoidAndCollocation { geoid_offset: 50.0, dz: 0.4 });
        assert_eq!(rows[0].r_collocation, Some(0.97));
        assert!((rows[0].vertical_reference.to_als_datum(349.0) - 298.6).abs() < 1e-12);
    }

    #[test]
    fn each_filter_removes_what_it_should_counted_at_the_first_failure() {
        let s = sims();
        let full = ShotContext { sim: Some(&s), window: window(), segment: None, forest_type: None };
        // Not simulated: every row to als_coverage, even with bad GEDI quality.
        let mut bad = shot();
        bad.degrade_flag = Some(1);
        let (rows, c) = run(&bad, &ShotContext { sim: None, ..full.clone() });
        assert!(rows.is_empty());
        assert_eq!(c.removed_by(Filter::AlsCoverage), 21);
        assert_eq!(c.shots_kept, 0);
        // Partly covered simulation: same.
        let mut partial = sims();
        partial.iter_mut().for_each(|w| w.ok = false);
        let (_, c) = run(&shot(), &ShotContext { sim: Some(&partial), ..full.clone() });
        assert_eq!(c.removed_by(Filter::AlsCoverage), 21);
        // Degraded shot: every row to quality.
        let (_, c) = run(&bad, &full);
        assert_eq!(c.removed_by(Filter::Quality), 21);
        // a3 quality 0, a4 sensitivity 0.85, a5 without RH: 3 rows each.
        let mut s3 = shot();
        s3.algorithms[3].quality_flag = Some(0);
        s3.algorithms[4].sensitivity = Some(0.85);
        s3.algorithms[5].rh = None;
        let (rows, c) = run(&s3, &full);
        assert_eq!(
            (
                c.removed_by(Filter::Quality),
                c.removed_by(Filter::Sensitivity),
                c.removed_by(Filter::GediValues),
                c.kept
            ),
            (3, 3, 3, 12)
        );
        assert_eq!(rows.len(), 12);
        assert!(rows.iter().all(|r| !matches!(r.algorithm, StudyAlgorithm::A(3..=5))));
        // Cover 1 in frac, RH100 70 m in int: 7 rows each.
        let mut odd = sims();
        odd[1].als_cover = Some(1.0);
        odd[2].rh = Some(rh(70.0));
        let (rows, c) = run(&shot(), &ShotContext { sim: Some(&odd), ..full.clone() });
        assert_eq!((c.removed_by(Filter::AlsCover), c.removed_by(Filter::SimRh100), c.kept), (7, 7, 7));
        assert!(rows.iter().all(|r| r.weighting == "count"));
        // RH100 bounds are inclusive; 4.9 m is out.
        for (top, kept) in [(5.0, 21), (60.0, 21), (4.9, 0)] {
            let mut s = sims();
            s.iter_mut().for_each(|w| w.rh = Some(rh(top)));
            let (_, c) = run(&shot(), &ShotContext { sim: Some(&s), ..full.clone() });
            assert_eq!(c.kept, kept, "RH100 {top}");
        }
        // No geoid offset: nothing can be aligned.
        let mut nogeoid = shot();
        nogeoid.geoid_offset = None;
        let (_, c) = run(&nogeoid, &full);
        assert_eq!(c.removed_by(Filter::GediValues), 21);
        assert!(balanced(&c));
    }

    #[test]
    fn quality_and_sensitivity_filters_agree_with_passes_quality() {
        let s = sims();
        let ctx = ShotContext { sim: Some(&s), window: window(), segment: None, forest_type: None };
        for q in [None, Some(0), Some(1)] {
            for d in [None, Some(0), Some(3)] {
                for sens in [None, Some(0.5), Some(0.9), Some(0.96), Some(0.99), Some(f64::NAN)] {
                    let mut sh = shot();
                    sh.degrade_flag = d;
                    sh.algorithms.iter_mut().for_each(|a| {
                        a.quality_flag = q;
                        a.sensitivity = sens;
                    });
                    let (rows, _) = run(&sh, &ctx);
                    assert_eq!(!rows.is_empty(), passes_quality(q, d, sens), "{q:?} {d:?} {sens:?}");
                }
            }
        }
    }

    #[test]
    fn acquisition_window_with_margin_and_unknown_dates() {
        let s = sims();
        let w = window().unwrap();
        let ctx = ShotContext { sim: Some(&s), window: Some(w), segment: None, forest_type: None };
        let rules = StudyRules { max_days_apart: 30.0, ..Default::default() };
        let day = 86_400.0;
        for (offset_days, kept) in [(0.0, true), (29.9, true), (30.1, false), (-30.9, true), (-31.1, false)] {
            let mut sh = shot();
            sh.delta_time = Some(JUNE_2022_S + offset_days * day);
            let mut c = FilterCounts::default();
            let mut out = Vec::new();
            select_rows(&sh, &ctx, &rules, &mut c, &mut out);
            assert_eq!(!out.is_empty(), kept, "{offset_days} days after the window's end");
            if !kept {
                assert_eq!(c.removed_by(Filter::AcquisitionWindow), 21);
            }
        }
        // Unknown window or date: kept, and counted as not checked.
        let (rows, c) = run(&shot(), &ShotContext { window: None, ..ctx.clone() });
        assert_eq!((rows.len() as u64, c.window_unknown), (21, 21));
        let mut nodate = shot();
        nodate.delta_time = None;
        assert_eq!(run(&nodate, &ctx).1.window_unknown, 21);
    }

    #[test]
    fn window_of_the_tiles_holding_the_point() {
        let t = |x0: f64, s: Option<i64>, e: Option<i64>| TileWindow {
            xmin: x0,
            ymin: 0.0,
            xmax: x0 + 100.0,
            ymax: 100.0,
            start_us: s,
            end_us: e,
        };
        let tiles = [t(0.0, Some(10), Some(20)), t(50.0, Some(5), Some(15)), t(200.0, None, None)];
        assert_eq!(als_window(&tiles, 10.0, 10.0), Some(AlsWindow { start_us: 10, end_us: 20 }));
        assert_eq!(als_window(&tiles, 60.0, 10.0), Some(AlsWindow { start_us: 5, end_us: 20 }));
        assert_eq!(als_window(&tiles, 250.0, 10.0), None, "a tile without dates");
        assert_eq!(als_window(&tiles, 500.0, 10.0), None, "no tile");
    }

    #[test]
    fn counts_add_and_round_trip_through_json() {
        let mut a = FilterCounts::default();
        a.remove_shots(2, Filter::AlsCoverage);
        assert_eq!((a.shots, a.candidates, a.removed_by(Filter::AlsCoverage)), (2, 42, 42));
        let s = sims();
        let ctx = ShotContext { sim: Some(&s), window: None, segment: None, forest_type: None };
        let mut out = Vec::new();
        select_rows(&shot(), &ctx, &StudyRules::default(), &mut a, &mut out);
        let mut total = FilterCounts::default();
        total.add(&a);
        total.add(&a);
        assert_eq!(
            (total.shots, total.candidates, total.kept, total.shots_kept, total.window_unknown),
            (6, 126, 42, 2, 42)
        );
        assert!(balanced(&total));
        assert_eq!(FilterCounts::from_json(&total.to_json()), Some(total));
        assert_eq!(FilterCounts::from_json(&serde_json::json!({"shots": 1})), None);
    }
}
