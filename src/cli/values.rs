//! Parsers of numeric flags whose nonsensical values would otherwise pass silently (a footprint of
//! σ 0 skipping every footprint, a NaN geoid offset replaced by the file's): clap refuses them in
//! one line naming the flag (docs/robustness.md).

/// A positive, finite number of metres at most `max`.
fn metres_in(s: &str, max: f64) -> Result<f64, String> {
    let v: f64 = s.trim().parse().map_err(|_| format!("`{s}` is not a number of metres"))?;
    if v.is_finite() && v > 0.0 && v <= max {
        Ok(v)
    } else {
        Err(format!("{} m: give a finite σ above 0 and at most {max} m", s.trim()))
    }
}

/// Largest pulse σ accepted (m): 20 times the 15 ns pulse's.
pub const MAX_PULSE_SIGMA_M: f64 = 20.0;
/// Largest |geoid offset| accepted (m): the Earth's geoid lies within about −107 and +86 m of the
/// ellipsoid.
pub const MAX_GEOID_OFFSET_M: f64 = 150.0;

/// `--fsigma`.
pub fn footprint_sigma(s: &str) -> Result<f32, String> {
    metres_in(s, f64::from(gedisim::kernels::sim::footprint::MAX_SIGMA_M)).map(|v| v as f32)
}

/// `--psigma`.
pub fn pulse_sigma(s: &str) -> Result<f32, String> {
    metres_in(s, MAX_PULSE_SIGMA_M).map(|v| v as f32)
}

/// `--geoid-offset`: finite and within [`MAX_GEOID_OFFSET_M`] of 0.
pub fn geoid_offset(s: &str) -> Result<f64, String> {
    let v: f64 = s.trim().parse().map_err(|_| format!("`{s}` is not a number of metres"))?;
    if v.is_finite() && v.abs() <= MAX_GEOID_OFFSET_M {
        Ok(v)
    } else {
        Err(format!("{} m: a geoid offset is finite and within ±{MAX_GEOID_OFFSET_M} m", s.trim()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nonsense_is_refused_and_sense_kept() {
        for bad in ["0", "-1", "NaN", "inf", "1e9", "x"] {
            assert!(footprint_sigma(bad).is_err(), "{bad}");
            assert!(pulse_sigma(bad).is_err(), "{bad}");
        }
        assert_eq!(footprint_sigma("5.5"), Ok(5.5));
        assert_eq!(pulse_sigma("0.3"), Ok(0.3));
        for bad in ["NaN", "1e300", "-inf", "151", "x"] {
            assert!(geoid_offset(bad).is_err(), "{bad}");
        }
        assert_eq!(geoid_offset("-49.5"), Ok(-49.5));
    }
}
