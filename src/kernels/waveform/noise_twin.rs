//! Noise twin: turns a noise-free simulated waveform into a GEDI-like received waveform that the
//! L2A kernel ([`crate::waveform::l2a`]) processes like a real one.
//!
//! Both modes resample the simulated waveform (top to bottom, any normalisation) to GEDI's 1 ns
//! grid, scale it to digitiser counts (DN), add Gaussian noise on a DC level and quantise:
//! - [`ShotTwin`] (mode a) copies one real shot: its energy (gain), noise mean and σ, record length
//!   and optionally its transmit pulse; the noise has the correlation and per-sample level of real
//!   GEDI records ([`NoiseShape::GEDI_V1`], measured) or is white.
//! - [`LinkMarginTwin`] (mode b) is gediMetric's link-margin model (docs/simulator-reference.md §2.3):
//!   σ solved from a link margin in dB, signal rescaled so that the noise is `true_sig` DN on an
//!   `offset` DN level, 12-bit floor digitisation.
//!
//! Noise is drawn from a ChaCha8 generator seeded explicitly: the same seed gives the same twin.

use rand_chacha::rand_core::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::waveform::l2a::Noise;

/// GEDI sample spacing in range: 1 ns two-way travel time, c·1 ns / 2 (m).
pub const GEDI_BIN_M: f64 = 0.149_896_229;

/// Default bin size of simulated waveforms (gediRat `-res`, m).
pub const SIM_BIN_M: f64 = 0.15;

/// Why a twin could not be made.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum TwinError {
    /// The simulated waveform is empty.
    #[error("empty simulated waveform")]
    Empty,
    /// A sample, parameter or pulse value is NaN or infinite, or a size parameter is not positive.
    #[error("invalid value for {0}")]
    Invalid(&'static str),
    /// The record (or the simulated signal on the GEDI grid) would be longer than
    /// [`MAX_RECORD_SAMPLES`].
    #[error("record longer than {samples} samples")]
    TooLong {
        /// The limit.
        samples: usize,
    },
    /// The simulated waveform carries no positive energy, so it cannot be scaled to a gain.
    #[error("simulated waveform has no positive energy")]
    NoEnergy,
    /// The waveform placed at `start` has non-zero samples outside the record.
    #[error("signal of {signal} samples placed at sample {start} has energy outside a record of {record} samples")]
    DoesNotFit {
        /// Record sample of the signal's first sample (negative: before the record).
        start: isize,
        /// Signal length on the GEDI grid (samples).
        signal: usize,
        /// Record length (samples).
        record: usize,
    },
}

/// A GEDI-like waveform and the noise statistics the L2A kernel should use for it.
#[derive(Debug, Clone, PartialEq)]
pub struct TwinWaveform {
    /// Received waveform (DN), top to bottom, on the 1 ns grid.
    pub wave: Vec<f32>,
    /// Noise mean and σ of the twin's noise model (after quantisation).
    pub noise: Noise,
}

/// Linearly resample a waveform with bins of `input_bin_m` onto GEDI's [`GEDI_BIN_M`] grid, sample
/// 0 on sample 0; the output covers the same vertical extent.
pub fn resample_to_gedi(wave: &[f64], input_bin_m: f64) -> Vec<f64> {
    if wave.is_empty() || !input_bin_m.is_finite() || input_bin_m <= 0.0 {
        return Vec::new();
    }
    let extent = (wave.len() - 1) as f64 * input_bin_m;
    let n_out = (extent / GEDI_BIN_M).floor() as usize + 1;
    let last = wave.len() - 1;
    (0..n_out)
        .map(|j| {
            let x = j as f64 * GEDI_BIN_M / input_bin_m;
            let i = (x.floor() as usize).min(last);
            let f = x - i as f64;
            wave[i] * (1.0 - f) + wave[(i + 1).min(last)] * f
        })
        .collect()
}

/// The shape of a twin's noise: N(0,1) draws filtered by a discrete Gaussian of σ = `correlation`
/// samples (0 = white), scaled so that one sample has the standard deviation `per_sample_ratio`·σ,
/// where σ is the noise σ the shot reports (and L2A's thresholds use).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseShape {
    /// σ (samples) of the Gaussian filter that correlates neighbouring samples; 0 = white noise.
    pub correlation: f64,
    /// Standard deviation of one sample of the record over the reported noise σ.
    pub per_sample_ratio: f64,
}

impl NoiseShape {
    /// Independent samples of standard deviation σ.
    pub const WHITE: NoiseShape = NoiseShape { correlation: 0.0, per_sample_ratio: 1.0 };

    /// The noise of real GEDI L1B records, **measured** on the noise-only samples (before the
    /// signal) of the shared V1 granule's calibration half (docs/l2a.md "Noise of the real
    /// records"): one sample has 0.52× the reported `noise_stddev_corrected`, and neighbouring
    /// samples are correlated as Gaussian-filtered white noise with σ 1.63 samples
    /// (autocorrelation 0.91, 0.70, 0.44, 0.22 at lags 1–4). After L2A's smoothing this noise
    /// has the level of the real records' noise; white noise of σ is 20–30 % weaker.
    pub const GEDI_V1: NoiseShape = NoiseShape { correlation: 1.63, per_sample_ratio: 0.52 };

    fn is_valid(&self) -> bool {
        self.correlation.is_finite()
            && self.correlation >= 0.0
            && self.per_sample_ratio.is_finite()
            && self.per_sample_ratio >= 0.0
    }

    /// Filter taps, normalised to unit energy (Σ t² = 1) so that the filtered draws keep unit
    /// variance; a single tap for white noise.
    fn taps(&self) -> Vec<f64> {
        if self.correlation <= 0.0 {
            return vec![1.0];
        }
        let half = (4.0 * self.correlation).ceil() as i64;
        let taps: Vec<f64> = (-half..=half).map(|j| (-0.5 * (j as f64 / self.correlation).powi(2)).exp()).collect();
        let norm = taps.iter().map(|t| t * t).sum::<f64>().sqrt();
        taps.into_iter().map(|t| t / norm).collect()
    }
}

/// `n` noise draws of unit per-sample variance with the correlation of `shape`, from `seed`.
/// White noise is the plain N(0,1) stream of the seed.
fn noise_draws(n: usize, shape: &NoiseShape, seed: u64) -> Vec<f64> {
    let taps = shape.taps();
    let mut normal = NormalSource::new(seed);
    let white: Vec<f64> = (0..n + taps.len() - 1).map(|_| normal.sample()).collect();
    (0..n).map(|i| taps.iter().zip(&white[i..]).map(|(t, w)| t * w).sum()).collect()
}

/// Mode (a): a twin of one real shot.
#[derive(Debug, Clone, PartialEq)]
pub struct ShotTwin {
    /// Σ (sample − noise mean) of the real shot (DN): the signal is scaled to this energy.
    pub energy_total: f64,
    /// Noise mean and σ of the real shot (DN).
    pub noise: Noise,
    /// Record length of the real shot (`rx_sample_count`).
    pub sample_count: usize,
    /// Transmit pulse of the real shot (`txwaveform`, DN, 1 ns samples) to convolve with, or
    /// `None` when the simulated waveform already contains the pulse.
    pub tx_pulse: Option<Vec<f32>>,
    /// Quantisation step (DN); values are rounded to the nearest multiple (0 = no quantisation).
    pub quantum: f64,
    /// Correlation and per-sample level of the noise ([`NoiseShape::GEDI_V1`] for real GEDI
    /// records, [`NoiseShape::WHITE`] for independent samples of σ).
    pub noise_shape: NoiseShape,
}

impl ShotTwin {
    /// Make the twin waveform: `sim` (bins of `input_bin_m`, top to bottom) placed with its first
    /// bin at record sample `start`, noise drawn from `seed`. `start` may be negative and the
    /// signal may run past the record's end, as long as what falls outside is zero (a simulation's
    /// empty buffer above the canopy and below the ground).
    pub fn apply(&self, sim: &[f64], input_bin_m: f64, start: isize, seed: u64) -> Result<TwinWaveform, TwinError> {
        check_signal(sim, input_bin_m)?;
        if !self.energy_total.is_finite() || self.energy_total <= 0.0 {
            return Err(TwinError::Invalid("energy_total"));
        }
        if !self.noise.mean.is_finite() || !self.noise.stddev.is_finite() || self.noise.stddev < 0.0 {
            return Err(TwinError::Invalid("noise"));
        }
        if !self.quantum.is_finite() || self.quantum < 0.0 {
            return Err(TwinError::Invalid("quantum"));
        }
        if !self.noise_shape.is_valid() {
            return Err(TwinError::Invalid("noise_shape"));
        }
        if self.sample_count > MAX_RECORD_SAMPLES {
            return Err(TwinError::TooLong { samples: MAX_RECORD_SAMPLES });
        }
        let mut signal = resample_to_gedi(sim, input_bin_m);
        if let Some(pulse) = &self.tx_pulse {
            signal = convolve_with_pulse(&signal, &normalised_pulse(pulse)?);
        }
        let energy: f64 = signal.iter().sum();
        if energy.is_nan() || energy <= 0.0 {
            return Err(TwinError::NoEnergy);
        }
        let gain = self.energy_total / energy;
        let mut record = place(&signal, start, self.sample_count)?;
        record.iter_mut().for_each(|v| *v *= gain);
        let draws = noise_draws(record.len(), &self.noise_shape, seed);
        let sample_sigma = self.noise.stddev * self.noise_shape.per_sample_ratio;
        let wave = record
            .iter()
            .zip(&draws)
            .map(|(&s, &d)| {
                let x = s + self.noise.mean + sample_sigma * d;
                (if self.quantum > 0.0 { (x / self.quantum).round() * self.quantum } else { x }) as f32
            })
            .collect();
        // The reported σ is the shot's (what L2A's thresholds use). Rounding adds a uniform
        // error of variance q²/12 and no bias.
        let stddev = (self.noise.stddev.powi(2) + self.quantum.powi(2) / 12.0).sqrt();
        Ok(TwinWaveform { wave, noise: Noise { mean: self.noise.mean, stddev } })
    }
}

/// Mode (b): gediMetric's link-margin noise model (docs/simulator-reference.md §2.3, §4).
#[derive(Debug, Clone, PartialEq)]
pub struct LinkMarginTwin {
    /// Link margin (dB) at the reference canopy cover `cover`.
    pub link_margin_db: f64,
    /// Reference canopy cover at which the link margin holds (0..1).
    pub cover: f64,
    /// True canopy cover of this waveform, if known (the reference uses 0 when unknown).
    pub true_cover: Option<f64>,
    /// Pulse σ used to find σ_link (m; `-linkPsig`).
    pub pulse_sigma_m: f64,
    /// Footprint σ used to find σ_link (m; `-linkFsig`).
    pub footprint_sigma_m: f64,
    /// Canopy reflectance ρv.
    pub rho_v: f64,
    /// Ground reflectance ρg.
    pub rho_g: f64,
    /// Noise σ in DN after rescaling (`-trueSig`).
    pub true_sig: f64,
    /// DC level in DN (`-dcBias`).
    pub offset: f64,
    /// Digitiser bits (`-bitRate`).
    pub bits: u32,
    /// Full scale in DN (`-maxDN`).
    pub max_dn: f64,
    /// Number of samples before the signal starts in the record (noise only).
    pub pre_samples: usize,
    /// Number of samples after the signal ends in the record (noise only).
    pub post_samples: usize,
}

/// False-alarm rate of the link-margin definition: 5 % per 30 m of range at 0.15 m bins.
const FALSE_ALARM_PER_BIN: f64 = 0.05 / (30.0 / 0.15);
/// Missed-detection rate of the link-margin definition (10 %).
const MISSED_DETECTION: f64 = 0.1;
/// Ground slope assumed by the link-margin definition (degrees).
const LINK_SLOPE_DEG: f64 = 2.0;

impl LinkMarginTwin {
    /// The reference defaults (pSig 0.764331 m, fSig 5.5 m, ρv 0.57, ρg 0.40, 5 DN noise on 94 DN,
    /// 12 bits over 4096 DN) for a link margin and reference cover; 200 noise samples each side.
    pub fn new(link_margin_db: f64, cover: f64) -> Self {
        Self {
            link_margin_db,
            cover,
            true_cover: None,
            pulse_sigma_m: 0.764_331,
            footprint_sigma_m: 5.5,
            rho_v: 0.57,
            rho_g: 0.40,
            true_sig: 5.0,
            offset: 94.0,
            bits: 12,
            max_dn: 4096.0,
            pre_samples: 200,
            post_samples: 200,
        }
    }

    /// σ_link: the noise σ (in units of a waveform of unit energy per metre) at which the ground
    /// return of a canopy of the reference cover has the requested link margin.
    ///
    /// Solves `10·log10((A − nS·σ)/(nN·σ)) = link_margin_db` in closed form; the reference finds
    /// the same root by step halving to 0.00015 dB.
    pub fn sigma_link(&self) -> f64 {
        let sigma_eff =
            (self.pulse_sigma_m.powi(2) + (self.footprint_sigma_m * LINK_SLOPE_DEG.to_radians().tan()).powi(2)).sqrt();
        let g = (1.0 - self.cover) * self.rho_g;
        let amplitude = (g / (g + self.rho_v * self.cover)) / (sigma_eff * (2.0 * std::f64::consts::PI).sqrt());
        let n_noise = gaussian_quantile(1.0 - FALSE_ALARM_PER_BIN);
        let n_signal = gaussian_quantile(1.0 - MISSED_DETECTION);
        let ratio = 10f64.powf(self.link_margin_db / 10.0);
        amplitude / (n_signal + n_noise * ratio)
    }

    /// Make the twin of `sim` (bins of `input_bin_m`, top to bottom) with noise drawn from `seed`.
    pub fn apply(&self, sim: &[f64], input_bin_m: f64, seed: u64) -> Result<TwinWaveform, TwinError> {
        check_signal(sim, input_bin_m)?;
        let params = [self.link_margin_db, self.cover, self.true_sig, self.offset, self.max_dn, self.rho_v, self.rho_g];
        if params.iter().any(|p| !p.is_finite()) || self.true_sig <= 0.0 || self.max_dn <= 0.0 || self.bits == 0 {
            return Err(TwinError::Invalid("link-margin parameters"));
        }
        if !(0.0..1.0).contains(&self.cover) {
            return Err(TwinError::Invalid("cover"));
        }
        let signal = resample_to_gedi(sim, input_bin_m);
        let total: f64 = signal.iter().map(|&w| w - w.min(0.0)).sum::<f64>() * GEDI_BIN_M;
        if total.is_nan() || total <= 0.0 {
            return Err(TwinError::NoEnergy);
        }
        let c = self.true_cover.unwrap_or(0.0);
        let refl_scale = (c * self.rho_v + (1.0 - c) * self.rho_g) * total
            / (self.cover * self.rho_v + (1.0 - self.cover) * self.rho_g);
        let sigma = self.sigma_link() * refl_scale;
        let n = self.pre_samples + signal.len() + self.post_samples;
        let record = place(&signal, self.pre_samples as isize, n)?;
        let step = self.max_dn / 2f64.powi(self.bits as i32);
        let top = self.max_dn - step;
        let mut normal = NormalSource::new(seed);
        let wave = record
            .iter()
            .map(|&s| {
                let x = (s + sigma * normal.sample()) * self.true_sig / sigma + self.offset;
                ((x / step).floor() * step).clamp(0.0, top) as f32
            })
            .collect();
        // Floor digitisation lowers the mean by half a step and adds step²/12 of variance.
        let noise =
            Noise { mean: self.offset - step / 2.0, stddev: (self.true_sig.powi(2) + step.powi(2) / 12.0).sqrt() };
        Ok(TwinWaveform { wave, noise })
    }
}

/// Rejects empty or non-finite simulated waveforms and bad bin sizes.
fn check_signal(sim: &[f64], input_bin_m: f64) -> Result<(), TwinError> {
    if sim.is_empty() {
        return Err(TwinError::Empty);
    }
    if sim.iter().any(|v| !v.is_finite()) {
        return Err(TwinError::Invalid("simulated waveform"));
    }
    if !input_bin_m.is_finite() || input_bin_m <= 0.0 {
        return Err(TwinError::Invalid("input_bin_m"));
    }
    if (sim.len() - 1) as f64 * input_bin_m / GEDI_BIN_M >= MAX_RECORD_SAMPLES as f64 {
        return Err(TwinError::TooLong { samples: MAX_RECORD_SAMPLES });
    }
    Ok(())
}

/// The longest record a twin makes: 100,000 GEDI samples (15 km of range; a real record has
/// about 1,000). Longer requests are errors, not allocations.
pub const MAX_RECORD_SAMPLES: usize = 100_000;

/// A record of `len` zeros with `signal[k]` at record sample `start + k`; samples falling outside
/// the record must be zero.
fn place(signal: &[f64], start: isize, len: usize) -> Result<Vec<f64>, TwinError> {
    let mut record = vec![0.0; len];
    for (k, &v) in signal.iter().enumerate() {
        let r = start + k as isize;
        match usize::try_from(r).ok().and_then(|r| record.get_mut(r)) {
            Some(slot) => *slot = v,
            None if v == 0.0 => {}
            None => return Err(TwinError::DoesNotFit { start, signal: signal.len(), record: len }),
        }
    }
    Ok(record)
}

/// The transmit pulse minus its baseline (median of its samples), clipped at 0, to unit sum.
fn normalised_pulse(pulse: &[f32]) -> Result<Vec<f64>, TwinError> {
    if pulse.is_empty() || pulse.iter().any(|v| !v.is_finite()) {
        return Err(TwinError::Invalid("tx_pulse"));
    }
    let mut sorted: Vec<f64> = pulse.iter().map(|&v| f64::from(v)).collect();
    sorted.sort_by(f64::total_cmp);
    // The pulse occupies a small part of the 128-sample record: the median is the baseline.
    let baseline = sorted[sorted.len() / 2];
    let p: Vec<f64> = pulse.iter().map(|&v| (f64::from(v) - baseline).max(0.0)).collect();
    let sum: f64 = p.iter().sum();
    if sum.is_nan() || sum <= 0.0 {
        return Err(TwinError::Invalid("tx_pulse"));
    }
    Ok(p.into_iter().map(|v| v / sum).collect())
}

/// Convolution of `signal` with `pulse`, centred on the pulse peak, same length as `signal`.
fn convolve_with_pulse(signal: &[f64], pulse: &[f64]) -> Vec<f64> {
    let peak = pulse.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)).map_or(0, |(i, _)| i);
    let n = signal.len() as isize;
    (0..n)
        .map(|i| {
            pulse
                .iter()
                .enumerate()
                .filter_map(|(j, &p)| {
                    let k = i - (j as isize - peak as isize);
                    (0..n).contains(&k).then(|| p * signal[k as usize])
                })
                .sum()
        })
        .collect()
}

/// Quantile of the unit Gaussian by the reference's method: integrate the density upward from 0
/// in steps of 2.5·10⁻⁵ until the cumulative probability reaches `p` (p ≥ 0.5).
fn gaussian_quantile(p: f64) -> f64 {
    const STEP: f64 = 2.5e-5;
    let density = |x: f64| (-0.5 * x * x).exp() / (2.0 * std::f64::consts::PI).sqrt();
    let (mut x, mut cumulative) = (0.0, 0.5);
    while cumulative < p && x < 40.0 {
        cumulative += density(x + STEP / 2.0) * STEP;
        x += STEP;
    }
    x
}

/// Seeded N(0,1) draws: Marsaglia's polar method on a ChaCha8 stream.
struct NormalSource {
    rng: ChaCha8Rng,
    spare: Option<f64>,
}

impl NormalSource {
    fn new(seed: u64) -> Self {
        Self { rng: ChaCha8Rng::seed_from_u64(seed), spare: None }
    }

    /// Uniform in [−1, 1).
    fn uniform(&mut self) -> f64 {
        (self.rng.next_u64() >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }

    fn sample(&mut self) -> f64 {
        if let Some(s) = self.spare.take() {
            return s;
        }
        loop {
            let (u, v) = (self.uniform(), self.uniform());
            let s = u * u + v * v;
            if s > 0.0 && s < 1.0 {
                let f = (-2.0 * s.ln() / s).sqrt();
                self.spare = Some(v * f);
                return u * f;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn link_margin_thresholds_match_the_reference() {
        assert!((gaussian_quantile(1.0 - FALSE_ALARM_PER_BIN) - 3.48).abs() < 0.01);
        assert!((gaussian_quantile(0.9) - 1.28).abs() < 0.01);
        // The solved σ gives back the requested link margin.
        let t = LinkMarginTwin::new(3.0, 0.9);
        let s = t.sigma_link();
        let sigma_eff = (0.764_331f64.powi(2) + (5.5 * 2f64.to_radians().tan()).powi(2)).sqrt();
        let g = 0.1 * 0.4;
        let a = (g / (g + 0.57 * 0.9)) / (sigma_eff * (2.0 * std::f64::consts::PI).sqrt());
        let db = 10.0 * ((a - gaussian_quantile(0.9) * s) / (gaussian_quantile(1.0 - FALSE_ALARM_PER_BIN) * s)).log10();
        assert!((db - 3.0).abs() < 1e-9);
    }

    #[test]
    fn normal_draws_are_seeded_and_standard() {
        let draw = |seed| {
            let mut n = NormalSource::new(seed);
            (0..20_000).map(|_| n.sample()).collect::<Vec<_>>()
        };
        let a = draw(7);
        assert_eq!(a, draw(7));
        assert_ne!(a, draw(8));
        let mean = a.iter().sum::<f64>() / a.len() as f64;
        let var = a.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / a.len() as f64;
        assert!(mean.abs() < 0.03 && (var - 1.0).abs() < 0.03, "mean {mean} var {var}");
    }

    #[test]
    fn resampling_keeps_the_extent_and_shape() {
        let sim: Vec<f64> = (0..1001).map(|i| (-0.5 * ((i as f64 - 500.0) / 20.0).powi(2)).exp()).collect();
        let r = resample_to_gedi(&sim, SIM_BIN_M);
        assert_eq!(r.len(), (1000.0 * 0.15 / GEDI_BIN_M).floor() as usize + 1);
        let peak = r.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)).map(|(i, _)| i).unwrap_or(0);
        assert!((peak as f64 * GEDI_BIN_M - 75.0).abs() < GEDI_BIN_M);
        assert!(resample_to_gedi(&[], 0.15).is_empty());
    }

    #[test]
    fn shot_twin_matches_the_shot_energy_and_noise() {
        let sim: Vec<f64> = (0..400).map(|i| (-0.5 * ((i as f64 - 200.0) / 6.0).powi(2)).exp()).collect();
        let twin = ShotTwin {
            energy_total: 10_000.0,
            noise: Noise { mean: 220.0, stddev: 3.0 },
            sample_count: 1000,
            tx_pulse: None,
            quantum: 1.0,
            noise_shape: NoiseShape::WHITE,
        };
        let t = twin.apply(&sim, GEDI_BIN_M, 300, 42).expect("twin");
        assert_eq!(t.wave.len(), 1000);
        assert_eq!(t.wave, twin.apply(&sim, GEDI_BIN_M, 300, 42).expect("twin").wave);
        let energy: f64 = t.wave.iter().map(|&w| f64::from(w) - 220.0).sum();
        assert!((energy - 10_000.0).abs() < 400.0, "energy {energy}");
        let pre = &t.wave[..250];
        let m = pre.iter().map(|&v| f64::from(v)).sum::<f64>() / 250.0;
        assert!((m - 220.0).abs() < 0.6);
        assert!(t.wave.iter().all(|v| v.fract() == 0.0));
        assert_eq!(
            twin.apply(&sim, GEDI_BIN_M, 700, 1),
            Err(TwinError::DoesNotFit { start: 700, signal: 400, record: 1000 })
        );
        // Zero samples may fall outside the record (a simulation's empty buffers), energy may not.
        let mut padded = vec![0.0; 50];
        padded.extend(&sim);
        padded.extend([0.0; 50]);
        let shifted = twin.apply(&padded, GEDI_BIN_M, 250, 42).expect("twin");
        assert_eq!(shifted.wave, t.wave, "the same signal at the same record samples");
        let inside = twin.apply(&padded, GEDI_BIN_M, -50, 42).expect("zeros before the record");
        let peak = inside.wave.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)).map(|(i, _)| i);
        assert!(peak.is_some_and(|p| p.abs_diff(200) <= 3), "peak at {peak:?}");
        assert_eq!(
            twin.apply(&padded, GEDI_BIN_M, -51, 42),
            Err(TwinError::DoesNotFit { start: -51, signal: 500, record: 1000 })
        );
        assert_eq!(twin.apply(&[], GEDI_BIN_M, 0, 1), Err(TwinError::Empty));
        assert_eq!(twin.apply(&[0.0, f64::NAN, 1.0], GEDI_BIN_M, 0, 1), Err(TwinError::Invalid("simulated waveform")));
        let no_noise = ShotTwin { noise: Noise { mean: 220.0, stddev: f64::NAN }, ..twin.clone() };
        assert_eq!(no_noise.apply(&sim, GEDI_BIN_M, 0, 1), Err(TwinError::Invalid("noise")));
        assert_eq!(twin.apply(&[0.0; 10], GEDI_BIN_M, 0, 1), Err(TwinError::NoEnergy));
        let with_pulse = ShotTwin { tx_pulse: Some(vec![10.0, 10.0, 30.0, 90.0, 30.0, 10.0, 10.0]), ..twin.clone() };
        assert!(with_pulse.apply(&sim, GEDI_BIN_M, 300, 42).is_ok());
    }

    #[test]
    fn correlated_noise_has_the_requested_level_and_correlation() {
        let shape = NoiseShape::GEDI_V1;
        let d = noise_draws(200_000, &shape, 5);
        assert_eq!(d, noise_draws(200_000, &shape, 5));
        let n = d.len() as f64;
        let var = d.iter().map(|x| x * x).sum::<f64>() / n;
        let lag = |l: usize| d.iter().zip(&d[l..]).map(|(a, b)| a * b).sum::<f64>() / n / var;
        assert!((var - 1.0).abs() < 0.02, "variance {var}");
        for l in 1..=4 {
            // Gaussian-filtered white noise: autocorrelation exp(−l²/(4σ²)).
            let expected = (-((l * l) as f64) / (4.0 * shape.correlation.powi(2))).exp();
            assert!((lag(l) - expected).abs() < 0.02, "lag {l}: {} vs {expected}", lag(l));
        }
        // White noise is the plain stream of the seed.
        let mut normal = NormalSource::new(5);
        let plain: Vec<f64> = (0..100).map(|_| normal.sample()).collect();
        assert_eq!(noise_draws(100, &NoiseShape::WHITE, 5), plain);
    }

    #[test]
    fn link_margin_twin_has_the_reference_noise_level() {
        let sim: Vec<f64> = (0..600).map(|i| (-0.5 * ((i as f64 - 300.0) / 6.0).powi(2)).exp()).collect();
        let twin = LinkMarginTwin::new(5.0, 0.95);
        let t = twin.apply(&sim, SIM_BIN_M, 3).expect("twin");
        let pre: Vec<f64> = t.wave[..200].iter().map(|&v| f64::from(v)).collect();
        let m = pre.iter().sum::<f64>() / 200.0;
        let sd = (pre.iter().map(|v| (v - m).powi(2)).sum::<f64>() / 199.0).sqrt();
        assert!((m - 93.5).abs() < 1.0, "mean {m}");
        assert!((sd - 5.0).abs() < 0.8, "sd {sd}");
        assert!(t.wave.iter().all(|&v| (0.0..4096.0).contains(&v) && v.fract() == 0.0));
        assert_eq!(LinkMarginTwin::new(5.0, 1.0).apply(&sim, SIM_BIN_M, 3), Err(TwinError::Invalid("cover")));
    }
}
