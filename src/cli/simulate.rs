//! `gedisim simulate`.

use std::path::PathBuf;
use std::time::Instant;

use clap::Args;

use gedisim::dataset::Dataset;
use gedisim::{Error, Result};

use super::reporters::{peak_rss_mb, progress};

#[derive(Args)]
pub struct SimulateArgs {
    /// LAS/LAZ file (direct mode).
    #[arg(long, requires_all = ["footprints", "out"], conflicts_with = "dataset")]
    pub als: Option<PathBuf>,
    /// CSV with a header naming id, x, y (direct mode; in dataset mode, footprints to simulate
    /// instead of the ingested shots, e.g. inventory plots).
    #[arg(long)]
    pub footprints: Option<PathBuf>,
    /// Output Parquet file (direct mode; dataset mode with --footprints, default
    /// <dataset>/sim/<CSV name>.parquet).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Dataset directory: simulate every ingested shot into <dataset>/sim/shots.parquet (or the
    /// --footprints) from the ingested ALS points.
    #[arg(long)]
    pub dataset: Option<PathBuf>,
    /// gedirat reproduces Hancock's gediRat exactly (batch-dependent bin grid, every point of
    /// every class); default fixes its slips.
    #[arg(long, value_enum, default_value = "default")]
    pub profile: ProfileArg,
    /// Pulse: `gaussian` (FWHM 15 ns unless --psigma) or a two-column pulse file (range m, amplitude).
    #[arg(long, default_value = "gaussian")]
    pub pulse: String,
    /// Turn off ALS density normalisation.
    #[arg(long)]
    pub no_norm: bool,
    /// Footprint Gaussian σ (m).
    #[arg(long, default_value_t = 5.5)]
    pub fsigma: f32,
    /// Gaussian pulse σ (m) instead of the 15 ns FWHM.
    #[arg(long)]
    pub psigma: Option<f32>,
    /// Convolve each return with the pulse while binning instead of after.
    #[arg(long)]
    pub pulse_before: bool,
    /// Direct mode with the default profile: keep the classes that ingest drops (7, 18, 64–67).
    #[arg(long)]
    pub keep_all_classes: bool,
    /// Print wall time, waveforms/s and peak memory at the end.
    #[arg(long)]
    pub stats: bool,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum ProfileArg {
    Gedirat,
    Default,
}

pub fn simulate(a: SimulateArgs) -> Result<()> {
    use gedisim::kernels::sim::{self, Profile, PulseTiming, SimConfig};
    let profile = match a.profile {
        ProfileArg::Gedirat => Profile::Gedirat,
        ProfileArg::Default => Profile::Default,
    };
    let mut cfg = SimConfig::new(profile);
    cfg.fsigma = a.fsigma;
    cfg.normalise_density = !a.no_norm;
    if a.pulse_before {
        cfg.pulse_timing = PulseTiming::BeforeBinning;
    }
    cfg.pulse = match (a.pulse.as_str(), a.psigma) {
        ("gaussian", Some(s)) => sim::Pulse::gaussian(s, cfg.res as f32)?,
        ("gaussian", None) => cfg.pulse,
        (file, _) => {
            let path = PathBuf::from(file);
            let text = std::fs::read_to_string(&path).map_err(|e| Error::file(&path, format!("cannot read pulse file: {e}")))?;
            let pairs = sim::pulse::parse_pulse_text(&text).map_err(|e| Error::field(&path, "pulse", e))?;
            sim::Pulse::tabulated(&pairs).map_err(|e| Error::field(&path, "pulse", e))?
        }
    };
    let start = Instant::now();
    let (ok, skipped, out) = if let Some(dir) = a.dataset {
        let ds = Dataset::open(&dir)?;
        let (footprints, dest) = match &a.footprints {
            Some(csv) => {
                let stem = csv.file_stem().and_then(|s| s.to_str()).unwrap_or("footprints");
                let dest = match &a.out {
                    Some(out) => out.clone(),
                    None => ds.table_file(gedisim::dataset::tables::SIM, stem)?,
                };
                (gedisim::io::footprints::read_footprints_csv(csv)?.into_iter().map(|f| (f, None)).collect(), dest)
            }
            None if a.out.is_some() => return Err(Error::Usage("--out in dataset mode needs --footprints".into())),
            None => (gedisim::ops::simulate::shot_footprints(&ds)?, ds.table_file(gedisim::dataset::tables::SIM, "shots")?),
        };
        let bar = progress(footprints.len() as u64, "footprints");
        let r = gedisim::ops::simulate::simulate_on_dataset(&ds, footprints, &cfg, profile, &dest, &|k| bar.inc(k as u64));
        bar.finish_and_clear();
        let (ok, skipped) = r?;
        (ok, skipped, dest)
    } else {
        let (Some(als_path), Some(fp_path), Some(out)) = (a.als, a.footprints, a.out) else {
            return Err(Error::Usage("give --als, --footprints and --out (direct mode) or --dataset".into()));
        };
        let footprints = gedisim::io::footprints::read_footprints_csv(&fp_path)?;
        let mut points = gedisim::io::las::read_points(&als_path)?;
        if profile == Profile::Default && !a.keep_all_classes {
            points = gedisim::ops::simulate::drop_ingest_classes(&points);
        }
        let (ok, skipped) = gedisim::ops::simulate::simulate_direct(&points, &footprints, &cfg, profile, &out)?;
        (ok, skipped, out)
    };
    eprintln!("{ok} footprints simulated, {skipped} skipped (see the status column) → {}", out.display());
    if a.stats {
        let s = start.elapsed().as_secs_f64();
        println!(
            "simulate: {} footprints × {} weightings, {s:.3} s, {:.1} footprints/s, peak RSS {:.1} MB",
            ok + skipped,
            gedisim::kernels::sim::N_WEIGHTINGS,
            (ok + skipped) as f64 / s,
            peak_rss_mb()
        );
    }
    Ok(())
}
