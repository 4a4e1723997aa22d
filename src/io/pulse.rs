//! Pulse files: two columns, range (m) and amplitude (docs/simulator-reference.md §1.6).

use std::path::Path;

use crate::error::{Error, Result};
use crate::kernels::sim::pulse::{parse_pulse_text, Pulse};
use crate::kernels::sim::PulseModel;

/// Read a two-column pulse file into a tabulated [`Pulse`].
pub fn read_pulse_file(path: &Path) -> Result<Pulse> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::file(path, format!("cannot read pulse file: {e}")))?;
    let pairs = parse_pulse_text(&text).map_err(|e| Error::field(path, "pulse", e))?;
    Pulse::tabulated(&pairs).map_err(|e| Error::field(path, "pulse", e))
}

/// The one pulse `model` fixes for every footprint, at bin size `res` (m) for a Gaussian: a
/// Gaussian of the given σ or the pulse file; `None` for the study's Gaussian and for recorded
/// pulses (each shot's own).
pub fn fixed_pulse(model: &PulseModel, res: f64) -> Result<Option<Pulse>> {
    Ok(match model {
        PulseModel::Gaussian(Some(s)) => Some(Pulse::gaussian(*s, res as f32)?),
        PulseModel::File(path) => Some(read_pulse_file(path)?),
        PulseModel::Gaussian(None) | PulseModel::Recorded(_) => None,
    })
}
