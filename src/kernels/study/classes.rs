//! The study's strata and filter as pure functions: sensitivity groups, slope and cover classes,
//! phenology from `leaf_off_flag`, forest type from Corine Land Cover, and the quality filter
//! (docs/contracts.md "The study"; docs/gedi-products.md §5).

/// The value of every class column when its input is missing or invalid.
pub const UNKNOWN: &str = "unknown";

/// Lowest sensitivity kept by the study (docs/gedi-products.md §5).
pub const MIN_SENSITIVITY: f64 = 0.90;
/// Upper bound of the `low` sensitivity group (inclusive).
pub const LOW_SENSITIVITY_MAX: f64 = 0.96;

/// Forest types of the `strata` and `results` tables.
pub const FOREST_TYPES: [&str; 5] = ["broadleaf", "coniferous", "mixed", "other", UNKNOWN];
/// Slope classes (degrees).
pub const SLOPE_CLASSES: [&str; 4] = ["[0,10)", "[10,20)", "[20,30)", ">=30"];
/// ALS canopy-cover classes (fraction).
pub const COVER_CLASSES: [&str; 4] = ["[0,0.25)", "[0.25,0.5)", "[0.5,0.75)", "[0.75,1]"];
/// Values of `algorithm`: `default` (the shot's selected algorithm) and `a1` … `a6`.
pub const ALGORITHMS: [&str; crate::gedi::N_ALGORITHMS + 1] = ["default", "a1", "a2", "a3", "a4", "a5", "a6"];

/// `low` for 0.90 ≤ s ≤ 0.96, `high` for s > 0.96, `None` below 0.90 or when not finite (the
/// study drops those shots).
pub fn sensitivity_group(s: f64) -> Option<&'static str> {
    if !s.is_finite() || s < MIN_SENSITIVITY {
        None
    } else if s <= LOW_SENSITIVITY_MAX {
        Some("low")
    } else {
        Some("high")
    }
}

/// Slope class of `deg`: `[0,10)`, `[10,20)`, `[20,30)`, `>=30`; `unknown` when missing, negative
/// or not finite.
pub fn slope_class(deg: Option<f64>) -> &'static str {
    match deg {
        Some(d) if d.is_finite() && d >= 0.0 => SLOPE_CLASSES[((d / 10.0) as usize).min(3)],
        _ => UNKNOWN,
    }
}

/// Cover class of `cover` (0–1): `[0,0.25)`, `[0.25,0.5)`, `[0.5,0.75)`, `[0.75,1]`; `unknown`
/// when missing, outside [0, 1] or not finite.
pub fn cover_class(cover: Option<f64>) -> &'static str {
    match cover {
        Some(c) if (0.0..=1.0).contains(&c) => COVER_CLASSES[((c / 0.25) as usize).min(3)],
        _ => UNKNOWN,
    }
}

/// Phenology from L2A `land_cover_data/leaf_off_flag` (V2 only): 1 → `leaf_off`, 0 → `leaf_on`;
/// null (V1 has no such dataset) or any other value (fill) → `unknown`, never a silent leaf-on.
pub fn phenology(leaf_off_flag: Option<u8>) -> &'static str {
    match leaf_off_flag {
        Some(0) => "leaf_on",
        Some(1) => "leaf_off",
        _ => UNKNOWN,
    }
}

/// Forest type of a Corine Land Cover level-3 code: 311 broadleaf, 312 coniferous, 313 mixed,
/// any other CLC code (111–523) `other`, anything else (no data) `unknown`.
pub fn forest_type_of_clc(code: u16) -> &'static str {
    match code {
        311 => "broadleaf",
        312 => "coniferous",
        313 => "mixed",
        c if CLC_CODES.contains(&c) => "other",
        _ => UNKNOWN,
    }
}

/// The 44 CLC level-3 codes in the order of the Copernicus raster's grid codes 1…44 (the 8-bit
/// CLC GeoTIFFs store the grid code, 1-based; 48 and 128 are no data).
pub const CLC_CODES: [u16; 44] = [
    111, 112, 121, 122, 123, 124, 131, 132, 133, 141, 142, 211, 212, 213, 221, 222, 223, 231, 241, 242, 243, 244, 311,
    312, 313, 321, 322, 323, 324, 331, 332, 333, 334, 335, 411, 412, 421, 422, 423, 511, 512, 521, 522, 523,
];

/// The CLC code of a Copernicus grid code (1…44), else `None`.
pub fn clc_code_of_grid_code(grid: u16) -> Option<u16> {
    CLC_CODES.get((grid as usize).checked_sub(1)?).copied()
}

/// Validate a forest-type label given by a user (CSV strata): one of [`FOREST_TYPES`].
pub fn parse_forest_type(s: &str) -> Option<&'static str> {
    let s = s.trim();
    FOREST_TYPES.iter().copied().find(|t| t.eq_ignore_ascii_case(s))
}

/// The study's quality filter for one algorithm (docs/gedi-products.md §5): `quality_flag_aN = 1`,
/// `degrade_flag = 0` (per shot) and sensitivity ≥ 0.90. Missing values fail.
pub fn passes_quality(quality_flag: Option<u8>, degrade_flag: Option<u8>, sensitivity: Option<f64>) -> bool {
    quality_flag == Some(1) && degrade_flag == Some(0) && sensitivity.and_then(sensitivity_group).is_some()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sensitivity_groups_at_their_bounds() {
        assert_eq!(sensitivity_group(0.8999), None);
        assert_eq!(sensitivity_group(0.90), Some("low"));
        assert_eq!(sensitivity_group(0.96), Some("low"));
        assert_eq!(sensitivity_group(0.9601), Some("high"));
        assert_eq!(sensitivity_group(1.0), Some("high"));
        assert_eq!(sensitivity_group(f64::NAN), None);
    }

    #[test]
    fn slope_classes_are_left_closed() {
        assert_eq!(slope_class(Some(0.0)), "[0,10)");
        assert_eq!(slope_class(Some(9.999)), "[0,10)");
        assert_eq!(slope_class(Some(10.0)), "[10,20)");
        assert_eq!(slope_class(Some(29.9)), "[20,30)");
        assert_eq!(slope_class(Some(30.0)), ">=30");
        assert_eq!(slope_class(Some(75.0)), ">=30");
        assert_eq!(slope_class(None), "unknown");
        assert_eq!(slope_class(Some(-1.0)), "unknown");
        assert_eq!(slope_class(Some(f64::NAN)), "unknown");
    }

    #[test]
    fn cover_classes_close_the_last_one() {
        assert_eq!(cover_class(Some(0.0)), "[0,0.25)");
        assert_eq!(cover_class(Some(0.25)), "[0.25,0.5)");
        assert_eq!(cover_class(Some(0.5)), "[0.5,0.75)");
        assert_eq!(cover_class(Some(0.7499)), "[0.5,0.75)");
        assert_eq!(cover_class(Some(0.75)), "[0.75,1]");
        assert_eq!(cover_class(Some(1.0)), "[0.75,1]");
        assert_eq!(cover_class(Some(1.01)), "unknown");
        assert_eq!(cover_class(None), "unknown");
    }

    #[test]
    fn phenology_never_defaults_to_leaf_on() {
        assert_eq!(phenology(Some(0)), "leaf_on");
        assert_eq!(phenology(Some(1)), "leaf_off");
        assert_eq!(phenology(None), "unknown");
        assert_eq!(phenology(Some(255)), "unknown");
    }

    #[test]
    fn clc_forest_codes_and_grid_codes() {
        assert_eq!(forest_type_of_clc(311), "broadleaf");
        assert_eq!(forest_type_of_clc(312), "coniferous");
        assert_eq!(forest_type_of_clc(313), "mixed");
        assert_eq!(forest_type_of_clc(211), "other");
        assert_eq!(forest_type_of_clc(999), "unknown");
        assert_eq!(forest_type_of_clc(0), "unknown");
        assert_eq!(clc_code_of_grid_code(23), Some(311));
        assert_eq!(clc_code_of_grid_code(24), Some(312));
        assert_eq!(clc_code_of_grid_code(25), Some(313));
        assert_eq!(clc_code_of_grid_code(1), Some(111));
        assert_eq!(clc_code_of_grid_code(44), Some(523));
        assert_eq!(clc_code_of_grid_code(0), None);
        assert_eq!(clc_code_of_grid_code(48), None);
    }

    #[test]
    fn quality_filter_needs_every_condition() {
        assert!(passes_quality(Some(1), Some(0), Some(0.95)));
        assert!(!passes_quality(Some(0), Some(0), Some(0.95)));
        assert!(!passes_quality(Some(1), Some(10), Some(0.95)));
        assert!(!passes_quality(Some(1), Some(0), Some(0.85)));
        assert!(!passes_quality(None, Some(0), Some(0.95)));
        assert!(!passes_quality(Some(1), None, Some(0.95)));
    }

    #[test]
    fn forest_type_labels_parse() {
        assert_eq!(parse_forest_type(" Broadleaf "), Some("broadleaf"));
        assert_eq!(parse_forest_type("pine"), None);
    }
}

/// One shot's stratum.
#[derive(Debug, Clone, PartialEq)]
pub struct Stratum {
    pub shot_number: u64,
    pub forest_type: &'static str,
    /// CLC level-3 code sampled (raster input only).
    pub clc_code: Option<u16>,
}

/// A shot's number and WGS84 position (lon, lat), if any.
pub type ShotPosition = (u64, Option<(f64, f64)>);
