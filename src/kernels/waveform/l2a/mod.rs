//! GEDI L2A waveform processing (setting groups a1..a6) as a pure kernel.
//!
//! Input: one received waveform (raw digitiser counts, top to bottom), its noise mean and σ, its
//! geolocation (first/last sample) and the settings of one algorithm. Output: the L2A positions
//! (toploc, botloc, modes, zcross, rx_cumulative, all 0-based fractional sample positions on NASA's
//! ¼-sample grid), relative heights in NASA's cm truncation, energy and sensitivity.
//!
//! Steps (docs/l2a.md): smooth → signal start/end above thresholds → modes (local maxima) → ground
//! mode → cumulative energy botloc→toploc → RH → sensitivity. A waveform that cannot be processed
//! yields a [`NoResult`] with the reason; nothing here panics on bad input.

mod cumulative;
mod geolocation;
mod locate;
mod settings;
mod smoothing;

pub use geolocation::WaveformGeolocation;
pub use settings::{AlgorithmSettings, MinDetectionModel, MAX_MODE_COUNT, MIN_DETECTION_PULSE_WIDTH, RH_COUNT};
pub use smoothing::{GaussianKernel, SIGMA_OFFSET, TRUNCATION_RATIO};

use cumulative::EnergyProfile;

/// Noise statistics of a waveform (counts): L1B `noise_mean_corrected` / `noise_stddev_corrected`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Noise {
    /// Noise mean (counts).
    pub mean: f64,
    /// Noise standard deviation (counts); must be positive.
    pub stddev: f64,
}

/// One detected mode: a local maximum of the zcross-smoothed waveform.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Mode {
    /// 0-based fractional sample position (¼-sample grid).
    pub position: f64,
    /// Smoothed amplitude at the mode (counts, noise mean included, like `rx_modeamps`).
    pub amplitude: f64,
}

/// Why a waveform produced no L2A result.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum NoResult {
    /// The waveform has no samples.
    #[error("empty waveform")]
    EmptyWaveform,
    /// The shot has L1B columns but no usable waveform: ingest nulls an empty record or one with
    /// NaN or infinite samples (and warns).
    #[error("no usable waveform (empty, or NaN or infinite samples at ingest)")]
    NoWaveform,
    /// A sample is NaN or infinite.
    #[error("non-finite sample at index {index}")]
    NonFiniteSample {
        /// Index of the first offending sample.
        index: usize,
    },
    /// The noise mean is not finite or the noise σ is not a positive finite number.
    #[error("invalid noise statistics (mean not finite or stddev not > 0)")]
    InvalidNoise,
    /// The settings cannot be applied (non-finite thresholds, zero sub-bin resolution).
    #[error("invalid algorithm settings")]
    InvalidSettings,
    /// The geolocation does not describe this waveform (sample count differs or not finite).
    #[error("geolocation does not match the waveform ({sample_count} samples described, {waveform_len} given)")]
    GeometryMismatch {
        /// Samples the geolocation describes.
        sample_count: usize,
        /// Samples in the waveform.
        waveform_len: usize,
    },
    /// The elevation of the first or last sample is not finite (relative heights need both).
    #[error("elevation of the first or last sample is not finite")]
    InvalidElevation,
    /// The first sample is not above the last: a waveform is recorded downwards, so such a
    /// geolocation is corrupt (`run` skips the shot as `bad_waveform_geometry`).
    #[error("bad waveform geometry: elevation_bin0 is not above elevation_lastbin")]
    BadGeometry,
    /// The smoothed waveform never rises above the front or back threshold, or carries no energy
    /// between them.
    #[error("no signal above the thresholds")]
    NoSignal,
    /// Signal found but no local maximum above the back threshold between toploc and botloc.
    #[error("no mode between signal start and end")]
    NoModes,
}

/// Outcome of processing one waveform with one algorithm.
pub type L2aOutcome = Result<L2aResult, NoResult>;

/// L2A result of one waveform and one algorithm (the per-shot `rx_processing_aN` fields).
#[derive(Debug, Clone, PartialEq)]
pub struct L2aResult {
    /// Algorithm id of the settings used (1..6 for GEDI groups).
    pub algorithm: u8,
    /// μ + k_front·σ (counts).
    pub front_threshold: f64,
    /// μ + k_back·σ (counts).
    pub back_threshold: f64,
    /// Signal start (highest return), 0-based fractional sample position.
    pub toploc: f64,
    /// Signal end (lowest return), 0-based fractional sample position.
    pub botloc: f64,
    /// Position of the selected ground mode (= `modes[selected_mode].position`).
    pub zcross: f64,
    /// Number of modes stored in `modes` (at most [`MAX_MODE_COUNT`]).
    pub num_modes: usize,
    /// Modes from top to bottom; only the first `num_modes` entries are meaningful.
    pub modes: [Mode; MAX_MODE_COUNT],
    /// Index of the ground mode in `modes`.
    pub selected_mode: usize,
    /// Positions where the energy summed from botloc upward reaches k % (k = 0..100).
    pub rx_cumulative: [f64; RH_COUNT],
    /// Relative heights in cm, truncated toward zero as NASA stores `rh_aN`.
    pub rh_cm: [i32; RH_COUNT],
    /// Relative heights in metres (`rh_cm / 100`).
    pub rh: [f64; RH_COUNT],
    /// Σ (sample − μ) over the whole waveform (counts).
    pub energy_total: f64,
    /// Modelled minimum detectable amplitude (counts; assumption, see [`MinDetectionModel`]).
    pub min_detection_threshold: f64,
    /// `min_detection_threshold · 6.5 · √(2π)` (counts).
    pub min_detection_energy: f64,
    /// `1 − min_detection_energy / energy_total` (0 when the waveform has no positive energy).
    pub sensitivity: f64,
    /// Elevation of toploc (m).
    pub elev_highestreturn: f64,
    /// Elevation of zcross (m).
    pub elev_lowestmode: f64,
    /// Elevation of botloc (m).
    pub elev_lowestreturn: f64,
}

impl L2aResult {
    /// The detected modes, top to bottom.
    pub fn modes(&self) -> &[Mode] {
        &self.modes[..self.num_modes]
    }
}

/// Reusable L2A processor: keeps kernels and buffers so the hot loop does not allocate, and
/// smooths each waveform once per distinct width however many algorithms use it (also across
/// [`L2aProcessor::process`] calls on the same waveform, one algorithm after another).
#[derive(Debug, Default)]
pub struct L2aProcessor {
    /// One kernel per distinct width seen so far, with its smoothed-waveform buffer.
    smoothers: Vec<Smoother>,
    /// Scratch list of every mode found (may exceed [`MAX_MODE_COUNT`]).
    modes: Vec<Mode>,
    /// Scratch energy profile on the sub-bin grid (botloc → toploc).
    profile: Vec<f64>,
    /// The waveform the cached smoothings belong to (bit patterns), for `process`.
    last_wave: Vec<u32>,
}

#[derive(Debug)]
struct Smoother {
    kernel: GaussianKernel,
    smoothed: Vec<f64>,
    /// Whether `smoothed` holds the current waveform.
    fresh: bool,
}

impl L2aProcessor {
    /// A processor with empty caches.
    pub fn new() -> Self {
        Self::default()
    }

    /// Process one waveform with one algorithm.
    pub fn process(
        &mut self,
        wave: &[f32],
        noise: Noise,
        geo: &WaveformGeolocation,
        settings: &AlgorithmSettings,
    ) -> L2aOutcome {
        validate_input(wave, noise, geo)?;
        // Smoothing depends on the samples alone: keep it while the same waveform comes back
        // (e.g. one SQL row per algorithm). Comparing costs one pass, smoothing about 44.
        let same =
            self.last_wave.len() == wave.len() && self.last_wave.iter().zip(wave).all(|(&a, b)| a == b.to_bits());
        if !same {
            self.begin_waveform();
            self.last_wave.clear();
            self.last_wave.extend(wave.iter().map(|w| w.to_bits()));
        }
        let energy_total = energy_total(wave, noise.mean);
        self.run(wave, noise, geo, settings, energy_total)
    }

    /// Process one waveform with several algorithms, sharing the smoothing; `out` is cleared and
    /// receives one outcome per entry of `settings`, in order.
    pub fn process_all(
        &mut self,
        wave: &[f32],
        noise: Noise,
        geo: &WaveformGeolocation,
        settings: &[AlgorithmSettings],
        out: &mut Vec<L2aOutcome>,
    ) {
        out.clear();
        self.begin_waveform();
        if let Err(reason) = validate_input(wave, noise, geo) {
            out.extend(settings.iter().map(|_| Err(reason)));
            return;
        }
        let energy_total = energy_total(wave, noise.mean);
        out.extend(settings.iter().map(|s| self.run(wave, noise, geo, s, energy_total)));
    }

    /// Marks every cached smoothing stale: a new waveform starts.
    fn begin_waveform(&mut self) {
        self.smoothers.iter_mut().for_each(|s| s.fresh = false);
        self.last_wave.clear();
    }

    /// Index of the smoother for `width`, smoothing `wave` with it if not done yet.
    fn smoothed(&mut self, wave: &[f32], width: f64) -> usize {
        let found = self.smoothers.iter().position(|s| s.kernel.width().to_bits() == width.to_bits());
        let index = found.unwrap_or_else(|| {
            self.smoothers.push(Smoother {
                kernel: GaussianKernel::for_width(width),
                smoothed: Vec::new(),
                fresh: false,
            });
            self.smoothers.len() - 1
        });
        let s = &mut self.smoothers[index];
        if !s.fresh {
            s.kernel.smooth_into(wave, &mut s.smoothed);
            s.fresh = true;
        }
        index
    }

    /// The algorithm proper, on validated input.
    fn run(
        &mut self,
        wave: &[f32],
        noise: Noise,
        geo: &WaveformGeolocation,
        s: &AlgorithmSettings,
        energy_total: f64,
    ) -> L2aOutcome {
        let front_threshold = noise.mean + s.front_threshold_sigmas * noise.stddev;
        let back_threshold = noise.mean + s.back_threshold_sigmas * noise.stddev;
        if !front_threshold.is_finite() || !back_threshold.is_finite() || s.subbin_resolution == 0 {
            return Err(NoResult::InvalidSettings);
        }
        let grid = f64::from(s.subbin_resolution);
        let locs_index = self.smoothed(wave, s.smoothing_width_locs);
        let zcross_index = self.smoothed(wave, s.smoothing_width_zcross);
        let locs = &self.smoothers[locs_index].smoothed;
        let zc = &self.smoothers[zcross_index].smoothed;

        let toploc = locate::signal_start(locs, front_threshold, grid).ok_or(NoResult::NoSignal)?;
        let botloc = locate::signal_end(locs, back_threshold, grid).ok_or(NoResult::NoSignal)?;
        if botloc < toploc {
            return Err(NoResult::NoSignal);
        }
        locate::find_modes(zc, toploc, botloc, back_threshold, grid, &mut self.modes);
        if self.modes.is_empty() {
            return Err(NoResult::NoModes);
        }
        let profile =
            EnergyProfile::new(zc, noise.mean, toploc, botloc, grid, &mut self.profile).ok_or(NoResult::NoSignal)?;
        let rx_cumulative = profile.cumulative_positions();
        let ground = if s.enable_select_mode {
            cumulative::select_ground(&self.modes, &profile, s.cumulative_energy_thresh)
        } else {
            self.modes.len() - 1
        };
        let zcross = self.modes[ground].position;

        // NASA stores at most MAX_MODE_COUNT modes; keep the lowest ones, which hold the ground.
        let first_kept = self.modes.len().saturating_sub(MAX_MODE_COUNT);
        let kept = &self.modes[first_kept..];
        let mut modes = [Mode::default(); MAX_MODE_COUNT];
        modes[..kept.len()].copy_from_slice(kept);

        let rh_cm = cumulative::relative_heights_cm(geo, &rx_cumulative, zcross);
        let min_detection_threshold = s.min_detection.threshold(noise.stddev);
        let min_detection_energy = min_detection_energy(min_detection_threshold);
        Ok(L2aResult {
            algorithm: s.id,
            front_threshold,
            back_threshold,
            toploc,
            botloc,
            zcross,
            num_modes: kept.len(),
            modes,
            selected_mode: ground - first_kept,
            rx_cumulative,
            rh_cm,
            rh: rh_cm.map(|cm| f64::from(cm) / 100.0),
            energy_total,
            min_detection_threshold,
            min_detection_energy,
            sensitivity: sensitivity(min_detection_energy, energy_total),
            elev_highestreturn: geo.elevation_at(toploc),
            elev_lowestmode: geo.elevation_at(zcross),
            elev_lowestreturn: geo.elevation_at(botloc),
        })
    }
}

/// Process one waveform with one algorithm (allocates a fresh [`L2aProcessor`]; prefer reusing one).
pub fn process_waveform(
    wave: &[f32],
    noise: Noise,
    geo: &WaveformGeolocation,
    settings: &AlgorithmSettings,
) -> L2aOutcome {
    L2aProcessor::new().process(wave, noise, geo, settings)
}

/// `Σ (w − mean)` over the whole waveform (counts), NASA's `energy_total` (§4.7).
fn energy_total(wave: &[f32], mean: f64) -> f64 {
    wave.iter().map(|&w| f64::from(w) - mean).sum()
}

/// Area of a Gaussian of amplitude `threshold` and σ = [`MIN_DETECTION_PULSE_WIDTH`] samples.
pub fn min_detection_energy(threshold: f64) -> f64 {
    threshold * MIN_DETECTION_PULSE_WIDTH * (2.0 * std::f64::consts::PI).sqrt()
}

/// `1 − min_detection_energy / energy_total`, or 0 when the waveform has no positive energy.
pub fn sensitivity(min_detection_energy: f64, energy_total: f64) -> f64 {
    if energy_total > 0.0 {
        1.0 - min_detection_energy / energy_total
    } else {
        0.0
    }
}

/// Checks shared by every algorithm: non-empty finite waveform, usable noise, matching geolocation.
fn validate_input(wave: &[f32], noise: Noise, geo: &WaveformGeolocation) -> Result<(), NoResult> {
    if wave.is_empty() {
        return Err(NoResult::EmptyWaveform);
    }
    if let Some(index) = wave.iter().position(|w| !w.is_finite()) {
        return Err(NoResult::NonFiniteSample { index });
    }
    if !noise.mean.is_finite() || !noise.stddev.is_finite() || noise.stddev <= 0.0 {
        return Err(NoResult::InvalidNoise);
    }
    if geo.sample_count != wave.len() {
        return Err(NoResult::GeometryMismatch { sample_count: geo.sample_count, waveform_len: wave.len() });
    }
    if !geo.is_valid() {
        return Err(NoResult::InvalidElevation);
    }
    if geo.sample_count > 1 && geo.elevation_bin0 <= geo.elevation_lastbin {
        return Err(NoResult::BadGeometry);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A noise-free waveform: flat at `mean` with a Gaussian canopy and ground return.
    fn synthetic(n: usize, mean: f32) -> Vec<f32> {
        (0..n)
            .map(|i| {
                let x = i as f32;
                mean + 60.0 * (-0.5 * ((x - 300.0) / 8.0).powi(2)).exp()
                    + 200.0 * (-0.5 * ((x - 360.0) / 5.0).powi(2)).exp()
            })
            .collect()
    }

    fn geo(n: usize) -> WaveformGeolocation {
        WaveformGeolocation::from_spacing(n, 500.0, 0.15)
    }

    const NOISE: Noise = Noise { mean: 200.0, stddev: 3.0 };

    #[test]
    fn synthetic_two_mode_waveform_is_processed_by_every_algorithm() {
        let wave = synthetic(800, 200.0);
        let mut p = L2aProcessor::new();
        let mut out = Vec::new();
        p.process_all(&wave, NOISE, &geo(800), &AlgorithmSettings::all_gedi(), &mut out);
        for r in out.iter().map(|o| o.as_ref().expect("processed")) {
            assert_eq!(r.num_modes, 2, "a{}", r.algorithm);
            assert!((r.zcross - 360.0).abs() <= 0.25, "a{} zcross {}", r.algorithm, r.zcross);
            assert!(r.toploc < 290.0 && r.botloc > 365.0);
            assert_eq!(r.rx_cumulative[0], r.botloc);
            assert_eq!(r.rx_cumulative[100], r.toploc);
            assert!(r.rh[100] > 8.0 && r.rh[0] < 0.0);
            assert!(r.sensitivity > 0.0 && r.sensitivity < 1.0);
        }
        // One-shot helper gives the same answer as the reusing processor.
        assert_eq!(process_waveform(&wave, NOISE, &geo(800), &AlgorithmSettings::a3()).as_ref(), out[2].as_ref());
    }

    #[test]
    fn bad_inputs_give_a_reason_not_a_panic() {
        let s = AlgorithmSettings::a1();
        assert_eq!(process_waveform(&[], NOISE, &geo(0), &s), Err(NoResult::EmptyWaveform));

        let flat = vec![200.0f32; 800];
        assert_eq!(process_waveform(&flat, NOISE, &geo(800), &s), Err(NoResult::NoSignal));

        // Pseudo-random noise of σ 3 around the mean (deterministic LCG): no signal either.
        let mut state = 12345u64;
        let noisy: Vec<f32> = (0..800)
            .map(|_| {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                200.0 + 3.0 * 1.7 * ((state >> 11) as f32 / (1u64 << 53) as f32 - 0.5) * 2.0
            })
            .collect();
        for alg in AlgorithmSettings::all_gedi() {
            assert_eq!(process_waveform(&noisy, NOISE, &geo(800), &alg), Err(NoResult::NoSignal));
        }

        let mut nan = synthetic(800, 200.0);
        nan[17] = f32::NAN;
        assert_eq!(process_waveform(&nan, NOISE, &geo(800), &s), Err(NoResult::NonFiniteSample { index: 17 }));

        let wave = synthetic(800, 200.0);
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let noise = Noise { mean: 200.0, stddev: bad };
            assert_eq!(process_waveform(&wave, noise, &geo(800), &s), Err(NoResult::InvalidNoise));
        }
        assert_eq!(
            process_waveform(&wave, NOISE, &geo(10), &s),
            Err(NoResult::GeometryMismatch { sample_count: 10, waveform_len: 800 })
        );
        let nan_top = WaveformGeolocation::vertical(800, f64::NAN, 380.0);
        assert_eq!(process_waveform(&wave, NOISE, &nan_top, &s), Err(NoResult::InvalidElevation));
        let mut zero_grid = s.clone();
        zero_grid.subbin_resolution = 0;
        assert_eq!(process_waveform(&wave, NOISE, &geo(800), &zero_grid), Err(NoResult::InvalidSettings));

        // A single sample and a monotonic ramp: no mode, never a panic.
        assert!(process_waveform(&[900.0], NOISE, &geo(1), &s).is_err());
        let ramp: Vec<f32> = (0..100).map(|i| 200.0 + i as f32 * 10.0).collect();
        assert_eq!(process_waveform(&ramp, NOISE, &geo(100), &s), Err(NoResult::NoModes));

        // process_all reports the input problem once per algorithm.
        let mut out = Vec::new();
        L2aProcessor::new().process_all(&[], NOISE, &geo(0), &AlgorithmSettings::all_gedi(), &mut out);
        assert_eq!(out, vec![Err(NoResult::EmptyWaveform); 6]);
    }

    #[test]
    fn a2_passes_over_a_weak_lowest_mode_and_a1_does_not() {
        // A strong return at 300 and a weak one (≈2 % of the energy) at 360.
        let wave: Vec<f32> = (0..800)
            .map(|i| {
                let x = i as f32;
                200.0
                    + 800.0 * (-0.5 * ((x - 300.0) / 6.0).powi(2)).exp()
                    + 30.0 * (-0.5 * ((x - 360.0) / 3.0).powi(2)).exp()
            })
            .collect();
        let a2 = process_waveform(&wave, NOISE, &geo(800), &AlgorithmSettings::a2()).expect("a2 processes");
        assert_eq!(a2.num_modes, 2);
        assert_eq!(a2.selected_mode, 0);
        assert!((a2.zcross - 300.0).abs() <= 0.25);
        let a5 = process_waveform(&wave, NOISE, &geo(800), &AlgorithmSettings::a5()).expect("a5 processes");
        assert_eq!(a5.selected_mode, a5.num_modes - 1);
        assert!((a5.zcross - 360.0).abs() <= 0.5);
    }
}
