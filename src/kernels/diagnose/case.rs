//! What the diagnosis knows about one shot: the real side (its L1B record facts and L2A products,
//! in the ALS vertical datum through the nominal geoid) and the simulated side (ground and canopy
//! parts of the ALS waveform, without a pulse, for each footprint width and weighting tried, at
//! the collocated position and, for short segments, at nearby positions).

use crate::gedi::{BeamType, N_ALGORITHMS, RH_LEN};
use crate::scenario::effects::NOMINAL_DENSITY;
use crate::sim::{self, Profile, SimConfig, Weighting, N_WEIGHTINGS};
use crate::waveform::l2a::Noise;

/// Footprint σ (m) at which every shot is simulated; other widths are interpolated between them.
pub const FSIGMA_GRID: [f64; 6] = [3.5, 4.5, 5.5, 7.0, 8.5, 10.0];

/// One L2A algorithm's stored products of a real shot.
#[derive(Debug, Clone, PartialEq)]
pub struct RealAlgorithm {
    /// `elev_lowestmode_aN` − N: GEDI ground in the ALS datum through the nominal geoid (m).
    pub ground: f64,
    /// `rh_aN` as stored (m above GEDI's ground), 101 values.
    pub rh: Vec<f32>,
}

/// The real side of one shot.
#[derive(Debug, Clone, PartialEq)]
pub struct RealShot {
    pub shot_number: u64,
    /// Track = one beam of one granule (`<granule>/<beam>`): the unit of calibration/held-out
    /// splits and of the bootstrap.
    pub track: String,
    pub beam_type: BeamType,
    /// Reported noise mean and σ (`noise_*_corrected`, DN).
    pub noise: Noise,
    /// Noise σ of this shot in the nominal chain (DN): set by [`set_nominal_noise`].
    pub nominal_noise_stddev: f64,
    /// Σ (sample − noise mean) over the record (DN): the twin's energy.
    pub energy: f64,
    /// Record length (samples).
    pub sample_count: usize,
    /// `elevation_bin0` − N and `elevation_lastbin` − N (m, ALS datum through the nominal geoid).
    pub bin0: f64,
    pub lastbin: f64,
    /// The received waveform minus its noise mean (DN), for the waveform residual.
    pub wave: Vec<f32>,
    /// `selected_algorithm` (1..6).
    pub selected: u8,
    /// Products of a1..a6 that pass the study's filter (quality 1, degrade 0, sensitivity ≥ 0.9).
    pub algorithms: [Option<RealAlgorithm>; N_ALGORITHMS],
    /// Strata of the shot (labels of `study::classes`).
    pub strata: Strata,
    /// The collocation segment (shots sharing one offset; the shot number when not collocated):
    /// the unit re-placed together.
    pub segment: String,
    /// Vertical offset of the shot's collocation segment (`offsets.dz`: GEDI − N − ALS, m, from
    /// the cross-correlation of whole waveforms), when collocated.
    pub collocation_dz: Option<f64>,
    /// The shot's recorded transmit pulse on the simulation's bins (`SimShot::dz`), placed at its
    /// reference point (docs/pulse.md); `None` = the study's Gaussian.
    pub pulse: Option<std::sync::Arc<crate::sim::Pulse>>,
}

/// Strata labels of one shot for the "where" decomposition.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Strata {
    pub forest_type: String,
    pub phenology: String,
    pub sensitivity_group: String,
    pub beam_type: String,
    pub slope_class: String,
    pub cover_class: String,
}

impl Strata {
    /// (stratum kind, label) pairs.
    pub fn pairs(&self) -> [(&'static str, &str); 6] {
        [
            ("forest_type", &self.forest_type),
            ("phenology", &self.phenology),
            ("sensitivity_group", &self.sensitivity_group),
            ("beam_type", &self.beam_type),
            ("slope_class", &self.slope_class),
            ("cover_class", &self.cover_class),
        ]
    }
}

/// Ground and canopy parts of one weighting, without pulse, on the shot's common bin grid.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Parts {
    pub ground: Vec<f32>,
    pub canopy: Vec<f32>,
}

/// One footprint width's simulation of a shot: the parts of every weighting.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SimVariant {
    pub weightings: [Parts; N_WEIGHTINGS],
}

/// Spacing (m) of the grid of positions at which the shots of short collocation segments are
/// also simulated ([`site_grid`]).
pub const SITE_STEP_M: f64 = 2.0;
/// Positions per axis on each side of the grid's centre (a 5 × 5 grid: ±4 m).
pub const SITE_HALF: i32 = 2;
/// Segments of this many shots or more keep their collocated position: their shared offset is
/// pinned by many waveforms and absorbs little of a waveform-shape effect.
pub const SHORT_SEGMENT_SHOTS: usize = 10;

/// The grid of horizontal offsets (m) around its centre, row by row ([`SITE_HALF`],
/// [`SITE_STEP_M`]). A shot of a short segment has site 0 at its collocated position, then these
/// offsets around its segment's re-collocated centre (docs/diagnosis.md).
pub fn site_grid() -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    for i in -SITE_HALF..=SITE_HALF {
        for j in -SITE_HALF..=SITE_HALF {
            out.push((f64::from(i) * SITE_STEP_M, f64::from(j) * SITE_STEP_M));
        }
    }
    out
}

/// The simulation of a shot at one horizontal position: every [`FSIGMA_GRID`] width on one bin
/// grid (bin k at `z0 − k·dz`, ALS datum) — or, at the grid sites of a long segment's shot (used
/// by the `geolocation` hypotheses only), the nominal width alone, which then stands for every
/// width.
#[derive(Debug, Clone, PartialEq)]
pub struct Site {
    pub z0: f64,
    /// Empty when the position could not be simulated (never chosen).
    pub variants: Vec<SimVariant>,
    /// ALS ground at this position (count weighting, σ_f 5.5 m) (m).
    pub als_ground: f64,
    /// Horizontal position relative to the collocated one (site 0), m.
    pub offset: (f64, f64),
}

/// The simulated side of one shot: the collocated position (site 0) and the [`site_grid`] around
/// its segment's re-collocated centre (a short segment: every width) or around the collocated
/// position (a long segment: the nominal width), among which the hypotheses re-place the shot
/// (`chain::reposition`).
#[derive(Debug, Clone, PartialEq)]
pub struct SimShot {
    pub dz: f64,
    pub sites: Vec<Site>,
    /// The shot's collocation segment is short ([`SHORT_SEGMENT_SHOTS`]): every hypothesis
    /// re-places the segment as one. Other shots move only under a `geolocation` hypothesis.
    pub short_segment: bool,
    /// Noise-free RH0..RH100 of the study's physics (count, 15 ns pulse, 5.5 m) from the ALS
    /// ground at the collocated position: the study's baseline simulated RH.
    pub rh_nominal: Vec<f32>,
}

impl SimShot {
    /// The collocated position (the study's).
    pub fn collocated(&self) -> &Site {
        &self.sites[0]
    }
}

/// Everything the diagnosis needs about one shot.
#[derive(Debug, Clone, PartialEq)]
pub struct ShotCase {
    pub real: RealShot,
    /// Shared: the noise-twin null of a hypothesis (`chain::null_case`) reuses it.
    pub sim: std::sync::Arc<SimShot>,
    /// Algorithms whose real ground disagrees grossly with the nominal chain's (a different
    /// mode picked: [`crate::diagnose::flag_ground_mismatches`]); left out of every gap.
    pub mismatch: [bool; N_ALGORITHMS],
}

impl ShotCase {
    /// The selected algorithm's products, if they pass the filter.
    pub fn selected(&self) -> Option<&RealAlgorithm> {
        self.real.algorithms.get(usize::from(self.real.selected).wrapping_sub(1))?.as_ref()
    }
}

/// Median `noise_stddev_corrected` of real GEDI shots of a beam type (DN), measured on the shared
/// granule (docs/scenario.md): the noise σ of the nominal chain, against which the `noise`
/// effect's factor is expressed.
pub fn nominal_noise_stddev(beam_type: BeamType) -> f64 {
    crate::scenario::real::record(beam_type).noise_stddev
}

/// Give every shot its noise σ in the nominal chain: its reported σ rescaled so that the median
/// of its beam type is [`nominal_noise_stddev`]. The spread of noise levels between shots is kept
/// — L2A's ground and RH errors grow faster than linearly with the noise, so a twin at one median
/// σ for all shots would be biased against the real ones wherever the signal is weak (a wide
/// pulse, sparse canopy) — while the level stays nominal, so that a departure from it is the
/// `noise` effect's to explain. Without usable reported σ a shot gets the nominal σ.
pub fn set_nominal_noise(cases: &mut [ShotCase]) {
    for bt in [BeamType::Coverage, BeamType::FullPower] {
        let mut sd: Vec<f64> = cases
            .iter()
            .filter(|c| c.real.beam_type == bt)
            .map(|c| c.real.noise.stddev)
            .filter(|v| v.is_finite() && *v > 0.0)
            .collect();
        sd.sort_by(|a, b| a.total_cmp(b));
        let nominal = nominal_noise_stddev(bt);
        let scale = if sd.is_empty() { f64::NAN } else { nominal / sd[sd.len() / 2] };
        for c in cases.iter_mut().filter(|c| c.real.beam_type == bt) {
            let v = c.real.noise.stddev * scale;
            c.real.nominal_noise_stddev = if v.is_finite() && v > 0.0 { v } else { nominal };
        }
    }
}

/// Check the RH lists of a case (101 values each).
pub fn rh_ok(rh: &[f32]) -> bool {
    rh.len() == RH_LEN && rh.iter().all(|v| v.is_finite())
}

/// Vertical margin added above and below the simulated waveforms (m): room for the widest pulse
/// the diagnosis tries (σ 3.8 m, 4σ kernels).
pub const PAD_M: f64 = 16.0;

/// The simulator settings of the diagnosis: the study's nominal one (15 ns pulse, σ_f 5.5 m,
/// default profile) and the nominal chain's, simulated at every width of [`FSIGMA_GRID`]
/// ([`fsigma_grid`]): without pulse (the chain convolves its own), without the coverage skip (the
/// nominal run decides coverage), density normalised by pulse ([`NOMINAL_DENSITY`]).
pub fn configs() -> (SimConfig, SimConfig) {
    let nominal = SimConfig::new(Profile::Default);
    let chain = SimConfig {
        fsigma: FSIGMA_GRID[NOMINAL_WIDTH] as f32,
        pulse: sim::Pulse::dirac(),
        min_covered_fraction: None,
        density_count: NOMINAL_DENSITY,
        ..nominal.clone()
    };
    (nominal, chain)
}

/// [`FSIGMA_GRID`] as the simulator takes it.
pub fn fsigma_grid() -> [f32; FSIGMA_GRID.len()] {
    FSIGMA_GRID.map(|f| f as f32)
}

/// Search of the re-collocation of short segments: ±8 m every metre around the reported position.
pub const RECOLLOCATE_SHIFT_M: f64 = 8.0;

pub const RECOLLOCATE_STEP_M: f64 = 1.0;

/// Index of the nominal σ_f 5.5 m in [`FSIGMA_GRID`] (where a site's ALS ground is taken).
pub const NOMINAL_WIDTH: usize = 2;

/// Put every width's parts of one position on one bin grid with [`PAD_M`] of empty bins above
/// and below. The default profile's bins lie on one absolute lattice, so the grids differ by
/// whole bins.
pub fn site_of(vs: &[&sim::SimulatedFootprint], als_ground: f64, offset: (f64, f64)) -> Site {
    let dz = vs[0].dz;
    let top = vs.iter().map(|v| v.z0).fold(f64::NEG_INFINITY, f64::max) + PAD_M;
    let bottom = vs.iter().map(|v| v.z0 - (v.n_bins() as f64 - 1.0) * dz).fold(f64::INFINITY, f64::min) - PAD_M;
    let n = ((top - bottom) / dz).round() as usize + 1;
    let place = |src: &[f32], z0: f64| {
        let mut out = vec![0f32; n];
        let off = ((top - z0) / dz).round() as usize;
        for (k, &v) in src.iter().enumerate() {
            if let Some(o) = out.get_mut(off + k) {
                *o = v;
            }
        }
        out
    };
    let variants = vs
        .iter()
        .map(|v| SimVariant {
            weightings: Weighting::ALL.map(|w| {
                let p = v.get(w);
                Parts { ground: place(&p.ground, v.z0), canopy: place(&p.canopy, v.z0) }
            }),
        })
        .collect();
    Site { z0: top, variants, als_ground, offset }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nominal_width_is_the_nominal_footprint() {
        assert_eq!(FSIGMA_GRID[NOMINAL_WIDTH], crate::scenario::effects::NOMINAL_FSIGMA_M);
    }
}
