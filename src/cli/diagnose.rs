//! `gedisim diagnose`.

use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use indicatif::ProgressBar;

use gedisim::dataset::Dataset;
use gedisim::{Error, Result};

use super::collocate::{collocate, CollocateArgs, LevelArg};
use super::reporters::{progress, Bars};
use super::run::{print_ingest_and_collocation, ChainArgs};

#[derive(Args)]
pub struct DiagnoseArgs {
    /// A dataset after `gedisim run` (or at least `ingest als`, `ingest gedi`; collocated here if it has no offsets).
    #[arg(long, conflicts_with_all = ["als", "l1b", "l2a"])]
    pub dataset: Option<PathBuf>,
    /// ALS tiles (files or folders): with --l1b and --l2a, the whole chain into <out>/dataset.
    #[arg(long, num_args = 1.., requires_all = ["l1b", "l2a"])]
    pub als: Vec<PathBuf>,
    /// L1B granules (files or folders).
    #[arg(long, num_args = 1..)]
    l1b: Vec<PathBuf>,
    /// L2A granules (files or folders).
    #[arg(long, num_args = 1..)]
    l2a: Vec<PathBuf>,
    #[command(flatten)]
    pub chain: ChainArgs,
    /// Output directory (diagnosis.json, tables, figures).
    #[arg(long)]
    pub out: PathBuf,
    /// Try only these effects (comma-separated; default: every effect the diagnosis fits).
    #[arg(long, value_delimiter = ',')]
    pub effects: Vec<String>,
}

/// Collocation of a dataset the diagnosis makes: per track (the baseline's horizontal collocation),
/// every run solved however short.
pub const DIAGNOSIS_COLLOCATION: gedisim::ops::collocate::CollocateOptions =
    gedisim::ops::collocate::CollocateOptions { level: gedisim::kernels::collocate::segments::Level::Beam, segment: 40, max_shift: 10.0, step: 1.0, min_segment: 1 };

pub fn diagnose(a: DiagnoseArgs) -> Result<()> {
    let start = Instant::now();
    let root = match &a.dataset {
        Some(d) => d.clone(),
        None => {
            if a.als.is_empty() {
                return Err(Error::Usage("give --dataset, or --als with --l1b and --l2a".into()));
            }
            // The first half of `gedisim run`, with the diagnosis's per-track collocation.
            let opts = gedisim::ops::run::RunOptions {
                als: a.als.clone(),
                l1b: a.l1b.clone(),
                l2a: a.l2a.clone(),
                landcover: a.chain.landcover.clone(),
                epsg: a.chain.epsg,
                geoid_offset: a.chain.geoid_offset,
                collocate: DIAGNOSIS_COLLOCATION,
                ..gedisim::ops::run::RunOptions::new(&a.out.join("dataset"))
            };
            print_ingest_and_collocation(&gedisim::ops::run::ingest_and_collocate(&opts, &Bars::new())?);
            opts.out
        }
    };
    let ds = Dataset::open(&root)?;
    if !ds.has_table(gedisim::dataset::tables::OFFSETS) {
        eprintln!("no offsets table: collocating per track first (the baseline's horizontal collocation)");
        let c = DIAGNOSIS_COLLOCATION;
        collocate(CollocateArgs {
            dataset: root.clone(),
            level: LevelArg::Beam,
            segment: c.segment,
            max_shift: c.max_shift,
            step: c.step,
            min_segment: c.min_segment,
            stats: false,
        })?;
    }
    let bar = progress(0, "shots");
    bar.set_message("simulating");
    let shots = ProgressBar::new_spinner();
    let out = gedisim::ops::diagnose::diagnose_dataset(&ds, &a.out, &a.effects, &|| bar.inc(1), &|step| {
        bar.finish_and_clear();
        shots.set_message(format!("fitting and scoring {step}"));
        shots.tick();
    });
    bar.finish_and_clear();
    shots.finish_and_clear();
    let out = out?;
    eprintln!("shots: {} read, {} used; dropped: {}", out.cases.shots_read, out.diagnosis.n_shots, gedisim::ops::diagnose::dropped_text(&out.cases));
    for line in gedisim::ops::diagnose::summary_lines(&out.diagnosis) {
        println!("{line}");
    }
    eprintln!("{} → {} ({:.1} s)", "diagnosis.json, tables, figures", a.out.display(), start.elapsed().as_secs_f64());
    Ok(())
}
