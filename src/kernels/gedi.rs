//! GEDI product conventions shared by the reader (`ops::ingest_gedi`) and the granule writer
//! (`io::granule`): beam names and types, dataset names, the V2 product identifiers.
//!
//! Facts and their sources are in docs/gedi-products.md §1–§3.

/// The eight GEDI beam group names, coverage beams first.
pub const BEAM_NAMES: [&str; 8] =
    ["BEAM0000", "BEAM0001", "BEAM0010", "BEAM0011", "BEAM0101", "BEAM0110", "BEAM1000", "BEAM1011"];

/// Number of relative-height values per shot (RH0..RH100 at 1 % steps).
pub const RH_LEN: usize = 101;

/// Number of L2A algorithm settings (a1..a6).
pub const N_ALGORITHMS: usize = 6;

/// The kind of laser beam a group holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BeamType {
    /// Coverage beam (split laser, lower energy): BEAM0000..BEAM0011.
    Coverage,
    /// Full-power beam: BEAM0101, BEAM0110, BEAM1000, BEAM1011.
    FullPower,
}

impl BeamType {
    /// Classify a beam by its group name; `None` for a name that is not one of the eight beams.
    ///
    /// The name, not the per-shot `channel`, carries the beam type (docs/gedi-products.md §1).
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "BEAM0000" | "BEAM0001" | "BEAM0010" | "BEAM0011" => Some(BeamType::Coverage),
            "BEAM0101" | "BEAM0110" | "BEAM1000" | "BEAM1011" => Some(BeamType::FullPower),
            _ => None,
        }
    }

    /// Parse a value of the `beam_type` column ([`Self::as_str`]).
    pub fn from_label(label: &str) -> Option<Self> {
        [BeamType::Coverage, BeamType::FullPower].into_iter().find(|b| b.as_str() == label)
    }

    /// The value of the `beam_type` column: `coverage` or `full_power`.
    pub fn as_str(self) -> &'static str {
        match self {
            BeamType::Coverage => "coverage",
            BeamType::FullPower => "full_power",
        }
    }

    /// The beam group's `description` attribute in GEDI files.
    pub fn description(self) -> &'static str {
        match self {
            BeamType::Coverage => "Coverage beam",
            BeamType::FullPower => "Full power beam",
        }
    }
}

/// Whether a group name looks like a GEDI beam group (`BEAM` + four binary digits).
pub fn is_beam_group(name: &str) -> bool {
    name.len() == 8 && name.starts_with("BEAM") && name[4..].bytes().all(|b| b == b'0' || b == b'1')
}

/// The per-shot `beam` number of a beam group: the decimal value of its binary suffix.
pub fn beam_number(name: &str) -> Option<u16> {
    is_beam_group(name).then(|| u16::from_str_radix(&name[4..], 2).ok()).flatten()
}

/// A V2 granule file name, e.g. `GEDI01_B_2019170155833_O02932_02_T02267_02_005_01_V002.h5`.
///
/// `level` is `"01_B"` or `"02_A"`; `start` the acquisition start `YYYYDDDHHMMSS`. The reader pairs
/// L1B and L2A files whose names agree up to the track field.
pub fn v2_file_name(level: &str, start: &str, orbit: u32, sub_orbit: u8, track: u32) -> String {
    format!("GEDI{level}_{start}_O{orbit:05}_{sub_orbit:02}_T{track:05}_02_005_01_V002.h5")
}

// The shot records of a granule (what `io::granule` writes and the scenario makes).

/// One L1B shot: the waveforms and their geolocation.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct L1bShot {
    /// Unique shot identifier (the L1B/L2A join key).
    pub shot_number: u64,
    /// Seconds since 2018-01-01T00:00:00 UTC.
    pub delta_time: f64,
    /// Received waveform, digitizer counts, top to bottom, noise not removed.
    pub rx_waveform: Vec<f32>,
    /// Transmitted pulse, digitizer counts.
    pub tx_waveform: Vec<f32>,
    /// Latitude of the first (top) waveform sample, degrees.
    pub latitude_bin0: f64,
    /// Longitude of the first waveform sample, degrees.
    pub longitude_bin0: f64,
    /// Latitude of the last waveform sample, degrees.
    pub latitude_lastbin: f64,
    /// Longitude of the last waveform sample, degrees.
    pub longitude_lastbin: f64,
    /// Elevation of the first sample, m above the WGS84 ellipsoid.
    pub elevation_bin0: f64,
    /// Elevation of the last sample, m above the WGS84 ellipsoid.
    pub elevation_lastbin: f64,
    /// Noise mean, counts.
    pub noise_mean_corrected: f64,
    /// Noise standard deviation, counts.
    pub noise_stddev_corrected: f64,
    /// 1 = stale return (filter out).
    pub stale_return_flag: u8,
    /// Non-zero = degraded pointing or positioning.
    pub degrade: i8,
    /// Geoid height above the WGS84 ellipsoid (N), m.
    pub geoid: f32,
    /// TanDEM-X elevation, m.
    pub digital_elevation_model: f32,
}

/// The outputs of one L2A algorithm setting (aN) for one shot.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct L2aAlgorithm {
    /// Elevation of the lowest (ground) mode, m WGS84.
    pub elev_lowestmode: f32,
    /// Latitude of the lowest mode, degrees.
    pub lat_lowestmode: f64,
    /// Longitude of the lowest mode, degrees.
    pub lon_lowestmode: f64,
    /// RH0..RH100 in **centimetres** (101 values), as stored in `geolocation/rh_aN`.
    pub rh_cm: Vec<i16>,
    /// Sensitivity (0..1).
    pub sensitivity: f32,
    /// 1 = valid.
    pub quality_flag: u8,
    /// Signal start, 0-based fractional sample position.
    pub toploc: f32,
    /// Signal end, 0-based fractional sample position.
    pub botloc: f32,
    /// Ground mode, 0-based fractional sample position.
    pub zcross: f32,
}

/// V2 `land_cover_data` values of one shot.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LandCover {
    /// 1 = leaf-off conditions.
    pub leaf_off_flag: u8,
    /// Day of year of leaf-off start.
    pub leaf_off_doy: i16,
    /// Day of year of leaf-on start.
    pub leaf_on_doy: i16,
    /// Leaf-on cycle.
    pub leaf_on_cycle: u8,
    /// Plant functional type class.
    pub pft_class: u8,
    /// Region class.
    pub region_class: u8,
    /// Urban proportion, percent.
    pub urban_proportion: u8,
    /// Landsat water persistence, percent.
    pub landsat_water_persistence: u8,
}

/// One L2A shot: the root (selected-algorithm) fields, the six algorithms and land cover.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct L2aShot {
    /// Unique shot identifier (the L1B/L2A join key).
    pub shot_number: u64,
    /// Seconds since 2018-01-01T00:00:00 UTC.
    pub delta_time: f64,
    /// 1 = valid (for the selected algorithm).
    pub quality_flag: u8,
    /// Non-zero = degraded (per shot).
    pub degrade_flag: u8,
    /// Sensitivity of the selected algorithm.
    pub sensitivity: f32,
    /// Selected algorithm, 1..6 (0 = none).
    pub selected_algorithm: u8,
    /// Elevation of the lowest mode of the selected algorithm, m WGS84.
    pub elev_lowestmode: f32,
    /// Latitude of the lowest mode, degrees.
    pub lat_lowestmode: f64,
    /// Longitude of the lowest mode, degrees.
    pub lon_lowestmode: f64,
    /// RH0..RH100 in **metres** (101 values) of the selected algorithm.
    pub rh: Vec<f32>,
    /// Waveform energy above the noise mean, counts.
    pub energy_total: f32,
    /// Algorithms a1..a6 (index 0 is a1).
    pub algorithms: [L2aAlgorithm; N_ALGORITHMS],
    /// V2 land-cover data.
    pub land_cover: LandCover,
}

impl L2aShot {
    /// Set `selected_algorithm` to `alg` (1..=6) and copy that algorithm's values into the root
    /// fields, as NASA's L2A does (root `rh` = `rh_aN` / 100, etc.).
    pub fn select_algorithm(&mut self, alg: u8) {
        let Some(a) = (alg as usize).checked_sub(1).and_then(|i| self.algorithms.get(i)) else {
            self.selected_algorithm = 0;
            return;
        };
        self.elev_lowestmode = a.elev_lowestmode;
        self.lat_lowestmode = a.lat_lowestmode;
        self.lon_lowestmode = a.lon_lowestmode;
        self.rh = a.rh_cm.iter().map(|&cm| (f64::from(cm) / 100.0) as f32).collect();
        self.sensitivity = a.sensitivity;
        self.quality_flag = a.quality_flag;
        self.selected_algorithm = alg;
    }
}
