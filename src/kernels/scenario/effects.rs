//! The effect registry: every unmodelled effect a scenario can withhold, with its parameters, and
//! how it transforms the physics, the waveform, the geolocation or the L2A products.
//!
//! The same registry is meant for both sides of the sim-to-real check: the scenario generator
//! applies an effect to make the pseudo-real world, and the diagnosis applies the same effect to
//! its simulations when it tests a hypothesis. Each effect therefore acts through small pure
//! hooks ([`Effect::apply_physics`], [`Effect::apply_waveform`], [`Effect::vertical_offset_m`],
//! [`Effect::noise_sigma_factor`], [`Effect::ground_offset_m`], [`Effect::extra_offset`]) that
//! either side can call. Names of effects and parameters are a contract (docs/scenario.md).

use std::fmt;

use crate::sim::{DensityCount, SimConfig, Weighting};

/// Footprint σ of the nominal physics (m), gediRat's default.
pub const NOMINAL_FSIGMA_M: f64 = 5.5;
/// Pulse FWHM of the nominal physics (ns).
pub const NOMINAL_PULSE_FWHM_NS: f64 = 15.0;
/// Pulse σ (m, range) of a 15 ns FWHM Gaussian, as [`Pulse::from_fwhm_ns`] computes it.
pub const NOMINAL_PULSE_SIGMA_M: f64 = 15.0 * 0.2998 / 2.0 / 2.35482;
/// Return weighting of the nominal physics: `frac`, each ALS pulse's unit of energy split equally
/// among its returns. Without intensities it is the estimate of the area each surface takes in
/// the footprint; `count` gives a pulse of four returns four times the energy of a single ground
/// hit (docs/diagnosis.md, "Nominal weighting").
pub const NOMINAL_WEIGHTING: Weighting = Weighting::Frac;
/// Density normalisation of the nominal physics: by pulse, each pulse counted once at its first
/// return and its returns sharing that count, instead of gediRat's per-return count of last
/// returns, which weighs canopy returns up on slanted ALS rays (docs/diagnosis.md, "Density
/// normalisation").
pub const NOMINAL_DENSITY: DensityCount = DensityCount::Pulses;
/// Lower bound of the band the `occlusion` effect scales (m above ground).
pub const OCCLUSION_FLOOR_M: f64 = 0.5;

/// The physics a waveform is simulated with: simulator settings, return weighting and the
/// ground/vegetation reflectance ratio applied to the ground part.
#[derive(Debug, Clone, PartialEq)]
pub struct Physics {
    /// Footprint σ, pulse, bins (the default profile).
    pub sim: SimConfig,
    /// Return weighting whose ground and canopy parts are used.
    pub weighting: Weighting,
    /// ρ_ground/ρ_veg: the ground part is multiplied by this before the parts are added.
    pub rho_ground_over_veg: f64,
}

impl Physics {
    /// The nominal ("true" by default) physics: intensity-free [`NOMINAL_WEIGHTING`], ρg/ρv = 1,
    /// Gaussian pulse of 15 ns FWHM, σ_f 5.5 m, default simulator profile with the density
    /// normalised by pulse ([`NOMINAL_DENSITY`]), so a `none` world is a control of the
    /// diagnosis's nominal chain.
    pub fn nominal() -> Physics {
        Physics {
            sim: SimConfig { density_count: NOMINAL_DENSITY, ..SimConfig::new(crate::sim::Profile::Default) },
            weighting: NOMINAL_WEIGHTING,
            rho_ground_over_veg: 1.0,
        }
    }
}

/// Vertical profile of one simulated waveform split into its ground and canopy parts (same
/// bins, top to bottom, bin k at elevation `z0 − k·dz`), with the ground elevation that defines
/// "height above ground" for the canopy effects.
#[derive(Debug, Clone, PartialEq)]
pub struct WaveParts {
    /// Ground-return part.
    pub ground: Vec<f64>,
    /// Canopy (non-ground) part.
    pub canopy: Vec<f64>,
    /// Elevation of bin 0 (m).
    pub z0: f64,
    /// Bin size (m).
    pub dz: f64,
    /// Ground elevation (m, same datum as z0).
    pub ground_z: f64,
}

impl WaveParts {
    /// Height above ground of bin `k` (m).
    pub fn height(&self, k: usize) -> f64 {
        self.z0 - k as f64 * self.dz - self.ground_z
    }

    /// The total waveform: canopy + ρ·ground.
    pub fn compose(&self, rho_ground_over_veg: f64) -> Vec<f64> {
        self.canopy.iter().zip(&self.ground).map(|(c, g)| c + rho_ground_over_veg * g).collect()
    }
}

/// Level of the extra geolocation error of the `geolocation` effect.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GeoLevel {
    /// One extra constant offset per track (beam of a granule).
    Beam,
    /// An independent extra offset per shot.
    Shot,
}

/// Weighting method of the `weighting` effect.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WeightMethod {
    Count,
    Frac,
    Int,
    /// The nominal weighting ([`NOMINAL_WEIGHTING`]) with the ground part scaled by
    /// `rho_ground_over_veg`.
    Ratio,
}

impl WeightMethod {
    /// The simulator weighting whose parts the method uses.
    pub fn weighting(self) -> Weighting {
        match self {
            WeightMethod::Ratio => NOMINAL_WEIGHTING,
            WeightMethod::Count => Weighting::Count,
            WeightMethod::Frac => Weighting::Frac,
            WeightMethod::Int => Weighting::Int,
        }
    }
}

/// One withheld effect with its parameters.
#[derive(Debug, Clone, PartialEq)]
pub enum Effect {
    /// Extra horizontal geolocation error beyond the per-track offsets every world has.
    Geolocation { level: GeoLevel, shot_sigma_m: f64 },
    /// GEDI − ALS vertical offset beyond the nominal geoid (m).
    Datum { dz_m: f64 },
    /// Return weighting and ground/vegetation reflectance ratio of the real waveforms.
    Weighting { method: WeightMethod, rho_ground_over_veg: f64 },
    /// A system response beyond the transmit pulse: the real waveforms convolved with a further
    /// zero-mean Gaussian of σ (m, range).
    Pulse { pulse_sigma_m: f64 },
    /// Footprint σ (m) of the real waveforms.
    Footprint { fsigma_m: f64 },
    /// Noise σ relative to the median real `noise_stddev_corrected` of the beam type.
    Noise { noise_sigma_factor: f64 },
    /// Canopy energy above `height_m` reduced by `fraction` (growth/loss between acquisitions).
    CanopyChange { height_m: f64, fraction: f64 },
    /// Canopy energy between 0.5 m and `height_m` is (1 + gain)× the simulated (ALS occlusion of
    /// the understorey).
    Occlusion { height_m: f64, gain: f64 },
    /// GEDI ground minus ALS ground of one L2A algorithm (0 = all), applied to its products.
    GroundDetection { algorithm: u8, offset_m: f64 },
}

/// The kinds of effect: the one registry the scenario, the diagnosis's fit and its report share.
/// Every dispatch on a kind is an exhaustive `match`, so a new kind is a compile error wherever it
/// needs a decision (its parameters, its parsing, its fit, the frame it is judged in).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum EffectKind {
    Geolocation,
    Datum,
    Weighting,
    Pulse,
    Footprint,
    Noise,
    CanopyChange,
    Occlusion,
    GroundDetection,
}

impl EffectKind {
    /// Every kind, in registry order.
    pub const ALL: [EffectKind; 9] = [
        EffectKind::Geolocation,
        EffectKind::Datum,
        EffectKind::Weighting,
        EffectKind::Pulse,
        EffectKind::Footprint,
        EffectKind::Noise,
        EffectKind::CanopyChange,
        EffectKind::Occlusion,
        EffectKind::GroundDetection,
    ];

    /// The registry name (a contract: docs/scenario.md).
    pub fn name(self) -> &'static str {
        match self {
            EffectKind::Geolocation => "geolocation",
            EffectKind::Datum => "datum",
            EffectKind::Weighting => "weighting",
            EffectKind::Pulse => "pulse",
            EffectKind::Footprint => "footprint",
            EffectKind::Noise => "noise",
            EffectKind::CanopyChange => "canopy_change",
            EffectKind::Occlusion => "occlusion",
            EffectKind::GroundDetection => "ground_detection",
        }
    }

    /// The kind named `name`.
    pub fn from_name(name: &str) -> Option<EffectKind> {
        EffectKind::ALL.into_iter().find(|k| k.name() == name)
    }

    /// Every name, joined by `, ` (for messages).
    pub fn names() -> String {
        EffectKind::ALL.map(EffectKind::name).join(", ")
    }

    /// Whether the effect reshapes the simulated waveform, and so moves the positions that fit
    /// it best.
    pub fn reshapes_waveform(self) -> bool {
        match self {
            EffectKind::Weighting
            | EffectKind::Pulse
            | EffectKind::Footprint
            | EffectKind::CanopyChange
            | EffectKind::Occlusion => true,
            EffectKind::Geolocation | EffectKind::Datum | EffectKind::Noise | EffectKind::GroundDetection => false,
        }
    }

    /// (parameters, main parameter, nominal value of the main parameter).
    fn specs(self) -> (&'static [ParamSpec], &'static str, f64) {
        macro_rules! p {
            ($($n:literal = $d:literal),*) => { &[$(ParamSpec { name: $n, default: $d }),*] };
        }
        match self {
            EffectKind::Geolocation => (p!("level" = "shot", "shot_sigma_m" = "3.0"), "shot_sigma_m", 0.0),
            EffectKind::Datum => (p!("dz_m" = "0.5"), "dz_m", 0.0),
            EffectKind::Weighting => {
                (p!("method" = "ratio", "rho_ground_over_veg" = "0.7"), "rho_ground_over_veg", 1.0)
            }
            EffectKind::Pulse => (p!("pulse_sigma_m" = "1.2"), "pulse_sigma_m", 0.0),
            EffectKind::Footprint => (p!("fsigma_m" = "7.0"), "fsigma_m", NOMINAL_FSIGMA_M),
            EffectKind::Noise => (p!("noise_sigma_factor" = "2.0"), "noise_sigma_factor", 1.0),
            EffectKind::CanopyChange => (p!("height_m" = "10.0", "fraction" = "0.3"), "fraction", 0.0),
            EffectKind::Occlusion => (p!("height_m" = "5.0", "gain" = "0.5"), "gain", 0.0),
            EffectKind::GroundDetection => (p!("algorithm" = "all", "offset_m" = "0.5"), "offset_m", 0.0),
        }
    }
}

/// Why an effect specification was rejected; `Display` is one line naming the field.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EffectError {
    #[error("--effect: unknown effect '{0}' (known: none, {known})", known = EffectKind::names())]
    UnknownEffect(String),
    #[error("--effect: '{0}' is given twice")]
    Duplicate(String),
    #[error("--effect: 'none' cannot be combined with other effects")]
    NoneCombined,
    #[error("--effect: empty effect name in '{0}'")]
    Empty(String),
    #[error("--param {field}: {message}")]
    Param { field: String, message: String },
    #[error("--magnitude: {0}")]
    Magnitude(String),
}

fn param_err(field: &str, message: impl fmt::Display) -> EffectError {
    EffectError::Param { field: field.to_string(), message: message.to_string() }
}

/// A parameter value as recorded in truth.json and diagnosis.json (a JSON number or string).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(untagged)]
pub enum ParamValue {
    Number(f64),
    Text(String),
}

impl fmt::Display for ParamValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ParamValue::Number(x) => write!(f, "{x}"),
            ParamValue::Text(s) => write!(f, "{s}"),
        }
    }
}

/// Description of one parameter: name, default, and whether it is the effect's main parameter.
struct ParamSpec {
    name: &'static str,
    default: &'static str,
}

impl Effect {
    /// The kind of effect.
    pub fn kind(&self) -> EffectKind {
        match self {
            Effect::Geolocation { .. } => EffectKind::Geolocation,
            Effect::Datum { .. } => EffectKind::Datum,
            Effect::Weighting { .. } => EffectKind::Weighting,
            Effect::Pulse { .. } => EffectKind::Pulse,
            Effect::Footprint { .. } => EffectKind::Footprint,
            Effect::Noise { .. } => EffectKind::Noise,
            Effect::CanopyChange { .. } => EffectKind::CanopyChange,
            Effect::Occlusion { .. } => EffectKind::Occlusion,
            Effect::GroundDetection { .. } => EffectKind::GroundDetection,
        }
    }

    /// The registry name.
    pub fn name(&self) -> &'static str {
        self.kind().name()
    }

    /// The parameters, in registry order (names as in the contract).
    pub fn params(&self) -> Vec<(&'static str, ParamValue)> {
        use ParamValue::{Number as N, Text as T};
        match *self {
            Effect::Geolocation { level, shot_sigma_m } => vec![
                (
                    "level",
                    T(match level {
                        GeoLevel::Beam => "beam",
                        GeoLevel::Shot => "shot",
                    }
                    .into()),
                ),
                ("shot_sigma_m", N(shot_sigma_m)),
            ],
            Effect::Datum { dz_m } => vec![("dz_m", N(dz_m))],
            Effect::Weighting { method, rho_ground_over_veg } => vec![
                (
                    "method",
                    T(match method {
                        WeightMethod::Count => "count",
                        WeightMethod::Frac => "frac",
                        WeightMethod::Int => "int",
                        WeightMethod::Ratio => "ratio",
                    }
                    .into()),
                ),
                ("rho_ground_over_veg", N(rho_ground_over_veg)),
            ],
            Effect::Pulse { pulse_sigma_m } => vec![("pulse_sigma_m", N(pulse_sigma_m))],
            Effect::Footprint { fsigma_m } => vec![("fsigma_m", N(fsigma_m))],
            Effect::Noise { noise_sigma_factor } => vec![("noise_sigma_factor", N(noise_sigma_factor))],
            Effect::CanopyChange { height_m, fraction } => vec![("height_m", N(height_m)), ("fraction", N(fraction))],
            Effect::Occlusion { height_m, gain } => vec![("height_m", N(height_m)), ("gain", N(gain))],
            Effect::GroundDetection { algorithm, offset_m } => vec![
                ("algorithm", if algorithm == 0 { T("all".into()) } else { N(f64::from(algorithm)) }),
                ("offset_m", N(offset_m)),
            ],
        }
    }

    /// Parse one effect: `name`, optional `magnitude` (scales the main parameter's departure from
    /// its nominal value: `main = nominal + magnitude·(value − nominal)`), and `key=value`
    /// parameters (unknown keys are errors). Missing parameters take their defaults.
    pub fn parse(name: &str, magnitude: Option<f64>, params: &[(String, String)]) -> Result<Effect, EffectError> {
        let kind = EffectKind::from_name(name).ok_or_else(|| EffectError::UnknownEffect(name.to_string()))?;
        let (spec, main, nominal) = kind.specs();
        for (k, _) in params {
            if !spec.iter().any(|s| s.name == k) {
                let known: Vec<&str> = spec.iter().map(|s| s.name).collect();
                return Err(param_err(
                    k,
                    format!("not a parameter of '{name}' (its parameters: {})", known.join(", ")),
                ));
            }
        }
        if let Some(m) = magnitude {
            if !m.is_finite() {
                return Err(EffectError::Magnitude(format!("{m} is not a finite number")));
            }
        }
        let given = |k: &str| params.iter().rev().find(|(p, _)| p == k).map(|(_, v)| v.as_str());
        let raw = |k: &str| -> &str {
            given(k).unwrap_or_else(|| spec.iter().find(|s| s.name == k).map(|s| s.default).unwrap_or(""))
        };
        let num = |k: &str| -> Result<f64, EffectError> {
            let v = raw(k);
            let x: f64 = v.trim().parse().map_err(|_| param_err(k, format!("'{v}' is not a number")))?;
            if !x.is_finite() {
                return Err(param_err(k, format!("'{v}' is not finite")));
            }
            Ok(if k == main { nominal + magnitude.unwrap_or(1.0) * (x - nominal) } else { x })
        };
        let check = |k: &str, x: f64, ok: bool, what: &str| -> Result<f64, EffectError> {
            if ok {
                Ok(x)
            } else {
                Err(param_err(k, format!("{x} is out of range ({what})")))
            }
        };
        let effect = match kind {
            EffectKind::Geolocation => {
                let level = match raw("level") {
                    "beam" => GeoLevel::Beam,
                    "shot" => GeoLevel::Shot,
                    v => return Err(param_err("level", format!("'{v}' is not beam or shot"))),
                };
                let s = num("shot_sigma_m")?;
                Effect::Geolocation {
                    level,
                    shot_sigma_m: check("shot_sigma_m", s, (0.0..=50.0).contains(&s), "0..50 m")?,
                }
            }
            EffectKind::Datum => {
                let dz = num("dz_m")?;
                Effect::Datum { dz_m: check("dz_m", dz, dz.abs() <= 100.0, "|dz| ≤ 100 m")? }
            }
            EffectKind::Weighting => {
                let method = match raw("method") {
                    "count" => WeightMethod::Count,
                    "frac" => WeightMethod::Frac,
                    "int" => WeightMethod::Int,
                    "ratio" => WeightMethod::Ratio,
                    v => return Err(param_err("method", format!("'{v}' is not count, frac, int or ratio"))),
                };
                // A method other than ratio keeps ρ = 1 unless ρ is given.
                let rho = if method != WeightMethod::Ratio && given("rho_ground_over_veg").is_none() {
                    1.0
                } else {
                    num("rho_ground_over_veg")?
                };
                Effect::Weighting {
                    method,
                    rho_ground_over_veg: check("rho_ground_over_veg", rho, (0.0..=100.0).contains(&rho), "0..100")?,
                }
            }
            EffectKind::Pulse => {
                let s = num("pulse_sigma_m")?;
                Effect::Pulse { pulse_sigma_m: check("pulse_sigma_m", s, s > 0.01 && s <= 20.0, "0.01..20 m")? }
            }
            EffectKind::Footprint => {
                let s = num("fsigma_m")?;
                Effect::Footprint { fsigma_m: check("fsigma_m", s, (0.5..=30.0).contains(&s), "0.5..30 m")? }
            }
            EffectKind::Noise => {
                let f = num("noise_sigma_factor")?;
                Effect::Noise {
                    noise_sigma_factor: check("noise_sigma_factor", f, f > 0.0 && f <= 100.0, "0..100, > 0")?,
                }
            }
            EffectKind::CanopyChange => {
                let h = num("height_m")?;
                let f = num("fraction")?;
                Effect::CanopyChange {
                    height_m: check("height_m", h, (0.0..=100.0).contains(&h), "0..100 m")?,
                    fraction: check("fraction", f, (-10.0..=1.0).contains(&f), "≤ 1; negative = growth")?,
                }
            }
            EffectKind::Occlusion => {
                let h = num("height_m")?;
                let g = num("gain")?;
                Effect::Occlusion {
                    height_m: check("height_m", h, h > OCCLUSION_FLOOR_M && h <= 100.0, "0.5..100 m")?,
                    gain: check("gain", g, (-1.0..=100.0).contains(&g), "-1..100")?,
                }
            }
            EffectKind::GroundDetection => {
                let algorithm = match raw("algorithm") {
                    "all" | "0" => 0,
                    v => match v.trim().trim_start_matches('a').parse::<u8>() {
                        Ok(n) if (1..=6).contains(&n) => n,
                        _ => return Err(param_err("algorithm", format!("'{v}' is not 1..6 or all"))),
                    },
                };
                let o = num("offset_m")?;
                Effect::GroundDetection {
                    algorithm,
                    offset_m: check("offset_m", o, o.abs() <= 50.0, "|offset| ≤ 50 m")?,
                }
            }
        };
        Ok(effect)
    }

    /// Change the simulation physics (weighting, pulse, footprint); other effects leave it alone.
    pub fn apply_physics(&self, p: &mut Physics) {
        match *self {
            Effect::Weighting { method, rho_ground_over_veg } => {
                p.weighting = method.weighting();
                p.rho_ground_over_veg = rho_ground_over_veg;
            }
            // Shots with a recorded pulse are broadened alike (`Effect::extra_pulse_sigma`).
            Effect::Pulse { pulse_sigma_m } => p.sim.pulse = p.sim.pulse.broadened(pulse_sigma_m),
            Effect::Footprint { fsigma_m } => p.sim.fsigma = fsigma_m as f32,
            _ => {}
        }
    }

    /// The band of heights above ground [lo, hi) (m) whose canopy energy this effect scales, and
    /// the factor (`canopy_change`, `occlusion`); `None` for the other effects.
    pub fn canopy_band(&self) -> Option<(f64, f64, f64)> {
        match *self {
            Effect::CanopyChange { height_m, fraction } => Some((height_m, f64::INFINITY, 1.0 - fraction)),
            Effect::Occlusion { height_m, gain } => Some((OCCLUSION_FLOOR_M, height_m, 1.0 + gain)),
            _ => None,
        }
    }

    /// Canopy energy `c` at height `h` above ground scaled by every band (`canopy_band`) it lies
    /// in, in their order: what [`Effect::apply_waveform`] of each does to one bin.
    pub fn scaled_in_bands(c: f64, h: f64, bands: &[(f64, f64, f64)]) -> f64 {
        bands.iter().fold(c, |c, &(lo, hi, factor)| if (lo..hi).contains(&h) { c * factor } else { c })
    }

    /// Change the canopy part of a simulated waveform by height above ground.
    pub fn apply_waveform(&self, w: &mut WaveParts) {
        let Some((lo, hi, factor)) = self.canopy_band() else {
            return;
        };
        for k in 0..w.canopy.len() {
            let h = w.height(k);
            if h >= lo && h < hi {
                w.canopy[k] *= factor;
            }
        }
    }

    /// Vertical offset added to every GEDI elevation (m).
    pub fn vertical_offset_m(&self) -> f64 {
        match *self {
            Effect::Datum { dz_m } => dz_m,
            _ => 0.0,
        }
    }

    /// Factor on the noise σ of every shot.
    pub fn noise_sigma_factor(&self) -> f64 {
        match *self {
            Effect::Noise { noise_sigma_factor } => noise_sigma_factor,
            _ => 1.0,
        }
    }

    /// Offset added to the L2A ground elevation of algorithm `alg` (1..6), m.
    pub fn ground_offset_m(&self, alg: u8) -> f64 {
        match *self {
            Effect::GroundDetection { algorithm, offset_m } if algorithm == 0 || algorithm == alg => offset_m,
            _ => 0.0,
        }
    }

    /// Extra horizontal geolocation error: (level, RMS per axis, m), if this effect has one.
    pub fn extra_offset(&self) -> Option<(GeoLevel, f64)> {
        match *self {
            Effect::Geolocation { level, shot_sigma_m } => Some((level, shot_sigma_m)),
            _ => None,
        }
    }
}

/// The withheld effects of one world: none (control), one, or a combination (`a+b`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct EffectSet {
    pub effects: Vec<Effect>,
}

impl EffectSet {
    /// Parse `none`, `name` or `name+name…`; `--param key=value` entries go to the one effect
    /// that has the key (a key several effects share may be written `effect.key`).
    pub fn parse(spec: &str, magnitude: Option<f64>, params: &[(String, String)]) -> Result<EffectSet, EffectError> {
        let names: Vec<&str> = spec.split('+').map(str::trim).collect();
        if names.iter().any(|n| n.is_empty()) {
            return Err(EffectError::Empty(spec.to_string()));
        }
        if names.contains(&"none") {
            if names.len() > 1 {
                return Err(EffectError::NoneCombined);
            }
            if let Some((k, _)) = params.first() {
                return Err(param_err(k, "the 'none' effect takes no parameter"));
            }
            return Ok(EffectSet::default());
        }
        let mut kinds = Vec::with_capacity(names.len());
        for (i, n) in names.iter().enumerate() {
            kinds.push(EffectKind::from_name(n).ok_or_else(|| EffectError::UnknownEffect(n.to_string()))?);
            if names[..i].contains(n) {
                return Err(EffectError::Duplicate(n.to_string()));
            }
        }
        let mut per: Vec<Vec<(String, String)>> = vec![Vec::new(); names.len()];
        for (k, v) in params {
            let (target, key) = match k.split_once('.') {
                Some((e, key)) => {
                    let i = names
                        .iter()
                        .position(|n| *n == e)
                        .ok_or_else(|| param_err(k, format!("'{e}' is not one of the effects given")))?;
                    (i, key.to_string())
                }
                None => {
                    let owners: Vec<usize> =
                        (0..names.len()).filter(|&i| kinds[i].specs().0.iter().any(|p| p.name == k)).collect();
                    match owners.as_slice() {
                        [i] => (*i, k.clone()),
                        [] => return Err(param_err(k, format!("not a parameter of {}", names.join(" or ")))),
                        _ => return Err(param_err(k, "ambiguous: write effect.key")),
                    }
                }
            };
            per[target].push((key, v.clone()));
        }
        let effects =
            names.iter().zip(&per).map(|(n, p)| Effect::parse(n, magnitude, p)).collect::<Result<Vec<_>, _>>()?;
        Ok(EffectSet { effects })
    }

    /// `none` or the names joined by `+`.
    pub fn name(&self) -> String {
        if self.effects.is_empty() {
            "none".into()
        } else {
            self.effects.iter().map(Effect::name).collect::<Vec<_>>().join("+")
        }
    }

    /// `base` with every effect's physics change applied.
    pub fn physics(&self, base: &Physics) -> Physics {
        let mut p = base.clone();
        self.effects.iter().for_each(|e| e.apply_physics(&mut p));
        p
    }

    /// Apply every waveform effect in order.
    pub fn apply_waveform(&self, w: &mut WaveParts) {
        self.effects.iter().for_each(|e| e.apply_waveform(w));
    }

    /// Sum of the vertical offsets (m).
    pub fn vertical_offset_m(&self) -> f64 {
        self.effects.iter().map(Effect::vertical_offset_m).sum()
    }

    /// Product of the noise factors.
    pub fn noise_sigma_factor(&self) -> f64 {
        self.effects.iter().map(Effect::noise_sigma_factor).product()
    }

    /// σ (m) of the system response beyond the transmit pulse (the `pulse` effect; 0 without).
    pub fn extra_pulse_sigma(&self) -> f64 {
        self.effects
            .iter()
            .map(|e| if let Effect::Pulse { pulse_sigma_m } = e { pulse_sigma_m.powi(2) } else { 0.0 })
            .sum::<f64>()
            .sqrt()
    }

    /// Sum of the ground offsets of algorithm `alg` (m).
    pub fn ground_offset_m(&self, alg: u8) -> f64 {
        self.effects.iter().map(|e| e.ground_offset_m(alg)).sum()
    }

    /// The extra geolocation error, if any effect has one.
    pub fn extra_offset(&self) -> Option<(GeoLevel, f64)> {
        self.effects.iter().find_map(Effect::extra_offset)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kv(k: &str, v: &str) -> (String, String) {
        (k.to_string(), v.to_string())
    }

    #[test]
    fn every_kind_parses_from_its_name_to_itself() {
        for kind in EffectKind::ALL {
            assert_eq!(EffectKind::from_name(kind.name()), Some(kind));
            assert_eq!(Effect::parse(kind.name(), None, &[]).unwrap().kind(), kind, "{}", kind.name());
        }
        assert_eq!(EffectKind::from_name("none"), None);
    }

    #[test]
    fn defaults_and_magnitude_scale_the_departure_from_nominal() {
        let e = Effect::parse("pulse", None, &[]).unwrap();
        assert_eq!(e, Effect::Pulse { pulse_sigma_m: 1.2 });
        let Effect::Pulse { pulse_sigma_m } = Effect::parse("pulse", Some(2.0), &[]).unwrap() else { panic!() };
        assert!((pulse_sigma_m - 2.4).abs() < 1e-12);
        assert_eq!(Effect::parse("datum", Some(3.0), &[]).unwrap(), Effect::Datum { dz_m: 1.5 });
        assert_eq!(Effect::parse("datum", None, &[kv("dz_m", "-2")]).unwrap(), Effect::Datum { dz_m: -2.0 });
        assert_eq!(
            Effect::parse("weighting", None, &[kv("method", "frac")]).unwrap(),
            Effect::Weighting { method: WeightMethod::Frac, rho_ground_over_veg: 1.0 }
        );
    }

    #[test]
    fn pair_parses_and_params_go_to_their_owner() {
        let s = EffectSet::parse("datum+pulse", None, &[kv("dz_m", "1"), kv("pulse_sigma_m", "2")]).unwrap();
        assert_eq!(s.name(), "datum+pulse");
        assert_eq!(s.effects, vec![Effect::Datum { dz_m: 1.0 }, Effect::Pulse { pulse_sigma_m: 2.0 }]);
        let s = EffectSet::parse("canopy_change+occlusion", None, &[kv("occlusion.height_m", "4")]).unwrap();
        assert_eq!(s.effects[1], Effect::Occlusion { height_m: 4.0, gain: 0.5 });
        assert_eq!(EffectSet::parse("none", None, &[]).unwrap().name(), "none");
    }

    #[test]
    fn bad_specs_name_the_field() {
        let err = |s: &str, p: &[(String, String)]| EffectSet::parse(s, None, p).unwrap_err().to_string();
        assert!(err("bogus", &[]).contains("unknown effect 'bogus'"));
        assert!(err("datum+datum", &[]).contains("twice"));
        assert!(err("none+datum", &[]).contains("none"));
        assert!(err("datum", &[kv("dz_m", "abc")]).contains("--param dz_m: 'abc' is not a number"));
        assert!(err("datum", &[kv("fsigma_m", "3")]).contains("--param fsigma_m"));
        assert!(err("footprint", &[kv("fsigma_m", "-1")]).contains("--param fsigma_m"));
        assert!(err("canopy_change+occlusion", &[kv("height_m", "3")]).contains("ambiguous"));
        assert!(err("geolocation", &[kv("level", "track")]).contains("--param level"));
        assert!(err("ground_detection", &[kv("algorithm", "7")]).contains("--param algorithm"));
        for e in [err("datum", &[kv("dz_m", "nan")]), err("", &[])] {
            assert_eq!(e.lines().count(), 1, "{e}");
        }
        assert!(EffectSet::parse("datum", Some(f64::NAN), &[]).unwrap_err().to_string().contains("--magnitude"));
    }

    #[test]
    fn canopy_effects_scale_their_height_band() {
        let parts = WaveParts { ground: vec![0.0; 40], canopy: vec![1.0; 40], z0: 20.0, dz: 0.5, ground_z: 0.0 };
        let mut w = parts.clone();
        Effect::CanopyChange { height_m: 10.0, fraction: 0.3 }.apply_waveform(&mut w);
        for k in 0..40 {
            let expect = if parts.height(k) >= 10.0 { 0.7 } else { 1.0 };
            assert!((w.canopy[k] - expect).abs() < 1e-12, "bin {k}");
        }
        let mut w = parts.clone();
        Effect::Occlusion { height_m: 5.0, gain: 0.5 }.apply_waveform(&mut w);
        assert_eq!(w.canopy[39], 1.0 * 1.5); // 0.5 m above ground
        assert_eq!(w.canopy[30], 1.0); // 5 m: outside [0.5, 5)
        assert_eq!(w.canopy[0], 1.0);
    }

    #[test]
    fn physics_hooks() {
        let base = Physics::nominal();
        let p = EffectSet::parse("footprint+pulse", None, &[]).unwrap().physics(&base);
        assert_eq!(p.sim.fsigma, 7.0);
        let want = NOMINAL_PULSE_SIGMA_M.hypot(1.2);
        assert!((f64::from(p.sim.pulse.sigma) - want).abs() < 0.01, "{} vs {want}", p.sim.pulse.sigma);
        assert!((base.sim.pulse.sigma as f64 - NOMINAL_PULSE_SIGMA_M).abs() < 1e-6);
        let g = EffectSet::parse("ground_detection", None, &[kv("algorithm", "2")]).unwrap();
        assert_eq!((g.ground_offset_m(1), g.ground_offset_m(2)), (0.0, 0.5));
    }
}
