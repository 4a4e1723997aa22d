//! Real GEDI RH brought onto the ALS ground (docs/contracts.md "The study", docs/gedi-products.md §5).
//!
//! GEDI RH values are heights above GEDI's own ground (`elev_lowestmode`). The RH point k sits at
//! `z_ground,GEDI + RH_GEDI[k]`, so its height above the ALS ground is
//! `RH_aligned[k] = RH_GEDI[k] + (z_ground,GEDI − z_ALS)`, both grounds in the ALS vertical datum.
//! The study prints a minus sign; read literally it would double the ground error, so it is a
//! typo for the translation the study describes in words.

/// How the GEDI ground (WGS84-ellipsoidal `elev_lowestmode`) was brought into the ALS datum.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum VerticalReference {
    /// `z = elev_lowestmode − N` with N the geoid offset (ellipsoid − orthometric) used for the shot.
    Geoid {
        /// Geoid offset N, m.
        geoid_offset: f64,
    },
    /// `z = elev_lowestmode − N − dz`, with `dz` the collocation's vertical offset of the segment
    /// (`offsets.dz`: GEDI height after removing N, minus ALS height of the same surface).
    /// Removing `dz` also removes any constant ground bias of GEDI in the segment, so the
    /// `ground_detection` table measures the remaining scatter only.
    GeoidAndCollocation {
        /// Geoid offset N, m.
        geoid_offset: f64,
        /// Collocation vertical offset, m.
        dz: f64,
    },
}

impl VerticalReference {
    /// The value of the results table's `vertical_reference` column: `geoid` or `geoid+collocation_dz`.
    pub fn label(&self) -> &'static str {
        match self {
            VerticalReference::Geoid { .. } => "geoid",
            VerticalReference::GeoidAndCollocation { .. } => "geoid+collocation_dz",
        }
    }

    /// The ellipsoidal height `z_ellipsoid` (m) expressed in the ALS datum.
    pub fn to_als_datum(&self, z_ellipsoid: f64) -> f64 {
        match *self {
            VerticalReference::Geoid { geoid_offset } => z_ellipsoid - geoid_offset,
            VerticalReference::GeoidAndCollocation { geoid_offset, dz } => z_ellipsoid - geoid_offset - dz,
        }
    }
}

/// `RH_aligned[k] = RH_GEDI[k] + (gedi_ground − als_ground)`: heights of GEDI's RH points above
/// the ALS ground. Both grounds in metres in the same (ALS) datum. Non-finite inputs give NaN.
pub fn align_rh(rh_gedi: &[f32], gedi_ground: f64, als_ground: f64) -> Vec<f32> {
    let shift = gedi_ground - als_ground;
    rh_gedi.iter().map(|&h| (h as f64 + shift) as f32).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// docs/gedi-products.md §5's example: ALS ground 100 m, GEDI ground 99 m (1 m too low), canopy
    /// top 120 m: GEDI RH100 = 21 m, aligned RH100 = 20 m (every RH 1 m lower).
    #[test]
    fn gedi_ground_one_metre_low_lowers_every_rh_by_one_metre() {
        let rh_gedi: Vec<f32> = (0..=100).map(|k| 21.0 * k as f32 / 100.0).collect();
        let aligned = align_rh(&rh_gedi, 99.0, 100.0);
        assert_eq!(aligned.len(), 101);
        assert!((aligned[100] - 20.0).abs() < 1e-6, "{}", aligned[100]);
        for (a, g) in aligned.iter().zip(&rh_gedi) {
            assert!((a - (g - 1.0)).abs() < 1e-5, "{a} vs {g}");
        }
        // The aligned top is the canopy top above the ALS ground, whatever GEDI's ground error.
        assert!((99.0 + rh_gedi[100] as f64 - 100.0 - aligned[100] as f64).abs() < 1e-5);
    }

    #[test]
    fn gedi_ground_too_high_raises_rh() {
        let aligned = align_rh(&[0.0, 10.0], 101.5, 100.0);
        assert_eq!(aligned, vec![1.5, 11.5]);
    }

    #[test]
    fn vertical_reference_subtracts_geoid_then_dz() {
        let geoid = VerticalReference::Geoid { geoid_offset: 49.5 };
        assert_eq!(geoid.to_als_datum(350.0), 300.5);
        assert_eq!(geoid.label(), "geoid");
        let both = VerticalReference::GeoidAndCollocation { geoid_offset: 49.5, dz: 0.75 };
        assert_eq!(both.to_als_datum(350.0), 299.75);
        assert_eq!(both.label(), "geoid+collocation_dz");
    }

    #[test]
    fn non_finite_ground_gives_nan() {
        assert!(align_rh(&[1.0], f64::NAN, 100.0)[0].is_nan());
    }
}
