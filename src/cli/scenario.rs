//! `gedisim scenario`.

use std::path::PathBuf;
use tracing::{info, warn};

use clap::Args;

use gedisim::{Error, Result};

#[derive(Args)]
pub struct ScenarioArgs {
    /// Withheld effect: none, geolocation, datum, weighting, pulse, footprint, noise,
    /// canopy_change, occlusion, ground_detection, or a pair such as datum+pulse.
    #[arg(long)]
    effect: String,
    /// Scale of the main parameter's departure from nominal (1 = the realistic default).
    #[arg(long, allow_hyphen_values = true)]
    magnitude: Option<f64>,
    /// Effect parameter as key=value (repeatable), e.g. --param dz_m=0.8; effect.key for a pair.
    #[arg(long = "param", value_name = "KEY=VALUE")]
    params: Vec<String>,
    /// Seed of every random draw (same seed, same granules).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// LAS/LAZ files or folders (default: the three bundled LiDAR HD tiles, embedded in the binary).
    #[arg(long, num_args = 1..)]
    als: Vec<PathBuf>,
    /// Output folder: als/, gedi/, truth.json.
    #[arg(long)]
    out: PathBuf,
    /// Granules (passes, eight beams each) crossing each tile.
    #[arg(long, default_value_t = 8)]
    passes: usize,
    /// Nominal geoid height N (m) stored in geophys_corr/geoid.
    #[arg(long, allow_hyphen_values = true, default_value_t = gedisim::ops::scenario::DEFAULT_GEOID_M)]
    geoid: f64,
    /// RMS per axis of the random horizontal offset of each track (m).
    #[arg(long, default_value_t = 3.0)]
    offset_sigma: f64,
    /// CRS (EPSG code) of tiles that carry none [default: 2154, with a warning].
    #[arg(long)]
    epsg: Option<u32>,
    /// Replace a world already in --out.
    #[arg(long)]
    force: bool,
}

pub fn scenario(a: ScenarioArgs) -> Result<()> {
    let params = a
        .params
        .iter()
        .map(|p| {
            p.split_once('=')
                .map(|(k, v)| (k.trim().to_string(), v.trim().to_string()))
                .ok_or_else(|| Error::Usage(format!("--param {p}: expected key=value")))
        })
        .collect::<Result<Vec<_>>>()?;
    let opts = gedisim::ops::scenario::ScenarioOptions {
        effect_spec: a.effect.clone(),
        magnitude: a.magnitude,
        params,
        seed: a.seed,
        tiles: a.als.clone(),
        out: a.out.clone(),
        passes_per_tile: a.passes,
        geoid_m: a.geoid,
        track_offset_sigma_m: a.offset_sigma,
        default_epsg: a.epsg,
        force: a.force,
    };
    let r = gedisim::ops::scenario::make_scenario(&opts)?;
    r.notes.iter().for_each(|n| warn!("{n}"));
    info!(
        "scenario {}: {} tiles, {} granules, {} tracks, {} shots ({} dropped) → {}",
        a.effect,
        r.tiles,
        r.granules,
        r.tracks,
        r.shots,
        r.dropped,
        r.truth.display()
    );
    Ok(())
}
