//! `gedisim demo`: the study end to end on the bundled LiDAR HD tiles (embedded in the binary,
//! `io::bundled`) with GEDI granules generated for them by the scenario generator: `scenario` →
//! `run` → `diagnose` → `report`, then the headline tables. `<out>/world/` holds the world (tiles,
//! granules, truth.json), `<out>/dataset/` the dataset and `<out>/dataset/report/` the report.
//! Re-running with the same effect and seed reuses the world, and `run` finds nothing new.

use std::path::{Path, PathBuf};

use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::kernels::collocate::segments::Level;
use crate::kernels::scenario::truth::Truth;
use crate::kernels::scenario::EffectSet;
use crate::ops::collocate::CollocateOptions;
use crate::ops::progress::{Progress, Step};
use crate::ops::report::headline::Headline;
use crate::ops::report::ReportSummary;
use crate::ops::run::{run_study, RunOptions, RunReport};
use crate::ops::scenario::{make_scenario, ScenarioOptions, ScenarioReport, DEFAULT_GEOID_M};

/// Options of `gedisim demo`.
#[derive(Debug, Clone)]
pub struct DemoOptions {
    /// Output folder: `world/`, `dataset/`.
    pub out: PathBuf,
    /// The scenario's withheld effect (`ground_detection` by default).
    pub effect: String,
    pub seed: u64,
    /// Granules per tile.
    pub passes: usize,
    /// Replace a world of another effect or seed in `out`.
    pub force: bool,
}

impl Default for DemoOptions {
    fn default() -> Self {
        DemoOptions {
            out: PathBuf::from("gedisim-demo"),
            effect: "ground_detection".into(),
            seed: 1,
            passes: 8,
            force: false,
        }
    }
}

/// What the demo did.
#[derive(Debug, Clone)]
pub struct DemoReport {
    /// The world built (`None`: the one in `<out>/world` was reused).
    pub world: Option<ScenarioReport>,
    pub world_dir: PathBuf,
    pub run: RunReport,
    pub report: ReportSummary,
    pub headline: Headline,
    /// The diagnosis of the world, in `<out>/diagnosis/`.
    pub diagnosis: crate::ops::diagnose::DiagnosisOutput,
}

/// The world's folder and the dataset's.
pub fn layout(out: &Path) -> (PathBuf, PathBuf) {
    (out.join("world"), out.join("dataset"))
}

/// Collocation of the demo: the bundled tiles are 50–100 m wide, so each beam of a granule
/// crosses a tile with 0–3 shots, fewer than a beam segment's default minimum (20): every run is
/// solved (`min_segment` 1), one offset per beam of a granule.
pub fn demo_collocation() -> CollocateOptions {
    CollocateOptions { level: Level::Beam, min_segment: 1, ..CollocateOptions::default() }
}

/// scenario → run → report → diagnose on the bundled tiles.
pub fn run_demo(opts: &DemoOptions, progress: &dyn Progress) -> Result<DemoReport> {
    // A bad --effect fails here, before any folder is touched.
    EffectSet::parse(&opts.effect, None, &[]).map_err(|e| Error::Usage(e.to_string()))?;
    let (world_dir, ds_dir) = layout(&opts.out);
    let truth = world_dir.join("truth.json");
    let mut reuse = false;
    if truth.exists() {
        let t: Truth = std::fs::read_to_string(&truth)
            .ok()
            .and_then(|s| serde_json::from_str(&s).ok())
            .ok_or_else(|| Error::file(&truth, "not a scenario truth file"))?;
        let same =
            t.effect_spec == opts.effect && t.seed == opts.seed && t.granules.len() == t.tiles.len() * opts.passes;
        if same {
            reuse = true;
        } else if opts.force {
            for d in [&world_dir, &ds_dir] {
                if d.exists() {
                    std::fs::remove_dir_all(d)
                        .map_err(|e| Error::file(d, format!("cannot remove the previous demo: {e}")))?;
                }
            }
        } else {
            return Err(Error::file(
                &opts.out,
                format!(
                    "holds a demo of effect {}, seed {}; use --force to replace it, or another --out",
                    t.effect_spec, t.seed
                ),
            ));
        }
    }
    let world = if reuse {
        None
    } else {
        progress.start(Step::Scenario, 0);
        let r = make_scenario(&ScenarioOptions {
            effect_spec: opts.effect.clone(),
            magnitude: None,
            params: Vec::new(),
            seed: opts.seed,
            tiles: Vec::new(),
            out: world_dir.clone(),
            passes_per_tile: opts.passes,
            geoid_m: DEFAULT_GEOID_M,
            track_offset_sigma_m: 3.0,
            default_epsg: None,
            force: true,
        });
        progress.finish();
        Some(r?)
    };
    let gedi = world_dir.join("gedi");
    let run_opts = RunOptions {
        als: vec![world_dir.join("als")],
        l1b: vec![gedi.clone()],
        l2a: vec![gedi],
        collocate: demo_collocation(),
        ..RunOptions::new(&ds_dir)
    };
    let run = run_study(&run_opts, progress)?;
    let ds = Dataset::open(&ds_dir)?;
    // The diagnosis of the world, told nothing about the withheld effect; then the report, which
    // shows it.
    let diagnosis_dir = opts.out.join("diagnosis");
    let diagnosis = crate::ops::diagnose::diagnose_dataset(&ds, &diagnosis_dir, &Default::default(), progress)?;
    let report_opts = crate::ops::report::ReportOptions { out: None, diagnosis: Some(diagnosis_dir) };
    let report = crate::ops::report::run_report(&ds, &report_opts, &Default::default(), progress)?;
    let headline = Headline {
        vertical_references: crate::dataset::results::vertical_references(&ds)?,
        ..Headline::read(&report.dir)?
    };
    Ok(DemoReport { world, world_dir, run, report, headline, diagnosis })
}
