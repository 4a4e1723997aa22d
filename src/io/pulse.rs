//! Pulse files: two columns, range (m) and amplitude (docs/simulator-reference.md §1.6).

use std::path::Path;

use crate::error::{Error, Result};
use crate::kernels::sim::pulse::{parse_pulse_text, Pulse};

/// Read a two-column pulse file into a tabulated [`Pulse`].
pub fn read_pulse_file(path: &Path) -> Result<Pulse> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::file(path, format!("cannot read pulse file: {e}")))?;
    let pairs = parse_pulse_text(&text).map_err(|e| Error::field(path, "pulse", e))?;
    Pulse::tabulated(&pairs).map_err(|e| Error::field(path, "pulse", e))
}
