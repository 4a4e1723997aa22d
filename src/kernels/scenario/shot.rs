//! One pseudo-real shot: a simulated footprint made into a GEDI L1B record (effects, noise twin,
//! record window, ellipsoidal geolocation) and processed by our L2A kernel into L2A products as
//! NASA would, with the `ground_detection` effect applied to the stored products. Pure.

use super::effects::{EffectSet, Physics, WaveParts};
use crate::gedi::{BeamType, N_ALGORITHMS, RH_LEN};
use crate::gedi::{L1bShot, L2aAlgorithm, L2aShot, LandCover};
use crate::sim::{Pulse, PulseReference, SimulatedFootprint, TransmitPulse, Weighting};
use crate::waveform::forward::{forward, signal_span, L2aRunner, RecordWindow};
use crate::waveform::l2a::{L2aOutcome, Noise};
use crate::waveform::noise_twin::GEDI_BIN_M;

/// NASA's fill value for L2A fields without a result.
pub const FILL: f64 = -9999.0;
/// Minimum sensitivity of a valid shot (the land threshold of the L2A quality flag).
pub const MIN_SENSITIVITY: f64 = 0.9;
/// Order in which the selected algorithm is chosen: the first valid one (a1 as NASA's default).
pub const SELECTION_ORDER: [u8; N_ALGORITHMS] = [1, 2, 5, 3, 4, 6];

/// Everything about one shot that is not in the simulated footprint.
#[derive(Debug, Clone, PartialEq)]
pub struct ShotSpec {
    pub shot_number: u64,
    pub delta_time: f64,
    pub beam_type: BeamType,
    /// Reported (geolocated) latitude and longitude (degrees).
    pub lat: f64,
    pub lon: f64,
    /// Geoid height N stored in `geophys_corr/geoid` (m): ellipsoidal = orthometric + N.
    pub geoid_m: f64,
    /// Noise mean and σ of the record (DN); σ is also what the L1B reports.
    pub noise: Noise,
    /// Received energy above the noise mean (DN).
    pub energy: f64,
    /// Record top above the signal start (m).
    pub above_signal_m: f64,
    /// Record bottom below the ground (m).
    pub below_ground_m: f64,
    /// Seed of the noise draws.
    pub noise_seed: u64,
    /// Error of the TanDEM-X-like DEM value (m).
    pub dem_error_m: f64,
    /// Land-cover values written to the L2A.
    pub land_cover: LandCover,
    /// The recorded transmit pulse (`txwaveform`, 128 samples of DN).
    pub tx_waveform: Vec<f32>,
}

/// What was planted in one shot (for truth.json).
#[derive(Debug, Clone, PartialEq)]
pub struct ShotTruth {
    /// ALS ground (orthometric, m) under the true footprint, from the true-physics simulation.
    pub als_ground_m: f64,
    /// Canopy top (orthometric, m) from the same waveform.
    pub true_top_m: Option<f64>,
    /// ALS ground converted to GEDI's datum: als_ground + N + datum dz (m, ellipsoidal).
    pub gedi_ground_expected_m: f64,
    /// Noise σ of the record (DN).
    pub noise_stddev: f64,
}

/// Why a shot could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ShotError {
    #[error("simulated waveform has no ground")]
    NoGround,
    #[error("simulated waveform has no energy")]
    NoEnergy,
    #[error("noise twin: {0}")]
    Twin(#[from] crate::waveform::noise_twin::TwinError),
    #[error("record of {0} samples does not fit GEDI's uint16 count")]
    TooLong(usize),
}

/// Spread (normal σ, clipped to ±[`TX_STRETCH_CLIP`]) of a drawn pulse's time scale.
pub const TX_STRETCH_SIGMA: f64 = 0.03;
pub const TX_STRETCH_CLIP: f64 = 0.08;
/// Spread (samples) of where a drawn pulse's peak sits in its record, around the library's.
pub const TX_SHIFT_SAMPLES: f64 = 1.5;

/// One shot's transmit pulse drawn from a real recorded pulse of its laser (`library`, a raw L1B
/// `txwaveform`): the library pulse cleaned of its noise floor, stretched in time by 1 + ε and
/// shifted by a fraction of a sample, recorded again on the library's floor with fresh floor
/// noise. Returns the new record (what the L1B stores) and the noise-free pulse that forms the
/// received waveform, placed at `reference` as found on the new record (as GEDI's ranging finds
/// it on its own record) at bin size `res` (m). `None` when the library record has no pulse.
pub fn draw_transmit(
    library: &[f32],
    rng: &mut super::rng::Stream,
    reference: PulseReference,
    res: f64,
) -> Option<(Vec<f32>, Pulse)> {
    let lib = TransmitPulse::from_record(library).ok()?;
    let stretch = 1.0 + (TX_STRETCH_SIGMA * rng.normal()).clamp(-TX_STRETCH_CLIP, TX_STRETCH_CLIP);
    let shift = TX_SHIFT_SAMPLES * (rng.uniform() - 0.5) * 2.0;
    // New sample i holds the library's pulse at (i − shift − peak)/stretch + peak.
    let clean: Vec<f64> = (0..library.len())
        .map(|i| lib.sample_at((i as f64 - shift - lib.peak) / stretch + lib.peak) / stretch)
        .collect();
    let record: Vec<f32> = clean.iter().map(|&v| (lib.floor + v + lib.floor_sigma * rng.normal()) as f32).collect();
    let seen = TransmitPulse::from_record(&record).ok()?;
    let truth = TransmitPulse { samples: clean, ..seen };
    Some((record, truth.to_pulse(reference, res)))
}

/// Make the L1B and L2A records of one shot from its true-physics simulation.
pub fn make_shot(
    sim: &SimulatedFootprint,
    physics: &Physics,
    effects: &EffectSet,
    spec: &ShotSpec,
    l2a: &mut L2aRunner,
) -> Result<(L1bShot, L2aShot, ShotTruth), ShotError> {
    let w = sim.get(physics.weighting);
    // Ground of the count weighting when the effect's weighting has none (e.g. int with no ground intensity).
    let ground_z = w.truth.als_ground.or(sim.get(Weighting::Count).truth.als_ground).ok_or(ShotError::NoGround)?;
    let mut parts = WaveParts {
        ground: w.ground.iter().map(|&v| f64::from(v)).collect(),
        canopy: w.canopy.iter().map(|&v| f64::from(v)).collect(),
        z0: sim.z0,
        dz: sim.dz,
        ground_z,
    };
    effects.apply_waveform(&mut parts);
    let wave: Vec<f64> = parts.compose(physics.rho_ground_over_veg).into_iter().map(|v| v.max(0.0)).collect();
    let (first, signal) = signal_span(&wave).ok_or(ShotError::NoEnergy)?;
    let z_first = sim.z0 - first as f64 * sim.dz;

    // Record window (orthometric): top above the signal start, bottom below the ground, on a
    // 1 ns grid that holds the signal's first sample exactly.
    let top_target = z_first + spec.above_signal_m;
    let start = ((top_target - z_first) / GEDI_BIN_M).round() as isize;
    let bin0_ortho = z_first + start as f64 * GEDI_BIN_M;
    let bottom = (ground_z - spec.below_ground_m).min(z_first - (signal.len() as f64 + 2.0) * sim.dz);
    let n = ((bin0_ortho - bottom) / GEDI_BIN_M).ceil() as usize + 1;
    if n > usize::from(u16::MAX) {
        return Err(ShotError::TooLong(n));
    }
    let datum = effects.vertical_offset_m();
    let elevation_bin0 = bin0_ortho + spec.geoid_m + datum;
    let elevation_lastbin = elevation_bin0 - (n - 1) as f64 * GEDI_BIN_M;
    let window = RecordWindow { sample_count: n, start, bin0: elevation_bin0, lastbin: elevation_lastbin };
    let twin = forward(signal, sim.dz, &window, spec.energy, spec.noise, spec.noise_seed, l2a)?;
    let dem = ground_z + spec.geoid_m + spec.dem_error_m;
    let l1b = L1bShot {
        shot_number: spec.shot_number,
        delta_time: spec.delta_time,
        rx_waveform: twin.wave.clone(),
        tx_waveform: spec.tx_waveform.clone(),
        latitude_bin0: spec.lat,
        longitude_bin0: spec.lon,
        latitude_lastbin: spec.lat,
        longitude_lastbin: spec.lon,
        elevation_bin0,
        elevation_lastbin,
        noise_mean_corrected: twin.noise.mean,
        noise_stddev_corrected: twin.noise.stddev,
        stale_return_flag: 0,
        degrade: 0,
        geoid: spec.geoid_m as f32,
        digital_elevation_model: dem as f32,
    };

    let energy_total: f64 = twin.wave.iter().map(|&v| f64::from(v) - twin.noise.mean).sum();
    let mut shot = L2aShot {
        shot_number: spec.shot_number,
        delta_time: spec.delta_time,
        degrade_flag: 0,
        energy_total: energy_total as f32,
        land_cover: spec.land_cover.clone(),
        ..Default::default()
    };
    for (i, outcome) in l2a.outcomes.iter().enumerate().take(N_ALGORITHMS) {
        let alg = (i + 1) as u8;
        shot.algorithms[i] = algorithm_products(outcome, effects.ground_offset_m(alg), spec, dem);
    }
    let selected =
        SELECTION_ORDER.iter().copied().find(|&a| shot.algorithms[usize::from(a) - 1].quality_flag == 1).unwrap_or(1);
    shot.select_algorithm(selected);
    let truth = ShotTruth {
        als_ground_m: ground_z,
        true_top_m: w.truth.true_top,
        gedi_ground_expected_m: ground_z + spec.geoid_m + datum,
        noise_stddev: twin.noise.stddev,
    };
    Ok((l1b, shot, truth))
}

/// The stored products of one algorithm, with the ground-detection offset `offset_m` applied
/// (ground up by `offset_m`: elevation + offset, RH − offset, zcross moved to match).
fn algorithm_products(outcome: &L2aOutcome, offset_m: f64, spec: &ShotSpec, dem: f64) -> L2aAlgorithm {
    let Ok(r) = outcome else {
        return L2aAlgorithm {
            elev_lowestmode: FILL as f32,
            lat_lowestmode: FILL,
            lon_lowestmode: FILL,
            rh_cm: vec![0; RH_LEN],
            sensitivity: 0.0,
            quality_flag: 0,
            toploc: FILL as f32,
            botloc: FILL as f32,
            zcross: FILL as f32,
        };
    };
    let elev = r.elev_lowestmode + offset_m;
    let shift_cm = offset_m * 100.0;
    let rh_cm = r
        .rh_cm
        .iter()
        .map(|&cm| {
            let v = if offset_m == 0.0 { f64::from(cm) } else { (f64::from(cm) - shift_cm).trunc() };
            v.clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
        })
        .collect();
    let valid = r.sensitivity >= MIN_SENSITIVITY && (elev - dem).abs() <= 100.0;
    L2aAlgorithm {
        elev_lowestmode: elev as f32,
        lat_lowestmode: spec.lat,
        lon_lowestmode: spec.lon,
        rh_cm,
        sensitivity: r.sensitivity as f32,
        quality_flag: u8::from(valid),
        toploc: r.toploc as f32,
        botloc: r.botloc as f32,
        zcross: (r.zcross - offset_m / GEDI_BIN_M) as f32,
    }
}
