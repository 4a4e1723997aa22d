//! Cumulative energy from botloc up to toploc, the 101 `rx_cumulative` positions, ground-mode
//! selection by cumulative energy (a2) and relative heights.

use super::{Mode, WaveformGeolocation, RH_COUNT};

/// The zcross-smoothed waveform minus the noise mean, linearly interpolated on the sub-bin grid
/// from botloc (j = 0) up to toploc (j = steps). Measured: this reproduces NASA's `rx_cumulative`
/// far better than the raw waveform (docs/gedi-products.md §4.6).
pub(super) struct EnergyProfile<'a> {
    /// Interpolated energy above the noise mean at each grid step.
    values: &'a [f64],
    botloc: f64,
    grid: f64,
    total: f64,
}

impl<'a> EnergyProfile<'a> {
    /// The profile between `toploc` and `botloc`, its values written to `buffer` (reused between
    /// waveforms), or `None` when it holds no positive energy.
    pub(super) fn new(
        smoothed: &[f64],
        mean: f64,
        toploc: f64,
        botloc: f64,
        grid: f64,
        buffer: &'a mut Vec<f64>,
    ) -> Option<Self> {
        let steps = ((botloc - toploc) * grid).round().max(0.0) as usize;
        let last = smoothed.len().checked_sub(1)?;
        buffer.clear();
        buffer.extend((0..=steps).map(|j| {
            let p = botloc - j as f64 / grid;
            // `as` truncates, which is floor for p ≥ 0 (and avoids a libm call per step).
            let i = (p.max(0.0) as usize).min(last);
            let f = p - i as f64;
            let next = smoothed[(i + 1).min(last)];
            smoothed[i] * (1.0 - f) + next * f - mean
        }));
        let total: f64 = buffer.iter().sum();
        (total > 0.0).then_some(Self { values: buffer, botloc, grid, total })
    }

    /// Position of grid step `j` (0 = botloc, increasing upward).
    fn position(&self, j: usize) -> f64 {
        self.botloc - j as f64 / self.grid
    }

    /// Positions where the cumulative energy first reaches k % of the total, k = 0..=100.
    pub(super) fn cumulative_positions(&self) -> [f64; RH_COUNT] {
        let mut out = [self.position(self.values.len() - 1); RH_COUNT];
        let mut k = 0;
        let mut cum = 0.0;
        for (j, &v) in self.values.iter().enumerate() {
            cum += v;
            while k < RH_COUNT && cum >= self.total * k as f64 / 100.0 {
                out[k] = self.position(j);
                k += 1;
            }
            if k == RH_COUNT {
                break;
            }
        }
        out
    }

    /// Share (%) of the total energy at or below `position`.
    pub(super) fn percent_below(&self, position: f64) -> f64 {
        let below: f64 =
            self.values.iter().enumerate().take_while(|&(j, _)| self.position(j) >= position).map(|(_, &v)| v).sum();
        100.0 * below / self.total
    }
}

/// Ground mode when `enable_select_mode` is on: starting from the lowest mode, pass over each mode
/// with less than `thresh` % of the energy below it, as long as a higher mode remains.
///
/// Inferred from the stored a2 data (docs/l2a.md): every a2 shot that passes over its lowest mode
/// has < 2.3 % of the energy below it, every shot that keeps it has ≥ 6 %; with 2–3 weak low modes
/// a2 passes over each one.
pub(super) fn select_ground(modes: &[Mode], profile: &EnergyProfile, thresh: f64) -> usize {
    let mut ground = modes.len() - 1;
    while ground > 0 && profile.percent_below(modes[ground].position) < thresh {
        ground -= 1;
    }
    ground
}

/// `trunc(100·(z(rx_cumulative[k]) − z(zcross)))` in cm, NASA's `rh_aN`.
pub(super) fn relative_heights_cm(
    geo: &WaveformGeolocation,
    cumulative: &[f64; RH_COUNT],
    zcross: f64,
) -> [i32; RH_COUNT] {
    let ground = geo.elevation_at(zcross);
    cumulative.map(|p| (100.0 * (geo.elevation_at(p) - ground)).trunc() as i32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cumulative_runs_from_botloc_to_toploc() {
        // A flat block of energy 1 above the mean between positions 2 and 6.
        let s = [0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 1.0, 0.0, 0.0];
        let mut buffer = Vec::new();
        let p = EnergyProfile::new(&s, 0.0, 2.0, 6.0, 4.0, &mut buffer).expect("positive energy");
        let c = p.cumulative_positions();
        assert_eq!(c[0], 6.0);
        assert_eq!(c[100], 2.0);
        assert!((c[50] - 4.0).abs() <= 0.25);
        assert!(c.windows(2).all(|w| w[1] <= w[0]));
        assert!((p.percent_below(2.0) - 100.0).abs() < 1e-9);
        assert!(EnergyProfile::new(&[0.0; 9], 1.0, 2.0, 6.0, 4.0, &mut buffer).is_none());
        assert!(EnergyProfile::new(&[], 1.0, 0.0, 0.0, 4.0, &mut buffer).is_none());
    }

    #[test]
    fn relative_heights_are_truncated_toward_zero() {
        let geo = WaveformGeolocation::from_spacing(11, 100.0, 0.15);
        let mut cum = [5.0; RH_COUNT];
        cum[0] = 6.0; // 0.15 m below the ground mode
        cum[100] = 1.0; // 0.60 m above
        let rh = relative_heights_cm(&geo, &cum, 5.0);
        assert_eq!(rh[0], -15);
        assert_eq!(rh[50], 0);
        assert!(rh[100] == 60 || rh[100] == 59);
    }
}
