//! Per-algorithm settings of GEDI L2A (the six setting groups a1..a6).
//!
//! Every value except the min-detection model is stored by NASA in each L2A granule under
//! `BEAMxxxx/rx_processing_aN/ancillary/` (docs/l2a.md, "Constants").

/// Width of the Gaussian whose area defines `min_detection_energy` (samples). Measured:
/// `min_detection_energy / min_detection_threshold = 6.5·√(2π)` in every stored shot.
pub const MIN_DETECTION_PULSE_WIDTH: f64 = 6.5;

/// Number of relative-height percentiles (RH0..RH100).
pub const RH_COUNT: usize = 101;

/// Maximum number of modes NASA stores per shot (`rx_max_mode_count`).
pub const MAX_MODE_COUNT: usize = 20;

/// Linear model `threshold = per_sigma·σ + offset` (counts) for the minimum detectable amplitude.
///
/// NASA's rule for `min_detection_threshold` is not public; this is a least-squares fit in the noise
/// σ per algorithm (named assumption, docs/l2a.md §Sensitivity).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MinDetectionModel {
    /// Slope of the threshold in units of the noise standard deviation.
    pub per_sigma: f64,
    /// Constant term of the threshold (counts).
    pub offset: f64,
}

impl MinDetectionModel {
    /// The modelled minimum detectable amplitude (counts) for a noise σ.
    pub fn threshold(&self, sigma: f64) -> f64 {
        self.per_sigma * sigma + self.offset
    }
}

/// All parameters of one L2A algorithm setting group.
#[derive(Debug, Clone, PartialEq)]
pub struct AlgorithmSettings {
    /// Algorithm number, 1..6 for the GEDI groups (0 for a custom group).
    pub id: u8,
    /// Nominal smoothing width used to find the signal start and end (`rx_smoothing_width_locs`, samples).
    pub smoothing_width_locs: f64,
    /// Nominal smoothing width used to find modes and energy (`rx_smoothing_width_zcross`, samples).
    pub smoothing_width_zcross: f64,
    /// Signal-start threshold in noise σ above the mean (`rx_front_threshold`).
    pub front_threshold_sigmas: f64,
    /// Signal-end and mode threshold in noise σ above the mean (`rx_back_threshold`).
    pub back_threshold_sigmas: f64,
    /// Positions are reported on a grid of 1/`subbin_resolution` samples (`rx_subbin_resolution`).
    pub subbin_resolution: u32,
    /// Whether the lowest mode may be passed over as ground (`enable_select_mode`, only a2).
    pub enable_select_mode: bool,
    /// A mode is rejected as ground when less than this share (%) of the botloc..toploc energy lies
    /// below it (`cumulative_energy_thresh`; only used when `enable_select_mode`).
    pub cumulative_energy_thresh: f64,
    /// Stored by NASA next to `cumulative_energy_thresh` (`cumulative_energy_minimum`); kept for
    /// completeness, its role cannot be inferred from the public data and it is not used.
    pub cumulative_energy_minimum: f64,
    /// Model of `min_detection_threshold` (assumption, fitted).
    pub min_detection: MinDetectionModel,
}

/// `[locs width, zcross width, front k, back k]` per algorithm (row 0 = a1), as stored in the
/// granules' `rx_processing_aN/ancillary` (docs/gedi-products.md §4.2).
const GEDI_TABLE: [[f64; 4]; 6] = [
    [6.5, 6.5, 3.0, 6.0],
    [6.5, 3.5, 3.0, 3.0],
    [6.5, 3.5, 3.0, 6.0],
    [6.5, 6.5, 6.0, 6.0],
    [6.5, 3.5, 3.0, 2.0],
    [6.5, 3.5, 3.0, 4.0],
];

/// Fitted min-detection models per algorithm (index 0 = a1): least squares of NASA's stored
/// `min_detection_threshold` against `stddev` on the calibration half of the shared V1 granule
/// (beams BEAM0001, BEAM0011, BEAM0110, BEAM1011; docs/l2a.md).
const MIN_DETECTION_FIT: [MinDetectionModel; 6] = [
    MinDetectionModel { per_sigma: 8.641, offset: -1.060 },
    MinDetectionModel { per_sigma: 3.829, offset: -1.081 },
    MinDetectionModel { per_sigma: 7.204, offset: -1.199 },
    MinDetectionModel { per_sigma: 8.641, offset: -1.060 },
    MinDetectionModel { per_sigma: 2.796, offset: -1.381 },
    MinDetectionModel { per_sigma: 5.010, offset: -1.318 },
];

impl AlgorithmSettings {
    /// The GEDI setting group `aN` for `alg` in 1..=6, or `None` for any other number.
    pub fn gedi(alg: u8) -> Option<Self> {
        (1..=6).contains(&alg).then(|| Self::from_table(usize::from(alg) - 1))
    }

    /// Settings of the table row `index` (0 = a1); callers guarantee `index < 6`.
    fn from_table(index: usize) -> Self {
        let [locs, zcross, front, back] = GEDI_TABLE[index];
        // Only a2 enables the choice of a ground mode above the lowest one.
        let select = index == 1;
        Self {
            id: index as u8 + 1,
            smoothing_width_locs: locs,
            smoothing_width_zcross: zcross,
            front_threshold_sigmas: front,
            back_threshold_sigmas: back,
            subbin_resolution: 4,
            enable_select_mode: select,
            cumulative_energy_thresh: if select { 2.5 } else { 0.0 },
            cumulative_energy_minimum: if select { 1.5 } else { 0.0 },
            min_detection: MIN_DETECTION_FIT[index],
        }
    }

    /// Settings group a1.
    pub fn a1() -> Self {
        Self::from_table(0)
    }
    /// Settings group a2.
    pub fn a2() -> Self {
        Self::from_table(1)
    }
    /// Settings group a3.
    pub fn a3() -> Self {
        Self::from_table(2)
    }
    /// Settings group a4.
    pub fn a4() -> Self {
        Self::from_table(3)
    }
    /// Settings group a5.
    pub fn a5() -> Self {
        Self::from_table(4)
    }
    /// Settings group a6.
    pub fn a6() -> Self {
        Self::from_table(5)
    }

    /// The six GEDI groups a1..a6 in order.
    pub fn all_gedi() -> Vec<Self> {
        (1..=6).filter_map(Self::gedi).collect()
    }
}
