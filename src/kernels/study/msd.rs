//! Mean squared deviation and its decomposition (Kobayashi & Salam 2000), population moments.
//!
//! With y the real (aligned) values and ŷ the simulated ones:
//! `MSD = mean((y − ŷ)²) = SB + SDSD + LCS`, `SB = (ȳ − ŷ̄)²`, `SDSD = (s_y − s_ŷ)²`,
//! `LCS = 2(1 − r)·s_y·s_ŷ = 2(s_y·s_ŷ − cov(y, ŷ))` (the second form stays defined when a
//! standard deviation is 0). The SQL of `queries/msd.sql` computes the same numbers.

/// The three parts of the MSD, and the count.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MsdSplit {
    /// Squared bias.
    pub sb: f64,
    /// Squared difference of standard deviations.
    pub sdsd: f64,
    /// Lack of correlation weighted by the standard deviations.
    pub lcs: f64,
    /// Number of pairs.
    pub n: usize,
}

impl MsdSplit {
    /// SB + SDSD + LCS.
    pub fn msd(&self) -> f64 {
        self.sb + self.sdsd + self.lcs
    }
}

/// The decomposition of the pairs (`real[i]`, `simulated[i]`); `None` when empty or of different lengths.
pub fn msd_split(real: &[f64], simulated: &[f64]) -> Option<MsdSplit> {
    let n = real.len();
    if n == 0 || simulated.len() != n {
        return None;
    }
    let nf = n as f64;
    let my = real.iter().sum::<f64>() / nf;
    let ms = simulated.iter().sum::<f64>() / nf;
    let (mut vy, mut vs, mut c) = (0.0, 0.0, 0.0);
    for (y, s) in real.iter().zip(simulated) {
        vy += (y - my) * (y - my);
        vs += (s - ms) * (s - ms);
        c += (y - my) * (s - ms);
    }
    let (sy, ss, cov) = ((vy / nf).sqrt(), (vs / nf).sqrt(), c / nf);
    Some(MsdSplit { sb: (my - ms).powi(2), sdsd: (sy - ss).powi(2), lcs: 2.0 * (sy * ss - cov), n })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parts_add_up_to_the_mean_squared_difference() {
        let y = [10.0, 12.5, 17.0, 21.0, 8.25];
        let s = [11.0, 12.0, 15.5, 23.0, 9.0];
        let split = msd_split(&y, &s).unwrap();
        let direct = y.iter().zip(&s).map(|(a, b)| (a - b) * (a - b)).sum::<f64>() / 5.0;
        assert!((split.msd() - direct).abs() < 1e-12, "{split:?} {direct}");
        assert!(split.sb >= 0.0 && split.sdsd >= 0.0 && split.lcs >= 0.0);
    }

    #[test]
    fn pure_offset_is_all_bias_and_pure_scaling_has_no_lcs() {
        let y = [1.0, 2.0, 3.0];
        let off = msd_split(&y, &[3.0, 4.0, 5.0]).unwrap();
        assert!((off.sb - 4.0).abs() < 1e-12 && off.sdsd.abs() < 1e-12 && off.lcs.abs() < 1e-12);
        let scaled = msd_split(&y, &[0.0, 2.0, 4.0]).unwrap();
        assert!(scaled.sb.abs() < 1e-12 && scaled.lcs.abs() < 1e-12 && scaled.sdsd > 0.0);
    }

    #[test]
    fn constant_series_and_bad_input() {
        let split = msd_split(&[5.0, 5.0], &[4.0, 6.0]).unwrap();
        assert!((split.msd() - 1.0).abs() < 1e-12);
        assert!(msd_split(&[], &[]).is_none());
        assert!(msd_split(&[1.0], &[1.0, 2.0]).is_none());
    }
}
