//! Footprint weights: the Gaussian laser intensity on the ground and the radius beyond which it
//! is ignored (docs/simulator-reference.md §1.3).

/// Intensity cut-off of the reference (gediRat `iThresh`): a return contributes only when its
/// footprint weight exceeds this value; the Gaussian pulse is truncated at the same value.
pub const I_THRESH: f32 = 0.0006;

/// GEDI's footprint σ (m): the reference's and the study's default (`--fsigma`).
pub const GEDI_SIGMA_M: f32 = 5.5;

/// Largest footprint σ accepted (m): 20 times GEDI's; beyond it a "footprint" covers kilometres.
pub const MAX_SIGMA_M: f32 = 100.0;

/// Normalised Gaussian density G(x; σ) = exp(−x²/(2σ²)) / (σ√(2π)), in f64 with the reference's
/// operation order (libclidar `gaussian`), so that its f32 casts round identically.
pub fn gaussian(x: f64, sigma: f64) -> f64 {
    (-x * x / (2.0 * sigma * sigma)).exp() / (sigma * (2.0 * std::f64::consts::PI).sqrt())
}

/// Weight of a return at horizontal distance `d` (m) from the footprint centre: the Gaussian
/// density of σ = `fsigma`, rounded to f32 (not scaled to 1 at the centre).
pub fn footprint_weight(d: f64, fsigma: f32) -> f32 {
    gaussian(d, fsigma as f64) as f32
}

/// Half-width of the square search box around a footprint (`determineGaussSep`): the first x on
/// the f32 grid 0, 0.2, 0.4, … where the Gaussian falls below `thresh`, plus the loop's 0.2
/// overshoot (17.4 m for σ = 5.5 m and the default cut-off).
pub fn gauss_sep(fsigma: f32, thresh: f32) -> f32 {
    // Bounded so that a nonsensical σ cannot loop for ever; 10⁶ steps = 200 km.
    let mut x = 0f32;
    for _ in 0..1_000_000 {
        let y = gaussian(x as f64, fsigma as f64) as f32;
        // C adds the double 0.2 to the float and stores the float.
        x = (x as f64 + 0.2) as f32;
        if !(y >= thresh) {
            break;
        }
    }
    x
}

/// Radius (m) of the ALS a footprint's simulation reads: the search box of [`gauss_sep`] at the
/// default cut-off, plus 1 m so that the 1.5 m density normalisation sees its neighbours.
pub fn read_radius(fsigma: f32) -> f64 {
    gauss_sep(fsigma, I_THRESH) as f64 + 1.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_search_radius_is_17_4_m() {
        assert!((gauss_sep(5.5, I_THRESH) - 17.4).abs() < 1e-4);
    }

    #[test]
    fn weight_cut_off_is_near_17_m() {
        assert!(footprint_weight(17.0, 5.5) > I_THRESH);
        assert!(footprint_weight(17.1, 5.5) <= I_THRESH);
    }
}
