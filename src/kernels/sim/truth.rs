//! "True" footprint properties from the simulated waveforms, as gediMetric computes them with
//! `-ground` (docs/simulator-reference.md §2.1): ALS ground, canopy top, ground slope and ALS cover.

/// Reflectance ratio ρv/ρg = 0.57/0.40 used for the ALS cover (fixed in the reference, Q9).
pub const RHO_RATIO: f32 = 0.57 / 0.40;

/// Cumulative-energy fraction from the top that defines the canopy top.
pub const TOP_THRESHOLD: f32 = 0.001;

/// Truths of one weighting of one footprint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Truth {
    /// Centre of gravity of the ground waveform (m); `None` without ground energy.
    pub als_ground: Option<f64>,
    /// Label of the first bin from the top where the cumulative energy reaches 0.1 % (m);
    /// `None` without energy.
    pub true_top: Option<f64>,
    /// Ground slope (degrees) from the ground waveform's spread beyond the pulse width;
    /// `None` without ground energy.
    pub slope_deg: Option<f32>,
    /// Canopy cover C/(C + 1.425·G) from the canopy and ground energies; −1 without energy.
    pub als_cover: f32,
}

/// Truths of a waveform `wave` and its ground part `ground` (same bins, top to bottom, bin k at
/// elevation `label(k)`), for a pulse of width `psigma` and a footprint of width `fsigma` (m).
/// Sums and types follow gediMetric `determineTruth` / `waveformTrueCover`.
pub fn truths(wave: &[f32], ground: &[f32], label: impl Fn(usize) -> f64, psigma: f32, fsigma: f32) -> Truth {
    // Ground centre of gravity: f64 numerator, f32 denominator; the plain mean is held in f32.
    let (mut tot_g, mut num, mut mean_g) = (0f32, 0f64, 0f32);
    for (k, &g) in ground.iter().enumerate() {
        tot_g += g;
        num += g as f64 * label(k);
        mean_g = (mean_g as f64 + g as f64 * label(k)) as f32;
    }
    let (als_ground, slope_deg) = if tot_g > 0.0 {
        let mean_g = (mean_g as f64 / tot_g as f64) as f32;
        let mut var = 0f32;
        for (k, &g) in ground.iter().enumerate() {
            let d = label(k) - mean_g as f64;
            var += (d * d) as f32 * g;
        }
        let sd = ((var / tot_g) as f64).sqrt() as f32;
        let slope = if sd > psigma {
            let excess = (sd * sd - psigma * psigma) as f64;
            (excess.sqrt().atan2(fsigma as f64) * 180.0 / std::f64::consts::PI) as f32
        } else {
            0.0
        };
        (Some(num / tot_g as f64), Some(slope))
    } else {
        (None, None)
    };

    let tot: f32 = wave.iter().sum();
    let mut cumul = 0f32;
    let mut true_top = None;
    for (k, &w) in wave.iter().enumerate() {
        cumul += w / tot;
        if cumul >= TOP_THRESHOLD {
            true_top = Some(label(k));
            break;
        }
    }

    Truth { als_ground, true_top, slope_deg, als_cover: als_cover(wave, ground) }
}

/// ALS cover: C = Σ(wave − ground) − n·min(wave), G = Σ ground − n·min(ground),
/// cover = C/(C + 1.425·G), or −1 when C + G ≤ 0.
pub fn als_cover(wave: &[f32], ground: &[f32]) -> f32 {
    let (mut tot_c, mut tot_g, mut min_c, mut min_g) = (0f32, 0f32, 100000f32, 100000f32);
    for (&w, &g) in wave.iter().zip(ground) {
        tot_g += g;
        tot_c += w - g;
        min_g = min_g.min(g);
        min_c = min_c.min(w);
    }
    let n = wave.len().min(ground.len()) as f32;
    tot_c -= min_c * n;
    tot_g -= min_g * n;
    if tot_g + tot_c > 0.0 {
        tot_c / (tot_c + tot_g * RHO_RATIO)
    } else {
        -1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flat_ground_under_a_canopy() {
        // Canopy 0.5 in bins 0–1, ground 1.0 in bin 3; labels 10, 9, 8, 7.
        let wave = [0.5f32, 0.5, 0.0, 1.0];
        let ground = [0.0f32, 0.0, 0.0, 1.0];
        let t = truths(&wave, &ground, |k| 10.0 - k as f64, 0.5, 5.5);
        assert_eq!(t.als_ground, Some(7.0));
        assert_eq!(t.true_top, Some(10.0));
        assert_eq!(t.slope_deg, Some(0.0));
        assert!((t.als_cover - 1.0 / (1.0 + RHO_RATIO)).abs() < 1e-6);
    }

    #[test]
    fn no_ground_and_no_energy() {
        let t = truths(&[0.0; 3], &[0.0; 3], |k| k as f64, 0.5, 5.5);
        assert_eq!((t.als_ground, t.true_top, t.slope_deg, t.als_cover), (None, None, None, -1.0));
    }
}
