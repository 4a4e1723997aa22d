//! Constants of real GEDI L1B records that a pseudo-real world reproduces, **measured** on the
//! shared V1 granule `tests/data/gedi/GEDI01_B_2019108080338_O01964_T05337_02_003_01_sub.h5`
//! (300 shots: 112 coverage, 188 full power) joined with its L2A by `shot_number`. The test
//! `scenario_constants_match_the_real_granule` (tests/scenario.rs) re-measures the noise and
//! energy medians from the file through our reader. Method and commands: docs/scenario.md.

use crate::gedi::BeamType;

/// Typical record of one beam type (medians over the granule's shots of that type).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BeamTypeRecord {
    /// Median `noise_stddev_corrected` (DN).
    pub noise_stddev: f64,
    /// Median `noise_mean_corrected` (DN).
    pub noise_mean: f64,
    /// Median `rx_energy` (DN, Σ of samples above the noise mean).
    pub energy: f64,
    /// Median distance from the first record sample down to the signal start (`elevation_bin0 −
    /// elev_highestreturn_a1`, m).
    pub above_signal_m: f64,
    /// Median distance from the ground mode down to the last record sample
    /// (`elev_lowestmode − elevation_lastbin`, m).
    pub below_ground_m: f64,
}

/// Coverage beams (BEAM0000–0011): noise σ 2.534 DN, mean 241.06 DN, energy 6896 DN, record
/// top 44.0 m above the signal start (49.0 m above ground − 5.0 m signal height), record bottom
/// 65.3 m below the ground mode; `rx_sample_count` median 767.
pub const COVERAGE: BeamTypeRecord = BeamTypeRecord {
    noise_stddev: 2.534,
    noise_mean: 241.06,
    energy: 6896.0,
    above_signal_m: 44.0,
    below_ground_m: 65.3,
};

/// Full-power beams (BEAM0101, 0110, 1000, 1011): noise σ 3.288 DN, mean 227.44 DN, energy
/// 16268 DN, record top 44.5 m above the signal start (50.2 − 5.75), bottom 68.4 m below the
/// ground mode; `rx_sample_count` median 797.5.
pub const FULL_POWER: BeamTypeRecord = BeamTypeRecord {
    noise_stddev: 3.288,
    noise_mean: 227.44,
    energy: 16268.0,
    above_signal_m: 44.5,
    below_ground_m: 68.4,
};

/// Shot-to-shot spread (log-normal σ) of the noise σ: the granule's 10–90 % range is ±7 % of
/// the median for both beam types.
pub const NOISE_STDDEV_LOG_SPREAD: f64 = 0.07;
/// Shot-to-shot spread (log-normal σ) of the received energy: 10–90 % is about ±15 %.
pub const ENERGY_LOG_SPREAD: f64 = 0.13;
/// Shot-to-shot spread of the noise mean (DN, normal σ; 10–90 % 240.6–245.4 for coverage).
pub const NOISE_MEAN_SPREAD: f64 = 2.0;

/// The typical record of a beam type.
pub fn record(beam_type: BeamType) -> BeamTypeRecord {
    match beam_type {
        BeamType::Coverage => COVERAGE,
        BeamType::FullPower => FULL_POWER,
    }
}
