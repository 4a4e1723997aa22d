//! The forward GEDI chain of one shot, shared by the scenario generator (`kernels::scenario::shot`)
//! and the diagnosis (`kernels::diagnose::chain`): a noise-free simulated waveform → its signal
//! span → the noise twin in a record window (docs/l2a.md, "Noise twin") → GEDI L2A a1–a6.

use super::l2a::{AlgorithmSettings, L2aOutcome, L2aProcessor, Noise, WaveformGeolocation};
use super::noise_twin::{NoiseShape, ShotTwin, TwinError, TwinWaveform};

/// The part of `wave` above 10⁻⁹ of its peak: the index of its first bin and its samples; `None`
/// when the waveform holds no energy.
pub fn signal_span(wave: &[f64]) -> Option<(usize, &[f64])> {
    let max = wave.iter().cloned().fold(0.0, f64::max);
    if !(max > 0.0) {
        return None;
    }
    let cut = max * 1e-9;
    let first = wave.iter().position(|&v| v > cut)?;
    let last = wave.iter().rposition(|&v| v > cut)?;
    Some((first, &wave[first..=last]))
}

/// Where a shot's record lies: `sample_count` samples of 1 ns, sample 0 at elevation `bin0`, the
/// last at `lastbin`; the signal's first bin lands on record sample `start`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RecordWindow {
    pub sample_count: usize,
    pub start: isize,
    pub bin0: f64,
    pub lastbin: f64,
}

/// GEDI's six L2A algorithm settings with the buffers one worker reuses.
#[derive(Debug)]
pub struct L2aRunner {
    processor: L2aProcessor,
    settings: Vec<AlgorithmSettings>,
    /// The outcomes of the last [`forward`] run, a1…a6 in order.
    pub outcomes: Vec<L2aOutcome>,
}

impl Default for L2aRunner {
    fn default() -> Self {
        L2aRunner { processor: L2aProcessor::new(), settings: AlgorithmSettings::all_gedi(), outcomes: Vec::new() }
    }
}

/// The received waveform of `signal` (bins of `dz` m, from [`signal_span`]) recorded in `window`:
/// scaled to `energy` (DN above the noise), GEDI's correlated noise of `noise` drawn from `seed`
/// ([`NoiseShape::GEDI_V1`], no quantisation); then L2A a1–a6 of it into `runner.outcomes`.
pub fn forward(
    signal: &[f64],
    dz: f64,
    window: &RecordWindow,
    energy: f64,
    noise: Noise,
    seed: u64,
    runner: &mut L2aRunner,
) -> Result<TwinWaveform, TwinError> {
    let twin = ShotTwin {
        energy_total: energy,
        noise,
        sample_count: window.sample_count,
        tx_pulse: None,
        quantum: 0.0,
        noise_shape: NoiseShape::GEDI_V1,
    }
    .apply(signal, dz, window.start, seed)?;
    let geo = WaveformGeolocation::vertical(window.sample_count, window.bin0, window.lastbin);
    let L2aRunner { processor, settings, outcomes } = runner;
    processor.process_all(&twin.wave, twin.noise, &geo, settings, outcomes);
    Ok(twin)
}
