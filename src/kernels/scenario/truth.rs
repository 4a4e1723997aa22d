//! `truth.json`, everything a world planted (docs/scenario.md): one set of serde types shared by
//! its writer (`ops::scenario`) and its readers (`ops::demo`, the benchmarks, the tests). For
//! scoring only: the diagnosis never reads it.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::effects::{Effect, ParamValue};

/// The `format` of a truth file this version writes.
pub const TRUTH_FORMAT: &str = "gedisim-scenario-truth/1";

/// A world's truth file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Truth {
    pub format: String,
    /// Effect name(s), `a+b` for a pair, `none` for a control.
    pub effect: String,
    /// The `--effect` text as given.
    pub effect_spec: String,
    pub effects: Vec<PlantedEffect>,
    pub magnitude: Option<f64>,
    /// `--param` pairs as given.
    pub params_given: Vec<(String, String)>,
    pub seed: u64,
    pub physics: TruePhysics,
    pub geoid: GeoidTruth,
    /// GEDI elevation − (ALS height + N), m: the `datum` effect's offset (0 otherwise).
    pub datum_dz_m: f64,
    pub noise: NoiseTruth,
    pub geolocation: GeolocationTruth,
    /// Offset added to the L2A ground of algorithms a1…a6 (m).
    pub ground_detection_offset_m: Vec<f64>,
    /// Distance a shot's footprint keeps inside its tile (m).
    pub margin_m: f64,
    pub n_shots: usize,
    pub n_dropped: usize,
    pub tiles: Vec<TileTruth>,
    pub granules: Vec<GranuleTruth>,
    pub tracks: Vec<TrackTruth>,
    pub shots: Vec<ShotTruthRecord>,
    pub dropped: Vec<DroppedShot>,
}

/// An effect with its parameters by contract name (docs/scenario.md): planted in truth.json, or
/// the simpler equivalent of a fitted effect in diagnosis.json.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlantedEffect {
    pub name: String,
    pub params: BTreeMap<String, ParamValue>,
}

impl PlantedEffect {
    pub fn of(e: &Effect) -> Self {
        PlantedEffect {
            name: e.name().to_string(),
            params: e.params().into_iter().map(|(k, v)| (k.to_string(), v)).collect(),
        }
    }

    /// A numeric parameter.
    pub fn number(&self, key: &str) -> Option<f64> {
        match self.params.get(key)? {
            ParamValue::Number(x) => Some(*x),
            ParamValue::Text(_) => None,
        }
    }
}

/// The true physics of the simulation (docs/scenario.md, "True physics").
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TruePhysics {
    pub weighting: String,
    pub rho_ground_over_veg: f64,
    /// The transmit pulse of every shot (recorded, and the reference point that lands on the surface).
    pub pulse: String,
    /// σ (m) of the system response beyond the transmit pulse (the `pulse` effect; 0 without).
    pub extra_pulse_sigma_m: f64,
    pub fsigma_m: f64,
    pub profile: String,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GeoidTruth {
    pub n_m: f64,
    pub dataset: String,
    pub relation: String,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoiseTruth {
    pub noise_sigma_factor: f64,
    /// Median `noise_stddev_corrected` of the real granule by beam type (DN).
    pub median_noise_stddev_corrected: BTreeMap<String, f64>,
    pub shape: String,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GeolocationTruth {
    pub convention: String,
    pub track_offset_sigma_m: f64,
    pub clip_sigmas: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TileTruth {
    /// Path of the copy, relative to the world (`als/<name>`).
    pub file: String,
    pub source: String,
    pub epsg: u32,
    /// [xmin, ymin, xmax, ymax] (m).
    pub extent: [f64; 4],
    pub points_used: usize,
    pub acquired_utc: Option<String>,
    pub leaf_off: bool,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GranuleTruth {
    /// Paths relative to the world (`gedi/<name>`).
    pub l1b: String,
    pub l2a: String,
    pub tile: usize,
    pub pass: usize,
    pub start_utc: String,
    pub orbit: u32,
    pub sub_orbit: u8,
    /// GEDI's reference ground track number (the file name's `T` field): the orbit's, not a track
    /// of this world.
    pub reference_track: u32,
    pub heading_deg: Option<f64>,
}

/// One track: one beam of one granule.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrackTruth {
    pub id: String,
    pub tile: usize,
    pub granule: usize,
    pub beam: String,
    pub beam_type: Option<String>,
    pub heading_deg: f64,
    /// True − reported position (m), as `collocate` reports offsets.
    pub dx: f64,
    pub dy: f64,
    pub n_shots: usize,
}

/// One shot written to the granules.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShotTruthRecord {
    pub shot_number: u64,
    pub track: String,
    /// Reported position (m).
    pub x: f64,
    pub y: f64,
    /// Where the waveform was formed (m).
    pub true_x: f64,
    pub true_y: f64,
    pub dx: f64,
    pub dy: f64,
    pub als_ground_m: Option<f64>,
    pub true_top_m: Option<f64>,
    pub gedi_ground_expected_m: Option<f64>,
    pub noise_stddev: Option<f64>,
    pub selected_algorithm: u8,
    pub quality_flag: u8,
}

/// A planned shot that was not written, and why.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DroppedShot {
    pub track: String,
    pub x: f64,
    pub y: f64,
    pub reason: String,
}

/// `Some(x)` when finite: JSON has no NaN.
pub fn finite(x: f64) -> Option<f64> {
    x.is_finite().then_some(x)
}
