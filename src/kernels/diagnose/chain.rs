//! The forward model of one hypothesis: the GEDI chain (ALS waveform → pulse → noise twin → L2A
//! a1–a6) in a simulator configuration ([`Configuration`]: weighting and transmit pulse) with a set
//! of effects switched on, and the same effects undone on the real side.
//!
//! Every configuration is simulated as a scientist would *and* processed like GEDI: σ_f 5.5 m,
//! noise at the level of the median real GEDI shot of the beam type with the shots' own spread
//! (`case::set_nominal_noise`), the shot's own energy and record window, our L2A. The
//! configuration that reproduces the real waveforms best is chosen first
//! (`super::configuration`); a world without any unmodelled effect then differs from it only by
//! noise, so a control is `unexplained`; every effect is a departure from it, through the hooks
//! of the effect registry (`scenario::effects`) shared with the world generator.

use std::collections::HashMap;
use std::sync::Arc;

use rayon::prelude::*;

use super::case::{RealAlgorithm, ShotCase, SimShot, Site, FSIGMA_GRID, SITE_STEP_M};
use crate::gedi::{N_ALGORITHMS, RH_LEN};
use crate::scenario::effects::{
    Effect, GeoLevel, WaveParts, WeightMethod, NOMINAL_FSIGMA_M, NOMINAL_PULSE_SIGMA_M, NOMINAL_WEIGHTING,
};
use crate::scenario::EffectSet;
use crate::sim::pulse::gaussian_blur;
use crate::sim::{Pulse, Weighting};
use crate::waveform::forward::{forward, signal_span, L2aRunner, RecordWindow};
use crate::waveform::l2a::Noise;
use crate::waveform::noise_twin::GEDI_BIN_M;

/// The transmit pulse a configuration simulates with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum PulseChoice {
    /// The study's Gaussian of 15 ns FWHM.
    Gaussian,
    /// Each shot's recorded transmit pulse (L1B `txwaveform`, docs/pulse.md); shots without one
    /// use the Gaussian.
    #[default]
    Recorded,
}

/// The ground and vegetation reflectances a configuration weighs the ALS returns with
/// (docs/diagnosis.md, "Reflectances").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Reflectance {
    /// Ground and vegetation alike (gediRat's waveforms).
    #[default]
    Equal,
    /// The reference simulator's reflectances at 1064 nm, ρv 0.57 and ρg 0.40: the ratio its
    /// gediMetric computes the ALS cover with (docs/simulator-reference.md §2); GEDI's L2B cover
    /// assumes ρv/ρg 1.5.
    Reference,
}

/// ρg/ρv of [`Reflectance::Reference`].
pub const REFERENCE_RHO_GROUND_OVER_VEG: f64 = 0.40 / 0.57;

impl Reflectance {
    /// ρg/ρv: what the ground returns' weight is multiplied by.
    pub fn rho_ground_over_veg(self) -> f64 {
        match self {
            Reflectance::Equal => 1.0,
            Reflectance::Reference => REFERENCE_RHO_GROUND_OVER_VEG,
        }
    }

    /// `equal` or `reference`: the `reflectance` value of diagnosis.json's configurations.
    pub fn name(self) -> &'static str {
        match self {
            Reflectance::Equal => "equal",
            Reflectance::Reference => "reference",
        }
    }
}

/// The simulator configuration a hypothesis starts from — the study's own question (docs/diagnosis.md,
/// "Configuration first"): the return weighting, the transmit pulse and the reflectances. A
/// configuration is chosen before any effect is ranked, and is never reported as an unmodelled effect.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Configuration {
    pub weighting: Weighting,
    pub pulse: PulseChoice,
    pub reflectance: Reflectance,
}

impl Default for Configuration {
    /// The nominal chain's: `frac` (`NOMINAL_WEIGHTING`), each shot's recorded pulse, equal
    /// reflectances.
    fn default() -> Self {
        Configuration { weighting: NOMINAL_WEIGHTING, pulse: PulseChoice::Recorded, reflectance: Reflectance::Equal }
    }
}

impl Configuration {
    /// The study's baseline: `count` weighting, the 15 ns Gaussian, equal reflectances.
    pub fn study() -> Configuration {
        Configuration { weighting: Weighting::Count, pulse: PulseChoice::Gaussian, reflectance: Reflectance::Equal }
    }

    /// e.g. `int + recorded pulse`, `frac + recorded pulse + reference reflectances`.
    pub fn label(&self) -> String {
        let pulse = match self.pulse {
            PulseChoice::Gaussian => "Gaussian 15 ns",
            PulseChoice::Recorded => "recorded pulse",
        };
        match self.reflectance {
            Reflectance::Equal => format!("{} + {pulse}", self.weighting.name()),
            Reflectance::Reference => format!("{} + {pulse} + reference reflectances", self.weighting.name()),
        }
    }
}

/// A hypothesis: a configuration, the effects added to it (none = the configuration alone), and
/// where it places the shots of short collocation segments ([`reposition`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Model {
    pub config: Configuration,
    pub effects: Vec<Effect>,
    /// Site index (`SimShot::sites`) of a shot, by shot number; absent = the collocated position.
    pub placement: Arc<HashMap<u64, usize>>,
    /// Pulsed parts computed once, used where they are this model's ([`PulsedSites`]).
    pub pulsed: PulsedSites,
}

/// What a site's pulsed parts depend on in a model: the pulse choice, the weighting method, the
/// footprint σ and the extra pulse σ (compared as numbers: an extra σ of −0 is 0).
type PulseSignature = (PulseChoice, Weighting, f64, f64);

fn pulse_signature(m: &Model) -> PulseSignature {
    (m.config.pulse, m.weighting().0, m.fsigma(), m.extra_pulse_sigma())
}

/// The pulsed parts ([`pulsed_parts`]) of every site of a set of shots under one model, computed
/// once: the chosen configuration's, which the ranking and the self-test re-place shots and make
/// twins with again and again (twins share their shots' sites). A model carries them
/// ([`Model::with_pulsed`]); one whose parts before the pulse differ, or a site, pulse or bin
/// size they were not made for, computes its own. The same numbers either way.
#[derive(Clone, Default)]
pub struct PulsedSites(Option<Arc<PulsedTable>>);

struct PulsedTable {
    signature: PulseSignature,
    /// By a site's address: the address of the pulse and the bin size the parts were made with,
    /// and the parts.
    parts: HashMap<usize, (usize, f64, WaveParts)>,
    /// The shots whose sites these are, kept alive so that no address is reused.
    _shots: Vec<Arc<SimShot>>,
}

fn address<T>(t: Option<&T>) -> usize {
    t.map_or(0, |t| t as *const T as usize)
}

impl PulsedSites {
    /// The parts of every site of `cases` under `model`.
    pub fn new(cases: &[&ShotCase], model: &Model) -> PulsedSites {
        let parts = cases
            .par_iter()
            .flat_map_iter(|c| {
                let pulse = c.real.pulse.as_deref();
                c.sim.sites.iter().filter(|s| !s.variants.is_empty()).map(move |s| {
                    let parts = pulsed_parts(c.sim.dz, s, model, pulse);
                    (address(Some(s)), (address(pulse), c.sim.dz, parts))
                })
            })
            .collect();
        PulsedSites(Some(Arc::new(PulsedTable {
            signature: pulse_signature(model),
            parts,
            _shots: cases.iter().map(|c| c.sim.clone()).collect(),
        })))
    }

    /// The parts of `site` under `model` with `pulse` and bins of `dz`, if these are they.
    fn get(&self, site: &Site, model: &Model, pulse: Option<&Pulse>, dz: f64) -> Option<&WaveParts> {
        let table = self.0.as_ref()?;
        let (p, d, parts) = table.parts.get(&address(Some(site)))?;
        (*p == address(pulse) && *d == dz && table.signature == pulse_signature(model)).then_some(parts)
    }
}

impl PartialEq for PulsedSites {
    /// A cache: it never changes what a model is.
    fn eq(&self, _: &PulsedSites) -> bool {
        true
    }
}

impl std::fmt::Debug for PulsedSites {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "PulsedSites({} sites)", self.0.as_ref().map_or(0, |t| t.parts.len()))
    }
}

impl Model {
    /// The configuration `config` without effects, at the collocated positions.
    pub fn configured(config: Configuration) -> Model {
        Model { config, ..Model::default() }
    }

    /// This model using `pulsed` where they are its parts.
    pub fn with_pulsed(self, pulsed: &PulsedSites) -> Model {
        Model { pulsed: pulsed.clone(), ..self }
    }

    /// This model with `e` added (same placement).
    pub fn with(&self, e: Effect) -> Model {
        let mut effects = self.effects.clone();
        effects.push(e);
        Model { effects, ..self.clone() }
    }

    /// These effects with the placement of `other`.
    pub fn placed_as(&self, other: &Model) -> Model {
        Model { placement: other.placement.clone(), ..self.clone() }
    }

    /// The site at which this model simulates `case`.
    pub fn site<'a>(&self, case: &'a ShotCase) -> &'a Site {
        let k = self.placement.get(&case.real.shot_number).copied().unwrap_or(0);
        case.sim.sites.get(k).unwrap_or(&case.sim.sites[0])
    }

    fn set(&self) -> EffectSet {
        EffectSet { effects: self.effects.clone() }
    }

    /// Apply the model's effects that act on the waveform after the pulse (canopy change,
    /// occlusion) to `parts`.
    pub fn apply_after_pulse(&self, parts: &mut WaveParts) {
        self.effects.iter().for_each(|e| e.apply_waveform(parts));
    }

    /// GEDI − ALS vertical offset (m) of the model's effects.
    pub fn vertical_offset_m(&self) -> f64 {
        self.set().vertical_offset_m()
    }

    /// Level of the model's `geolocation` effect, if it has one: how finely it re-places shots.
    pub fn geolocation_level(&self) -> Option<GeoLevel> {
        self.effects.iter().rev().find_map(|e| e.extra_offset()).map(|(level, _)| level)
    }

    /// Footprint σ (m).
    pub fn fsigma(&self) -> f64 {
        self.effects
            .iter()
            .rev()
            .find_map(|e| if let Effect::Footprint { fsigma_m } = e { Some(*fsigma_m) } else { None })
            .unwrap_or(NOMINAL_FSIGMA_M)
    }

    /// σ (m, range) of the system response beyond the transmit pulse (the `pulse` effect; 0 without).
    pub fn extra_pulse_sigma(&self) -> f64 {
        self.set().extra_pulse_sigma()
    }

    /// `x` (bins of `dz`) convolved with the model's pulse: the shot's recorded `pulse` (at `dz`)
    /// then the extra Gaussian, or one Gaussian of the nominal σ and the extra σ in quadrature.
    pub fn apply_pulse(&self, x: &[f64], pulse: Option<&Pulse>, dz: f64) -> Vec<f64> {
        let extra = self.extra_pulse_sigma();
        let recorded = self.config.pulse == PulseChoice::Recorded;
        match pulse.filter(|p| recorded && (f64::from(p.res) - dz).abs() < 1e-6) {
            Some(p) => gaussian_blur(&p.convolve_same(x), extra, dz),
            None => gaussian_blur(x, NOMINAL_PULSE_SIGMA_M.hypot(extra), dz),
        }
    }

    /// Weighting and ρg/ρv: the configuration's weighting and reflectances, unless a `weighting`
    /// effect names another method; an effect's ρ multiplies the configuration's (`ratio` scales
    /// the configuration's own weighting).
    pub fn weighting(&self) -> (Weighting, f64) {
        let rho = self.config.reflectance.rho_ground_over_veg();
        self.effects
            .iter()
            .rev()
            .find_map(|e| match *e {
                Effect::Weighting { method: WeightMethod::Ratio, rho_ground_over_veg } => {
                    Some((self.config.weighting, rho * rho_ground_over_veg))
                }
                Effect::Weighting { method, rho_ground_over_veg } => {
                    Some((method.weighting(), rho * rho_ground_over_veg))
                }
                _ => None,
            })
            .unwrap_or((self.config.weighting, rho))
    }
}

/// One algorithm's products: a ground elevation (m, ALS datum) and RH0..RH100 (m).
#[derive(Debug, Clone, PartialEq)]
pub struct Products {
    pub ground: f64,
    pub rh: [f32; RH_LEN],
}

/// Reusable buffers of one worker.
#[derive(Debug, Default)]
pub struct Scratch {
    l2a: L2aRunner,
}

impl Scratch {
    pub fn new() -> Scratch {
        Scratch::default()
    }
}

/// Seed of a shot's noise draws: the same for every hypothesis, so that hypotheses are compared
/// on the same noise (common random numbers).
fn noise_seed(shot_number: u64) -> u64 {
    shot_number.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0xD1A6_0000_5EED
}

/// The pulse-free parts of weighting `w` at footprint σ `fsigma`, interpolated linearly between
/// the two nearest simulated widths (a site simulated at the nominal width only gives that one).
fn parts_at(site: &Site, w: Weighting, fsigma: f64) -> (Vec<f64>, Vec<f64>) {
    if let [only] = site.variants.as_slice() {
        let p = &only.weightings[w as usize];
        return (p.ground.iter().map(|&v| f64::from(v)).collect(), p.canopy.iter().map(|&v| f64::from(v)).collect());
    }
    let grid = &FSIGMA_GRID;
    let f = fsigma.clamp(grid[0], grid[grid.len() - 1]);
    let i = grid.windows(2).position(|p| f <= p[1]).unwrap_or(grid.len() - 2);
    let t = (f - grid[i]) / (grid[i + 1] - grid[i]);
    let (a, b) = (&site.variants[i].weightings[w as usize], &site.variants[i + 1].weightings[w as usize]);
    let mix = |x: &[f32], y: &[f32]| -> Vec<f64> {
        x.iter().zip(y).map(|(&p, &q)| (1.0 - t) * f64::from(p) + t * f64::from(q)).collect()
    };
    (mix(&a.ground, &b.ground), mix(&a.canopy, &b.canopy))
}

/// The noise-free simulated waveform of `case` under `model` at the model's site of the case
/// (bins of the site's grid), with the canopy effects applied after the pulse as in the world
/// generator.
pub fn simulated_wave(case: &ShotCase, model: &Model) -> Vec<f64> {
    simulated_wave_at(case.sim.dz, model.site(case), model, case.real.pulse.as_deref())
}

/// The noise-free simulated waveform at `site` (bins of `dz` from `site.z0`) with the shot's
/// recorded `pulse`, if any.
pub fn simulated_wave_at(dz: f64, site: &Site, model: &Model, pulse: Option<&Pulse>) -> Vec<f64> {
    if let Some(parts) = model.pulsed.get(site, model, pulse, dz) {
        return composed_after_pulse(parts, model);
    }
    let mut parts = pulsed_parts(dz, site, model, pulse);
    model.apply_after_pulse(&mut parts);
    composed(&parts, model)
}

/// `composed` of `parts` with `model`'s after-pulse effects applied, without copying them: each
/// bin's canopy scaled by every band it lies in, in the effects' order, as
/// [`Model::apply_after_pulse`] does.
fn composed_after_pulse(parts: &WaveParts, model: &Model) -> Vec<f64> {
    let bands: Vec<(f64, f64, f64)> = model.effects.iter().filter_map(Effect::canopy_band).collect();
    let rho = model.weighting().1;
    (parts.canopy.iter().zip(&parts.ground).enumerate())
        .map(|(k, (&c, &g))| {
            let c = if bands.is_empty() { c } else { Effect::scaled_in_bands(c, parts.height(k), &bands) };
            (c + rho * g).max(0.0)
        })
        .collect()
}

/// The ground and canopy parts at `site` under `model`'s weighting and footprint, convolved with
/// its pulse: [`simulated_wave_at`] before the effects that act after the pulse.
pub fn pulsed_parts(dz: f64, site: &Site, model: &Model, pulse: Option<&Pulse>) -> WaveParts {
    if let Some(parts) = model.pulsed.get(site, model, pulse, dz) {
        return parts.clone();
    }
    let (ground, canopy) = parts_at(site, model.weighting().0, model.fsigma());
    WaveParts {
        ground: model.apply_pulse(&ground, pulse, dz),
        canopy: model.apply_pulse(&canopy, pulse, dz),
        z0: site.z0,
        dz,
        ground_z: site.als_ground,
    }
}

/// The waveform of `parts` (after-pulse effects applied) at `model`'s ground/vegetation ratio,
/// clipped at 0.
pub fn composed(parts: &WaveParts, model: &Model) -> Vec<f64> {
    parts.compose(model.weighting().1).into_iter().map(|v| v.max(0.0)).collect()
}

/// `model` and `other` simulate the same waveforms up to the effects that act after the pulse
/// (a ground/vegetation ratio, a canopy change, an occlusion): same weighting method, footprint,
/// pulse, vertical offset and placement.
pub fn same_before_pulse(model: &Model, other: &Model) -> bool {
    model.config == other.config
        && model.weighting().0 == other.weighting().0
        && model.fsigma() == other.fsigma()
        && model.extra_pulse_sigma() == other.extra_pulse_sigma()
        && model.vertical_offset_m() == other.vertical_offset_m()
        && Arc::ptr_eq(&model.placement, &other.placement)
}

/// Σx, Σx² and the count of a real waveform's samples: the same at every site a shot is
/// correlated at ([`correlation`]).
#[derive(Debug, Clone, Copy)]
struct RealSums {
    n: f64,
    sx: f64,
    sxx: f64,
}

impl RealSums {
    fn of(wave: &[f32]) -> RealSums {
        let (mut sx, mut sxx) = (0.0, 0.0);
        for &r in wave {
            let x = f64::from(r);
            sx += x;
            sxx += x * x;
        }
        RealSums { n: wave.len() as f64, sx, sxx }
    }
}

/// Pearson correlation between the real waveform of `case` (elevations through the nominal geoid
/// and the model's vertical offset) and `wave` (bins of `dz` from `z0`), read at the real
/// samples by linear interpolation: the collocation's measure of fit of a position. `real`: the
/// real waveform's [`RealSums`]. `wave` is 0 outside its bins, so only the real samples within
/// them add to the sums that involve it.
fn correlation(case: &ShotCase, model: &Model, wave: &[f64], z0: f64, dz: f64, real: RealSums) -> f64 {
    let top = case.real.bin0 - model.vertical_offset_m();
    let samples = &case.real.wave;
    // Sample s lies at p = (z0 − top + s·b)/dz bins into `wave`, inside for 0 ≤ p < len − 1;
    // a sample more on each side (value_at gives 0 there).
    let bins = |p: f64| (p * dz + top - z0) / GEDI_BIN_M;
    let lo = (bins(0.0).floor() - 1.0).clamp(0.0, samples.len() as f64) as usize;
    let hi = (bins(wave.len() as f64 - 1.0).ceil() + 2.0).clamp(lo as f64, samples.len() as f64) as usize;
    let (mut sy, mut syy, mut sxy) = (0.0, 0.0, 0.0);
    for (s, &r) in samples.iter().enumerate().take(hi).skip(lo) {
        let (x, y) = (f64::from(r), value_at(wave, z0, dz, top - s as f64 * GEDI_BIN_M));
        sy += y;
        syy += y * y;
        sxy += x * y;
    }
    pearson_of(real.n, real.sx, sy, real.sxx, syy, sxy, 2)
}

/// The value of `wave` (bins of `dz` from `z0`, downwards) at elevation `z` by linear
/// interpolation; 0 outside it.
pub(super) fn value_at(wave: &[f64], z0: f64, dz: f64, z: f64) -> f64 {
    let p = (z0 - z) / dz;
    // For p ≥ 0 its floor is its truncation (`as`, without the libm call `floor` is on x86-64's
    // baseline); p < 0 and NaN lie outside.
    if p >= 0.0 {
        let i = p as usize;
        if i < wave.len().saturating_sub(1) {
            let t = p - i as f64;
            return (1.0 - t) * wave[i] + t * wave[i + 1];
        }
    }
    0.0
}

/// Pearson r of the pairs (x, y); NaN with fewer than `min_n` pairs or without spread.
pub(super) fn pearson(pairs: impl Iterator<Item = (f64, f64)>, min_n: usize) -> f64 {
    let (mut n, mut sx, mut sy, mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for (x, y) in pairs {
        n += 1.0;
        sx += x;
        sy += y;
        sxx += x * x;
        syy += y * y;
        sxy += x * y;
    }
    pearson_of(n, sx, sy, sxx, syy, sxy, min_n)
}

/// Pearson r from the sums of n pairs; NaN with fewer than `min_n` pairs or without spread.
fn pearson_of(n: f64, sx: f64, sy: f64, sxx: f64, syy: f64, sxy: f64, min_n: usize) -> f64 {
    let var = (sxx - sx * sx / n) * (syy - sy * sy / n);
    if n >= min_n as f64 && var > 0.0 {
        (sxy - sx * sy / n) / var.sqrt()
    } else {
        f64::NAN
    }
}

/// Re-place the shots for `model`, each to the site (`SimShot::sites`) where the model's waveform
/// correlates best with the real one — the collocation redone with the hypothesis instead of the
/// nominal simulation:
/// - without a `geolocation` effect, the shots of short collocation segments, each segment as
///   one (the same site offset for all its shots, correlations summed). On tracks of one or two
///   shots the nominal collocation fits each position to the nominal waveform and so absorbs much
///   of a waveform-shape effect; re-placing gives every hypothesis the same freedom;
/// - with `geolocation` at level `beam`, every segment that has sites, as one;
/// - with `geolocation` at level `shot`, every shot that has sites, on its own.
///
/// Ties keep the lowest site (the collocated position first). Other shots keep their placement
/// in `model`.
pub fn reposition(cases: &[&ShotCase], model: &Model) -> Model {
    let level = model.geolocation_level();
    let movable = |c: &ShotCase| c.sim.sites.len() > 1 && (level.is_some() || c.sim.short_segment);
    let scores: Vec<Vec<f64>> = cases
        .par_iter()
        .map(|c| {
            if !movable(c) {
                return Vec::new();
            }
            let real = RealSums::of(&c.real.wave);
            c.sim
                .sites
                .iter()
                .map(|s| {
                    if s.variants.is_empty() {
                        f64::NAN
                    } else {
                        let wave = simulated_wave_at(c.sim.dz, s, model, c.real.pulse.as_deref());
                        correlation(c, model, &wave, s.z0, c.sim.dz, real)
                    }
                })
                .collect()
        })
        .collect();
    // Per unit moved as one (segment or shot): summed r per site (NaN once any shot lacks the
    // site) and its shots.
    type Unit = (Vec<f64>, Vec<u64>);
    let mut units: HashMap<(&str, u64), Unit> = HashMap::new();
    for (c, sc) in cases.iter().zip(&scores) {
        if sc.is_empty() {
            continue;
        }
        let key = (c.real.segment.as_str(), if level == Some(GeoLevel::Shot) { c.real.shot_number } else { 0 });
        let (sum, shots) = units.entry(key).or_insert_with(|| (vec![0.0; sc.len()], Vec::new()));
        if sum.len() == sc.len() {
            sum.iter_mut().zip(sc).for_each(|(a, b)| *a += b);
        } else {
            sum.iter_mut().for_each(|v| *v = f64::NAN);
        }
        shots.push(c.real.shot_number);
    }
    let mut placement = (*model.placement).clone();
    for (sum, shots) in units.into_values() {
        let best = (0..sum.len()).filter(|&k| sum[k].is_finite()).fold(0, |b, k| {
            if !sum[b].is_finite() || sum[k] > sum[b] {
                k
            } else {
                b
            }
        });
        for s in shots {
            placement.insert(s, best);
        }
    }
    Model { placement: Arc::new(placement), ..model.clone() }
}

/// The GEDI-processed simulation of `case` under `model`: one entry per algorithm a1..a6
/// (`None` where L2A finds no result or the twin cannot be made).
pub fn predict(case: &ShotCase, model: &Model, scratch: &mut Scratch) -> [Option<Products>; N_ALGORITHMS] {
    let wave = simulated_wave(case, model);
    match twin(case, model, &wave, model.site(case).z0, noise_seed(case.real.shot_number), scratch) {
        Some((_, _, products)) => products,
        None => std::array::from_fn(|_| None),
    }
}

/// The noise twin of a noise-free waveform `wave` of `case` (bins of the case's `dz` from `z0`)
/// under `model` with the noise draw `seed`, in the real shot's record window: the received
/// waveform (DN), its noise, and its L2A products.
#[allow(clippy::type_complexity)]
fn twin(
    case: &ShotCase,
    model: &Model,
    wave: &[f64],
    z0: f64,
    seed: u64,
    scratch: &mut Scratch,
) -> Option<(Vec<f32>, Noise, [Option<Products>; N_ALGORITHMS])> {
    let (first, signal) = signal_span(wave)?;
    let real = &case.real;
    let z_first = z0 - first as f64 * case.sim.dz;
    let start = ((real.bin0 - z_first) / GEDI_BIN_M).round() as isize;
    let window = RecordWindow { sample_count: real.sample_count, start, bin0: real.bin0, lastbin: real.lastbin };
    let noise = Noise { mean: real.noise.mean, stddev: real.nominal_noise_stddev * model.set().noise_sigma_factor() };
    let twin = forward(signal, case.sim.dz, &window, real.energy, noise, seed, &mut scratch.l2a).ok()?;
    let products = std::array::from_fn(|a| match scratch.l2a.outcomes.get(a) {
        Some(Ok(r)) if r.elev_lowestmode.is_finite() => {
            Some(Products { ground: r.elev_lowestmode, rh: std::array::from_fn(|k| r.rh_cm[k] as f32 / 100.0) })
        }
        _ => None,
    });
    Some((twin.wave, twin.noise, products))
}

/// The noise-twin null of `case` under `model`: the same shot with its real side replaced by a
/// second, independent noise twin of the model's simulation — a shot for which `model` is true
/// up to the resolution of the sites: the twin is made at a random point of the model's site's
/// cell (uniform within ± half the [`SITE_STEP_M`] per axis, waveforms interpolated bilinearly
/// between the sites around it), as a real shot lies between the sites a placement can choose.
/// Scored like the real shots, it gives the gap that noise and site resolution alone leave
/// under a hypothesis's freedom (re-placement fits noise too): the floor against which an effect
/// judged on spread (`geolocation`) is measured. `None` when no twin can be made.
pub fn null_case(case: &ShotCase, model: &Model, scratch: &mut Scratch) -> Option<ShotCase> {
    let seed = noise_seed(case.real.shot_number) ^ NULL_SEED;
    let mut rng = crate::scenario::rng::Stream::new(seed, &["null position"]);
    let here = model.site(case).offset;
    let target = (here.0 + (rng.uniform() - 0.5) * SITE_STEP_M, here.1 + (rng.uniform() - 0.5) * SITE_STEP_M);
    twin_case(case, model, target, seed, scratch)
}

/// `case` with its real side replaced by a noise twin (noise draw `seed`) of `model`'s simulation
/// at the horizontal offset `target` (m from the collocated position): at the model's own site
/// when `target` is its offset, else between the sites around it ([`wave_between`]). The
/// model's real-side effects (a datum, a ground detection) are put on the twin's products as
/// GEDI's would carry them. `None` when no twin can be made.
pub fn twin_case(
    case: &ShotCase,
    model: &Model,
    target: (f64, f64),
    seed: u64,
    scratch: &mut Scratch,
) -> Option<ShotCase> {
    let site = model.site(case);
    let (wave, z0) =
        if target == site.offset { (simulated_wave(case, model), site.z0) } else { wave_between(case, model, target)? };
    let (wave, noise, products) = twin(case, model, &wave, z0, seed, scratch)?;
    let set = model.set();
    let vo = set.vertical_offset_m();
    let mut real = case.real.clone();
    // Stored the way the real side is, so that `real_products` and `correlation` undo the
    // model's real-side offsets back to the twin's own frame.
    real.algorithms = std::array::from_fn(|a| {
        let p = products[a].as_ref()?;
        let o = set.ground_offset_m(a as u8 + 1);
        Some(RealAlgorithm { ground: p.ground + vo + o, rh: p.rh.iter().map(|&v| (f64::from(v) - o) as f32).collect() })
    });
    real.bin0 += vo;
    real.lastbin += vo;
    real.noise = noise;
    real.wave = wave.iter().map(|&v| (f64::from(v) - noise.mean) as f32).collect();
    real.collocation_dz = None;
    Some(ShotCase { real, sim: case.sim.clone(), mismatch: case.mismatch })
}

/// The noise-free waveform of `case` under `model` at the horizontal offset `target` (m from the
/// collocated position): the waveforms of the sites less than [`SITE_STEP_M`] away on each axis,
/// weighted bilinearly, on one bin grid (the sites' grids share one lattice). Returns it with
/// the elevation of its first bin; `None` when no site is near.
fn wave_between(case: &ShotCase, model: &Model, target: (f64, f64)) -> Option<(Vec<f64>, f64)> {
    let dz = case.sim.dz;
    let near: Vec<(f64, &Site)> = case
        .sim
        .sites
        .iter()
        .filter(|s| !s.variants.is_empty())
        .filter_map(|s| {
            let w = (1.0 - (s.offset.0 - target.0).abs() / SITE_STEP_M)
                * (1.0 - (s.offset.1 - target.1).abs() / SITE_STEP_M);
            (w > 0.0 && (s.offset.0 - target.0).abs() < SITE_STEP_M).then_some((w, s))
        })
        .collect();
    let total: f64 = near.iter().map(|(w, _)| w).sum();
    if !(total > 0.0) {
        return None;
    }
    let waves: Vec<(f64, f64, Vec<f64>)> = near
        .iter()
        .map(|(w, s)| (w / total, s.z0, simulated_wave_at(dz, s, model, case.real.pulse.as_deref())))
        .collect();
    let top = waves.iter().map(|(_, z0, _)| *z0).fold(f64::NEG_INFINITY, f64::max);
    let len = waves.iter().map(|(_, z0, v)| ((top - z0) / dz).round() as usize + v.len()).max()?;
    let mut out = vec![0.0; len];
    for (w, z0, v) in &waves {
        let off = ((top - z0) / dz).round() as usize;
        out[off..off + v.len()].iter_mut().zip(v).for_each(|(o, x)| *o += w * x);
    }
    Some((out, top))
}

/// The noise-twin nulls of `cases` under `model` (parallel), with the index of the case each
/// comes from.
pub fn null_cases(cases: &[&ShotCase], model: &Model) -> Vec<(usize, ShotCase)> {
    cases
        .par_iter()
        .enumerate()
        .map_init(Scratch::new, |scratch, (i, c)| null_case(c, model, scratch).map(|n| (i, n)))
        .flatten()
        .collect()
}

/// Mixed into a shot's noise seed for its null twin (independent of the simulated side's draw).
const NULL_SEED: u64 = 0x0A11_7717_u64;

/// The real products of algorithm `alg` (1..6) of `case` with the model's real-side effects
/// undone: the datum offset removed from the ground, the ground-detection offset removed from the
/// ground and added back to RH.
pub fn real_products(case: &ShotCase, model: &Model, alg: u8) -> Option<Products> {
    let r = case.real.algorithms.get(usize::from(alg) - 1)?.as_ref()?;
    let set = model.set();
    let o = set.ground_offset_m(alg);
    let ground = r.ground - set.vertical_offset_m() - o;
    if r.rh.len() != RH_LEN {
        return None;
    }
    Some(Products { ground, rh: std::array::from_fn(|k| (f64::from(r.rh[k]) + o) as f32) })
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::diagnose::case::{site_grid, Parts, RealShot, SimShot, SimVariant, Strata};
    use crate::gedi::BeamType;

    /// A site at `offset` (m from the collocated position) whose canopy layer's height depends on
    /// the position (unique on the site grid), over a ground at 100 m.
    fn site(offset: (f64, f64)) -> Site {
        let (n, z0) = (300, 140.0);
        let top = 20.0 + offset.0 + 0.3 * offset.1;
        let z = |k: usize| z0 - k as f64 * GEDI_BIN_M;
        let ground = (0..n).map(|k| (-0.5 * ((z(k) - 100.0) / 0.3).powi(2)).exp() as f32).collect();
        let canopy = (0..n).map(|k| (0.3 * (-0.5 * ((z(k) - 100.0 - top) / 1.5).powi(2)).exp()) as f32).collect();
        let parts = Parts { ground, canopy };
        Site {
            z0,
            variants: vec![SimVariant { weightings: std::array::from_fn(|_| parts.clone()) }],
            als_ground: 100.0,
            offset,
        }
    }

    /// A shot of a long segment whose real waveform is the nominal one at `truth`.
    fn case(shot: u64, segment: &str, truth: (f64, f64)) -> ShotCase {
        let mut sites = vec![site((0.0, 0.0))];
        sites.extend(site_grid().into_iter().map(site));
        let sim = Arc::new(SimShot { dz: GEDI_BIN_M, sites, short_segment: false, rh_nominal: vec![0.0; RH_LEN] });
        let wave: Vec<f32> =
            simulated_wave_at(GEDI_BIN_M, &site(truth), &Model::default(), None).iter().map(|&v| v as f32).collect();
        let real = RealShot {
            shot_number: shot,
            track: "g/BEAM0000".into(),
            beam_type: BeamType::Coverage,
            noise: Noise { mean: 0.0, stddev: 1.0 },
            nominal_noise_stddev: 1.0,
            energy: 1.0,
            sample_count: wave.len(),
            bin0: 140.0,
            lastbin: 140.0 - (wave.len() - 1) as f64 * GEDI_BIN_M,
            wave,
            selected: 1,
            algorithms: std::array::from_fn(|_| None),
            strata: Strata::default(),
            segment: segment.into(),
            collocation_dz: None,
            pulse: None,
        };
        ShotCase { real, sim, mismatch: [false; N_ALGORITHMS] }
    }

    fn offsets(cases: &[&ShotCase], model: &Model) -> Vec<(f64, f64)> {
        let placed = reposition(cases, model);
        cases.iter().map(|c| placed.site(c).offset).collect()
    }

    #[test]
    fn geolocation_level_decides_what_moves() {
        let (a, b) = (case(1, "s", (2.0, -2.0)), case(2, "s", (-4.0, 4.0)));
        let cases = [&a, &b];
        // Without geolocation a long segment keeps its collocated position.
        assert_eq!(offsets(&cases, &Model::default()), vec![(0.0, 0.0); 2]);
        // Level shot: each shot to its own position.
        let shot = Model::default().with(Effect::Geolocation { level: GeoLevel::Shot, shot_sigma_m: 0.0 });
        assert_eq!(offsets(&cases, &shot), vec![(2.0, -2.0), (-4.0, 4.0)]);
        // Level beam: the segment moves as one, to where both its shots are.
        let (c, d) = (case(3, "t", (2.0, -2.0)), case(4, "t", (2.0, -2.0)));
        let beam = Model::default().with(Effect::Geolocation { level: GeoLevel::Beam, shot_sigma_m: 0.0 });
        assert_eq!(offsets(&[&c, &d], &beam), vec![(2.0, -2.0); 2]);
        let moved = offsets(&cases, &beam);
        assert_eq!(moved[0], moved[1]);
    }

    #[test]
    fn wave_between_interpolates_the_sites_bilinearly() {
        let c = case(1, "s", (0.0, 0.0));
        let m = Model::default();
        let at = |x: f64, y: f64| wave_between(&c, &m, (x, y)).unwrap();
        let node = simulated_wave_at(GEDI_BIN_M, &site((2.0, -2.0)), &m, None);
        let (w, z0) = at(2.0, -2.0);
        assert_eq!(z0, 140.0);
        assert!(w.iter().zip(&node).all(|(a, b)| (a - b).abs() < 1e-12));
        let right = simulated_wave_at(GEDI_BIN_M, &site((4.0, -2.0)), &m, None);
        let (mid, _) = at(3.0, -2.0);
        assert!(mid.iter().zip(node.iter().zip(&right)).all(|(v, (a, b))| (v - 0.5 * (a + b)).abs() < 1e-12));
    }

    #[test]
    fn model_reads_its_effects() {
        let m = Model::default()
            .with(Effect::Footprint { fsigma_m: 7.0 })
            .with(Effect::Weighting { method: WeightMethod::Int, rho_ground_over_veg: 0.5 });
        assert_eq!(m.fsigma(), 7.0);
        assert_eq!(m.weighting(), (Weighting::Int, 0.5));
        assert_eq!(m.extra_pulse_sigma(), 0.0);
        assert_eq!(Model::default().weighting(), (NOMINAL_WEIGHTING, 1.0));
        // A ratio scales the configuration's own weighting: count stays count.
        let count = Model::configured(Configuration { weighting: Weighting::Count, ..Configuration::study() });
        let ratio = count.with(Effect::Weighting { method: WeightMethod::Ratio, rho_ground_over_veg: 0.6 });
        assert_eq!(ratio.weighting(), (Weighting::Count, 0.6));
        assert_eq!(count.weighting(), (Weighting::Count, 1.0));
        // The configuration's reflectances multiply an effect's ratio.
        let reference =
            Model::configured(Configuration { reflectance: Reflectance::Reference, ..Configuration::study() });
        assert_eq!(reference.weighting(), (Weighting::Count, REFERENCE_RHO_GROUND_OVER_VEG));
        let ratio = reference.with(Effect::Weighting { method: WeightMethod::Ratio, rho_ground_over_veg: 0.5 });
        assert_eq!(ratio.weighting(), (Weighting::Count, 0.5 * REFERENCE_RHO_GROUND_OVER_VEG));
    }
}
