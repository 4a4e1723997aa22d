//! Sample position → elevation, latitude and longitude (docs/gedi-products.md §1, exact on NASA's data).

/// Coordinates of the first (`bin0`) and last stored sample of one waveform.
///
/// A fractional 0-based position `p` maps to `bin0 + (lastbin − bin0)·p/(n − 1)`, the mapping NASA
/// uses for every L2A position (toploc, botloc, zcross, modes, rx_cumulative).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WaveformGeolocation {
    /// Number of samples of the waveform (`rx_sample_count`).
    pub sample_count: usize,
    /// Elevation of sample 0 (m, WGS84 ellipsoid in GEDI products).
    pub elevation_bin0: f64,
    /// Elevation of sample n−1 (m).
    pub elevation_lastbin: f64,
    /// Latitude of sample 0 (degrees; NaN when unknown).
    pub latitude_bin0: f64,
    /// Latitude of sample n−1 (degrees; NaN when unknown).
    pub latitude_lastbin: f64,
    /// Longitude of sample 0 (degrees; NaN when unknown).
    pub longitude_bin0: f64,
    /// Longitude of sample n−1 (degrees; NaN when unknown).
    pub longitude_lastbin: f64,
}

impl WaveformGeolocation {
    /// A vertical axis only, from the elevations of the first and last sample (lat/lon unknown).
    pub fn vertical(sample_count: usize, elevation_bin0: f64, elevation_lastbin: f64) -> Self {
        Self {
            sample_count,
            elevation_bin0,
            elevation_lastbin,
            latitude_bin0: f64::NAN,
            latitude_lastbin: f64::NAN,
            longitude_bin0: f64::NAN,
            longitude_lastbin: f64::NAN,
        }
    }

    /// A vertical axis from the elevation of sample 0 and the bin spacing `dz` (m, positive: each
    /// sample lies `dz` below the previous one), e.g. for simulated waveforms.
    pub fn from_spacing(sample_count: usize, elevation_bin0: f64, dz: f64) -> Self {
        let span = dz * sample_count.saturating_sub(1) as f64;
        Self::vertical(sample_count, elevation_bin0, elevation_bin0 - span)
    }

    /// Fraction of the way from bin0 to lastbin at position `p` (0 for a one-sample waveform).
    fn fraction(&self, position: f64) -> f64 {
        if self.sample_count > 1 {
            position / (self.sample_count - 1) as f64
        } else {
            0.0
        }
    }

    /// Elevation (m) at a fractional 0-based sample position.
    pub fn elevation_at(&self, position: f64) -> f64 {
        self.elevation_bin0 + (self.elevation_lastbin - self.elevation_bin0) * self.fraction(position)
    }

    /// Latitude (degrees) at a fractional 0-based sample position.
    pub fn latitude_at(&self, position: f64) -> f64 {
        self.latitude_bin0 + (self.latitude_lastbin - self.latitude_bin0) * self.fraction(position)
    }

    /// Longitude (degrees) at a fractional 0-based sample position.
    pub fn longitude_at(&self, position: f64) -> f64 {
        self.longitude_bin0 + (self.longitude_lastbin - self.longitude_bin0) * self.fraction(position)
    }

    /// Whether the elevations are finite (a prerequisite for relative heights).
    pub fn is_valid(&self) -> bool {
        self.elevation_bin0.is_finite() && self.elevation_lastbin.is_finite()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolates_between_first_and_last_bin() {
        let g = WaveformGeolocation {
            sample_count: 5,
            elevation_bin0: 100.0,
            elevation_lastbin: 96.0,
            latitude_bin0: 10.0,
            latitude_lastbin: 10.4,
            longitude_bin0: -44.0,
            longitude_lastbin: -44.4,
        };
        assert_eq!(g.elevation_at(0.0), 100.0);
        assert_eq!(g.elevation_at(4.0), 96.0);
        assert!((g.elevation_at(2.5) - 97.5).abs() < 1e-12);
        assert!((g.latitude_at(1.0) - 10.1).abs() < 1e-12);
        assert!((g.longitude_at(3.0) + 44.3).abs() < 1e-12);
        let s = WaveformGeolocation::from_spacing(11, 50.0, 0.15);
        assert!((s.elevation_lastbin - 48.5).abs() < 1e-12);
    }
}
