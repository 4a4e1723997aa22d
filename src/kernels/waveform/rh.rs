//! Relative heights (RH) from cumulative waveform energy, as gediMetric's `findRH` computes them,
//! at 1 % steps (RH0 … RH100, 101 values).
//!
//! RH*p* is the elevation label of the first bin, walking from the bottom of the waveform upwards,
//! at which the cumulative energy reaches *p* % of the total, minus the ground elevation. There is
//! no interpolation: RH values are bin labels minus the ground. The reference prints 21 values at
//! 5 % steps; `rh[5k]` here corresponds to its RH at 5k % (docs/simulator-reference.md §2.2).

/// Number of RH values (0 … 100 % at 1 % steps).
pub const N_RH: usize = 101;

/// RH0 … RH100 (metres above `ground`) of a waveform stored top to bottom, sample k labelled
/// `z0 − k·dz`.
pub fn rh_profile(wave: &[f32], z0: f64, dz: f64, ground: f64) -> [f32; N_RH] {
    rh_profile_by(wave, |k| z0 - k as f64 * dz, ground)
}

/// Whether RH is defined for `wave`: every sample finite and the total energy positive. (The
/// reference gives all zeros otherwise, which [`rh_profile`] keeps for parity; callers that can
/// say "undefined" — the `gedi_rh` SQL function — return null instead.)
pub fn has_energy(wave: &[f32]) -> bool {
    wave.iter().all(|w| w.is_finite()) && wave.iter().sum::<f32>() > 0.0
}

/// RH0 … RH100 of a waveform stored top to bottom whose sample k has the elevation `label(k)`.
///
/// Follows `findRH`: energies are summed in f32 from the bottom bin upwards; only bins with
/// positive energy can set a percentile; percentile *p* is reached when the cumulative sum is at
/// least `(p/100)·total` (f32); if rounding leaves RH100 unset it takes the highest bin with
/// energy, and a waveform without positive energy gives all zeros.
pub fn rh_profile_by(wave: &[f32], label: impl Fn(usize) -> f64, ground: f64) -> [f32; N_RH] {
    let total: f32 = wave.iter().sum();
    // Thresholds computed once: the f32 fraction of p/100, correctly rounded, times the total.
    let thresholds: [f32; N_RH] = std::array::from_fn(|p| ((p as f64 / 100.0) as f32 * total).min(total));
    let mut rh = [f32::NAN; N_RH];
    let mut next = 0; // percentiles are reached in increasing order, so one cursor suffices
    let mut cumul = 0f32;
    let mut last_return = None;
    for (i, &w) in wave.iter().enumerate().rev() {
        cumul += w;
        if w > 0.0 {
            let height = (label(i) - ground) as f32;
            while next < N_RH && cumul >= thresholds[next] {
                rh[next] = height;
                next += 1;
            }
            last_return = Some(height);
        }
    }
    match last_return {
        None => [0.0; N_RH],
        Some(top) => {
            // f32 rounding can leave the last percentiles unreached: they take the top return.
            rh[next..].fill(top);
            rh
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn single_bin_gives_constant_rh() {
        let mut wave = vec![0.0f32; 10];
        wave[4] = 2.0;
        let rh = rh_profile(&wave, 100.0, 0.5, 97.0);
        assert!(rh.iter().all(|&v| v == 1.0));
    }

    #[test]
    fn percentiles_walk_up_from_the_bottom() {
        // Four equal bins at 3, 2, 1, 0 m above ground (top to bottom).
        let wave = [1.0f32, 1.0, 1.0, 1.0];
        let rh = rh_profile(&wave, 3.0, 1.0, 0.0);
        assert_eq!(rh[0], 0.0);
        assert_eq!(rh[25], 0.0);
        assert_eq!(rh[26], 1.0);
        assert_eq!(rh[50], 1.0);
        assert_eq!(rh[75], 2.0);
        assert_eq!(rh[100], 3.0);
    }

    #[test]
    fn empty_wave_gives_zeros() {
        assert_eq!(rh_profile(&[0.0; 5], 10.0, 1.0, 0.0), [0.0; N_RH]);
        assert_eq!(rh_profile(&[], 10.0, 1.0, 0.0), [0.0; N_RH]);
    }
}
