//! `gedisim diagnose`: reads a dataset's shots (and their per-beam collocation offsets, strata)
//! and ALS points into [`diagnose::ShotCase`]s, runs the kernels of [`crate::kernels::diagnose`], and writes
//! `<out>/diagnosis.json`, its tables (Parquet + CSV) and figures (PNG + SVG). docs/diagnosis.md.
//!
//! By step: [`cases`] reads the shots and plans their sites, [`sites`] simulates them, the kernels
//! diagnose, [`write`] writes the tables and figures and [`summary`] the summary lines; [`key`]
//! decides whether a diagnosis already written can be reused. Here: the options and the order of
//! the steps.

mod cases;
mod key;
mod sites;
mod summary;
mod write;

pub use cases::{read_cases, CaseReport, Cases};
use key::{inputs_key, reusable};
pub use summary::{params_text, summary_lines};
use write::{write_figures, write_tables};

use std::path::{Path, PathBuf};

use crate::dataset::{tables, Dataset};
use crate::error::{Error, Result};
use crate::kernels::collocate::segments::Level;
use crate::kernels::diagnose::case::{FSIGMA_GRID, RECOLLOCATE_SHIFT_M, SITE_HALF, SITE_STEP_M};
use crate::kernels::diagnose::json::DiagnosisJson;
use crate::kernels::diagnose::{self};
use crate::kernels::scenario::effects::EffectKind;
use crate::kernels::sim::{self, PulseModel};
use crate::ops::collocate::{CollocateOptions, CollocateReport};
use crate::ops::progress::{Progress, Step};
use crate::ops::run::{RunOptions, RunReport};

/// What `diagnose` wrote (or found already written for the same inputs).
#[derive(Debug, Clone)]
pub struct DiagnosisOutput {
    pub json: DiagnosisJson,
    pub files: Vec<PathBuf>,
    /// The inputs were those of the diagnosis already in the folder: nothing was recomputed.
    pub reused: bool,
}

/// every run solved however short, with the diagnosis's pulse.
pub fn diagnosis_collocation(pulse: &PulseModel) -> CollocateOptions {
    CollocateOptions {
        level: Level::Beam,
        segment: 40,
        max_shift: 10.0,
        step: 1.0,
        min_segment: 1,
        pulse: pulse.clone(),
    }
}

/// Half-width (m) of the ALS window a shot's case needs: the largest shift of its sites' centre
/// (the collocation's, or a short segment's re-collocation around the reported position), the
/// grid of sites around it, and the read radius of the widest footprint tried.
pub fn window_half(max_shift: f64) -> f64 {
    let fmax = FSIGMA_GRID[FSIGMA_GRID.len() - 1] as f32;
    max_shift.max(RECOLLOCATE_SHIFT_M) + f64::from(SITE_HALF) * SITE_STEP_M + sim::footprint::read_radius(fmax)
}

/// What `gedisim diagnose` reads.
#[derive(Debug, Clone)]
pub enum DiagnoseInput {
    /// A dataset after `gedisim run` (or at least both ingests; collocated first if it has no
    /// offsets).
    Dataset(PathBuf),
    /// The first half of `gedisim run` into `<out>/dataset` (its `out` and `collocate` are set
    /// here): tiles, granules and land cover ingested, collocated per beam.
    Chain(Box<RunOptions>),
}

/// What `gedisim diagnose` did.
#[derive(Debug, Clone)]
pub struct DiagnoseReport {
    /// The ingest and collocation of [`DiagnoseInput::Chain`].
    pub chain: Option<RunReport>,
    /// The collocation of a dataset that had no offsets.
    pub collocated: Option<CollocateReport>,
    pub output: DiagnosisOutput,
}

/// What a diagnosis is asked for.
#[derive(Debug, Clone)]
pub struct DiagnoseOptions {
    /// The effects tried (names of `diagnose::fit::FITTED_EFFECTS`; empty = all).
    pub effects: Vec<String>,
    /// The shots' transmit pulse in the nominal chain.
    pub pulse: PulseModel,
    /// Twin sets per planted hypothesis in the self-test (`diagnose::selftest`); 0 = none.
    pub twins: usize,
    /// The configuration, the effects and the self-test on the shots of tracks drawn up to this
    /// many shots (`diagnose::sample`); 0 = every shot.
    pub ranked_shots: usize,
    /// Diagnose again even when `out` holds the diagnosis of the same inputs.
    pub force: bool,
}

impl DiagnoseOptions {
    /// Every effect, each shot's recorded pulse, the default self-test.
    pub fn new() -> DiagnoseOptions {
        DiagnoseOptions {
            effects: Vec::new(),
            pulse: PulseModel::Recorded(Default::default()),
            twins: diagnose::selftest::TWINS,
            ranked_shots: diagnose::sample::RANKED_SHOTS,
            force: false,
        }
    }
}

impl Default for DiagnoseOptions {
    fn default() -> Self {
        DiagnoseOptions::new()
    }
}

/// `gedisim diagnose`: the dataset (made or collocated first when needed) diagnosed into `out`.
pub fn diagnose(
    input: DiagnoseInput,
    out: &Path,
    opts: &DiagnoseOptions,
    progress: &dyn Progress,
) -> Result<DiagnoseReport> {
    let pulse = &opts.pulse;
    // What this command writes into a dataset (the chain's tables, a missing `offsets/`) it writes
    // as the dataset's one writer: the lock is held until the diagnosis ends.
    let (ds, chain) = match input {
        DiagnoseInput::Dataset(root) => {
            let ds = Dataset::open(&root)?;
            let ds = if ds.has_table(tables::OFFSETS) { ds } else { ds.as_writer()? };
            (ds, None)
        }
        DiagnoseInput::Chain(opts) => {
            let collocate = diagnosis_collocation(pulse);
            let als_window = Some(window_half(collocate.max_shift));
            let opts = RunOptions { out: out.join("dataset"), collocate, als_window, ..*opts };
            let (ds, report) = crate::ops::run::ingest_and_collocate(&opts, progress)?;
            (ds, Some(report))
        }
    };
    let collocated = if ds.has_table(tables::OFFSETS) {
        None
    } else {
        Some(crate::ops::collocate::collocate(&ds, &diagnosis_collocation(pulse), progress)?)
    };
    let output = diagnose_dataset(&ds, out, opts, progress)?;
    Ok(DiagnoseReport { chain, collocated, output })
}

/// Diagnose the dataset into `out`: its cases read and simulated, then each effect fitted and
/// scored as one [`Step::DiagnoseFit`] (each effect a note) — unless `out` holds the diagnosis
/// of the same inputs ([`inputs_key`]) and `opts.force` is false, which is then returned as it is.
pub fn diagnose_dataset(
    ds: &Dataset,
    out: &Path,
    opts: &DiagnoseOptions,
    progress: &dyn Progress,
) -> Result<DiagnosisOutput> {
    let (effects, pulse) = (&opts.effects, &opts.pulse);
    let kinds: Vec<EffectKind> = if effects.is_empty() {
        diagnose::fit::FITTED_EFFECTS.to_vec()
    } else {
        effects
            .iter()
            .map(|e| {
                EffectKind::from_name(e).filter(|k| diagnose::fit::FITTED_EFFECTS.contains(k)).ok_or_else(|| {
                    Error::Usage(format!(
                        "--effects: '{e}' is not an effect the diagnosis fits (known: {})",
                        diagnose::fit::FITTED_EFFECTS.map(EffectKind::name).join(", ")
                    ))
                })
            })
            .collect::<Result<_>>()?
    };
    let key = inputs_key(ds, &kinds, opts)?;
    if let Some(done) = reusable(out, &key).filter(|_| !opts.force) {
        return Ok(done);
    }
    let Cases { ranked: cases, located, report } = read_cases(ds, pulse, opts.ranked_shots, progress)?;
    if cases.len() < 4 {
        return Err(Error::file(
            ds.root().join(tables::SHOTS),
            format!(
                "only {} usable shot(s) for the diagnosis (need ≥ 4): {}",
                cases.len(),
                dropped_text(&report.dropped)
            ),
        ));
    }
    progress.start(Step::DiagnoseFit, 0);
    let d = diagnose::diagnose(cases, &located, &kinds, opts.twins, &|step| progress.note(step));
    drop(located);
    progress.finish();
    std::fs::create_dir_all(out).map_err(|e| Error::file(out, e))?;
    // The old diagnosis.json goes first: tables half rewritten by an interrupted run are never
    // taken for those of the earlier key.
    let path = out.join("diagnosis.json");
    if path.exists() {
        std::fs::remove_file(&path).map_err(|e| Error::file(&path, e))?;
    }
    let mut files = write_tables(&d, out)?;
    files.extend(write_figures(&d, out)?);
    let names = files.iter().filter_map(|f| f.file_name().map(|n| n.to_string_lossy().into_owned())).collect();
    let json = DiagnosisJson {
        summary: summary_lines(&d),
        dataset: Some(ds.root().canonicalize().unwrap_or_else(|_| ds.root().to_path_buf()).display().to_string()),
        inputs_key: Some(key),
        files: names,
        ..DiagnosisJson::of(&d, report.shots_read, &report.dropped, opts.ranked_shots)
    };
    // diagnosis.json last: a diagnosis interrupted before it is never reused.
    let text = serde_json::to_string_pretty(&json).map_err(|e| Error::file(&path, e))?;
    crate::dataset::write_atomic(&path, text.as_bytes())?;
    files.push(path);
    Ok(DiagnosisOutput { json, files, reused: false })
}

/// "reason (n), …" of (reason, count) pairs.
pub fn dropped_text<S: AsRef<str>>(dropped: &[(S, usize)]) -> String {
    if dropped.is_empty() {
        return "none dropped".into();
    }
    dropped.iter().map(|(k, n)| format!("{} ({n})", k.as_ref())).collect::<Vec<_>>().join(", ")
}
