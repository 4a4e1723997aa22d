//! The shots' recorded transmit pulses (`tx_waveform` of the `shots/` table, docs/pulse.md) as
//! the pulses the simulation convolves with: what `simulate --pulse recorded`, the collocation and
//! the diagnosis use.

use std::collections::HashMap;
use std::sync::Arc;

use crate::dataset::shots::for_each_transmit_record;
use crate::dataset::Dataset;
use crate::error::Result;
use crate::kernels::sim::{Pulse, PulseReference, TransmitPulse};

/// The shots' recorded transmit pulses (`tx_waveform`, docs/pulse.md) at bin size `res` (m),
/// placed at `reference`.
#[derive(Debug, Clone, Default)]
pub struct ShotPulses {
    pub by_shot: HashMap<u64, Arc<Pulse>>,
    /// Shots without a `tx_waveform`.
    pub missing: usize,
    /// Shots whose record holds no usable pulse (too short, non-finite, no pulse above the floor).
    pub unusable: usize,
}

impl ShotPulses {
    /// The mean of every shot's pulse (aligned at the reference point); `None` without any.
    pub fn mean(&self) -> Option<Pulse> {
        let mut all: Vec<(&u64, &Arc<Pulse>)> = self.by_shot.iter().collect();
        all.sort_by_key(|(sn, _)| **sn);
        Pulse::mean(&all.iter().map(|(_, p)| p.as_ref()).collect::<Vec<_>>())
    }

    /// One line on the shots that fell back to another pulse, if any.
    pub fn note(&self) -> Option<String> {
        (self.missing + self.unusable > 0).then(|| {
            format!(
                "recorded pulse: {} shot(s) without a transmit waveform and {} with no usable pulse use the mean \
                 recorded pulse",
                self.missing, self.unusable
            )
        })
    }
}

/// Every shot's recorded transmit pulse from the `shots/` table (see [`ShotPulses`]).
pub fn shot_pulses(ds: &Dataset, reference: PulseReference, res: f64) -> Result<ShotPulses> {
    let mut out = ShotPulses::default();
    for_each_transmit_record(ds, |sn, tx| match tx {
        None => out.missing += 1,
        Some(tx) => match recorded_pulse(&tx, reference, res) {
            Some(p) => {
                out.by_shot.insert(sn, Arc::new(p));
            }
            None => out.unusable += 1,
        },
    })?;
    Ok(out)
}

/// A transmit record as a pulse at bin size `res` placed at `reference`; `None` when the record
/// holds no usable pulse.
pub fn recorded_pulse(tx: &[f32], reference: PulseReference, res: f64) -> Option<Pulse> {
    TransmitPulse::from_record(tx).ok().map(|t| t.to_pulse(reference, res))
}
