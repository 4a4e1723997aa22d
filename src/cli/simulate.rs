//! `gedisim simulate`.

use std::path::PathBuf;
use std::time::Instant;
use tracing::{info, warn};

use clap::Args;

use gedisim::kernels::sim::footprint::GEDI_SIGMA_M;
use gedisim::kernels::sim::PulseModel;
use gedisim::{Error, Result};

use super::reporters::{peak_rss_mb, Bars};

#[derive(Args)]
pub struct SimulateArgs {
    /// LAS/LAZ files, folders holding them, or https:// and s3:// URLs (direct mode); a COPC file
    /// is decoded only around the footprints, a file no footprint reaches is not read.
    #[arg(long, num_args = 1.., requires_all = ["footprints", "out"], conflicts_with = "dataset")]
    als: Vec<PathBuf>,
    /// CSV of footprints: an id (id, plot_id, …) and x, y or lon, lat columns; `,` `;` or tab
    /// separated (direct mode; in dataset mode, footprints to simulate instead of the ingested
    /// shots, e.g. inventory plots).
    #[arg(long)]
    footprints: Option<PathBuf>,
    /// EPSG code of the footprints' x, y (e.g. 2154 or EPSG:2154), reprojected to the ALS CRS when
    /// it differs (default: the ALS CRS, said on stderr). lon, lat columns are WGS84 degrees.
    #[arg(long, value_name = "EPSG", value_parser = parse_epsg)]
    crs: Option<u32>,
    /// Output Parquet file (direct mode; dataset mode with --footprints, default
    /// <dataset>/simulated/<CSV name>.parquet).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Dataset directory: simulate every ingested shot into <dataset>/simulated/shots.parquet (or
    /// the --footprints) from the ingested ALS points (`sim/` is `run`'s alone).
    #[arg(long)]
    dataset: Option<PathBuf>,
    /// gedirat reproduces Hancock's gediRat exactly (batch-dependent bin grid, every point of
    /// every class); default fixes its slips.
    #[arg(long, value_enum, default_value = "default")]
    profile: ProfileArg,
    #[command(flatten)]
    pulse: PulseArgs,
    /// Turn off ALS density normalisation.
    #[arg(long)]
    no_norm: bool,
    /// What the density normalisation counts: last-returns (gediRat: each return divided by the
    /// last returns of its own 1.5 m cell) or pulses (each pulse counted once at its first
    /// return, its returns sharing that count: the diagnosis's nominal physics, docs/diagnosis.md).
    #[arg(long, value_enum, default_value = "last-returns", conflicts_with = "no_norm")]
    density: DensityArg,
    /// Footprint Gaussian σ (m).
    #[arg(long, default_value_t = GEDI_SIGMA_M, allow_negative_numbers = true)]
    #[arg(value_parser = super::values::footprint_sigma)]
    fsigma: f32,
    /// Gaussian pulse σ (m) instead of the 15 ns FWHM.
    #[arg(long, allow_negative_numbers = true, value_parser = super::values::pulse_sigma)]
    psigma: Option<f32>,
    /// Convolve each return with the pulse while binning instead of after.
    #[arg(long)]
    pulse_before: bool,
    /// Direct mode with the default profile: keep the classes that ingest drops (7, 18, 64–67).
    #[arg(long)]
    keep_all_classes: bool,
    /// Print wall time, waveforms/s and peak memory at the end.
    #[arg(long)]
    stats: bool,
    /// Dataset mode: simulate on the Ballista cluster whose scheduler is at this address
    /// (`gedisim cluster`), the profile's settings only; every node must see the dataset.
    #[arg(long, value_name = "df://HOST:PORT", requires = "dataset")]
    cluster: Option<String>,
}

/// The transmit pulse of a command (docs/pulse.md); each command has its own default.
#[derive(Args)]
pub struct PulseArgs {
    /// Transmit pulse: `gaussian` (15 ns FWHM, the study's), `recorded` (each shot's L1B
    /// txwaveform; positions without a shot use the mean recorded pulse) or a two-column pulse
    /// file (range m, amplitude) [default: recorded for collocate and diagnose, gaussian otherwise].
    #[arg(long)]
    pulse: Option<String>,
    /// Point of a recorded pulse that lands on the reflecting surface: gaussian-fit (L1B tx_gloc),
    /// centroid or peak.
    #[arg(long, default_value = "gaussian-fit", value_parser = REFERENCES)]
    pulse_reference: String,
}

const REFERENCES: [&str; 3] = ["gaussian-fit", "centroid", "peak"];

impl PulseArgs {
    /// The pulse model, `default` (`gaussian` or `recorded`) when --pulse is not given.
    pub fn model(&self, default: &str, psigma: Option<f32>) -> PulseModel {
        let reference = self.pulse_reference.parse().unwrap_or_default();
        PulseModel::parse(self.pulse.as_deref().unwrap_or(default), psigma, reference)
    }
}

#[derive(Clone, Copy, PartialEq, clap::ValueEnum)]
pub enum DensityArg {
    LastReturns,
    Pulses,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum ProfileArg {
    Gedirat,
    Default,
}

pub fn simulate(a: SimulateArgs) -> Result<()> {
    use gedisim::kernels::sim::{DensityCount, Profile};
    use gedisim::ops::simulate::{SimulateOptions, Source};
    let als_input = a.als.clone();
    let source = match (a.dataset, a.als) {
        (Some(dataset), _) => Source::Dataset { dataset, footprints: a.footprints, out: a.out },
        (None, als) if !als.is_empty() => {
            let (Some(footprints), Some(out)) = (a.footprints, a.out) else {
                return Err(Error::Usage("give --als, --footprints and --out (direct mode) or --dataset".into()));
            };
            Source::Direct { als, footprints, out, keep_all_classes: a.keep_all_classes }
        }
        (None, _) => return Err(Error::Usage("give --als, --footprints and --out (direct mode) or --dataset".into())),
    };
    let opts = SimulateOptions {
        source,
        profile: match a.profile {
            ProfileArg::Gedirat => Profile::Gedirat,
            ProfileArg::Default => Profile::Default,
        },
        fsigma: a.fsigma,
        normalise_density: !a.no_norm,
        density_count: match a.density {
            DensityArg::LastReturns => DensityCount::LastReturns,
            DensityArg::Pulses => DensityCount::Pulses,
        },
        pulse_before: a.pulse_before,
        pulse: a.pulse.model("gaussian", a.psigma),
        engine: a.cluster.map(gedisim::ops::simulate::Engine::Cluster).unwrap_or_default(),
        footprints_crs: a.crs,
    };
    let start = Instant::now();
    let r = gedisim::ops::simulate::simulate(&opts, &Bars::new())?;
    if let Some(p) = &r.placement {
        info!("{p}");
    }
    info!("{} footprints simulated, {} skipped (see the status column) → {}", r.simulated, r.skipped, r.out.display());
    if r.outside_files > 0 {
        warn!(
            "{} footprint(s) lie outside every --als file's header bounds (status no_points unless a neighbouring \
             file's points reach them): if the points are there, a header's bounds are wrong; `gedisim ingest als` \
             takes the points' own extent",
            r.outside_files
        );
    }
    if let Some(c) = &r.copc {
        info!("COPC: {c}, {} points within the footprints' read radius", c.points_kept);
    }
    super::reporters::print_fetched(&als_input);
    if a.stats {
        let s = start.elapsed().as_secs_f64();
        let n = r.simulated + r.skipped;
        println!(
            "simulate: {n} footprints × {} weightings, {s:.3} s, {:.1} footprints/s, peak RSS {:.1} MB",
            gedisim::kernels::sim::N_STUDY_WEIGHTINGS,
            n as f64 / s,
            peak_rss_mb()
        );
    }
    Ok(())
}

/// `2154` or `EPSG:2154`.
fn parse_epsg(s: &str) -> std::result::Result<u32, String> {
    let code = s.trim();
    let code = code.strip_prefix("EPSG:").or_else(|| code.strip_prefix("epsg:")).unwrap_or(code);
    code.parse().map_err(|_| format!("`{s}` is not an EPSG code (e.g. 2154 or EPSG:2154)"))
}
