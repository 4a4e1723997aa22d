//! The gap between real and simulated RH, accumulated as sums so that shots, tracks and bootstrap
//! resamples combine by addition.
//!
//! Every (shot, algorithm) pair contributes RH1..RH99 in two frames:
//! - **RH frame**: heights above each side's own ground (`RH_real[k]` vs `RH_sim[k]`), what GEDI
//!   stores; blind to a vertical datum offset.
//! - **ALS frame**: heights above the simulated ground of the real RH points, `RH_real[k] +
//!   (ground_real − ground_sim)` vs `RH_sim[k]`; blind to a ground-detection offset (which moves
//!   GEDI's ground and RH in opposite directions).
//!
//! The gap of a set of pairs is the mean over k of the absolute per-percentile bias, averaged over
//! the two frames (`mean_abs_bias`), with the MSD and its Kobayashi–Salam parts likewise.

use crate::scenario::effects::EffectKind;
use crate::study::msd::MsdSplit;

/// Number of percentiles in the gap (RH1..RH99).
pub const N_PCT: usize = 99;

/// Population moments of (real y, simulated p) per percentile.
#[derive(Debug, Clone, PartialEq)]
pub struct Moments {
    pub n: f64,
    pub sy: [f64; N_PCT],
    pub sp: [f64; N_PCT],
    pub syy: [f64; N_PCT],
    pub spp: [f64; N_PCT],
    pub syp: [f64; N_PCT],
}

impl Default for Moments {
    fn default() -> Self {
        Moments { n: 0.0, sy: [0.0; N_PCT], sp: [0.0; N_PCT], syy: [0.0; N_PCT], spp: [0.0; N_PCT], syp: [0.0; N_PCT] }
    }
}

impl Moments {
    fn add(&mut self, y: impl Fn(usize) -> f64, p: impl Fn(usize) -> f64) {
        self.n += 1.0;
        for k in 0..N_PCT {
            let (y, p) = (y(k), p(k));
            self.sy[k] += y;
            self.sp[k] += p;
            self.syy[k] += y * y;
            self.spp[k] += p * p;
            self.syp[k] += y * p;
        }
    }

    fn merge(&mut self, o: &Moments) {
        self.n += o.n;
        for k in 0..N_PCT {
            self.sy[k] += o.sy[k];
            self.sp[k] += o.sp[k];
            self.syy[k] += o.syy[k];
            self.spp[k] += o.spp[k];
            self.syp[k] += o.syp[k];
        }
    }

    /// Bias of percentile k, simulated − real (the study's sign, docs/diagnosis.md "Signs").
    pub fn bias(&self, k: usize) -> f64 {
        (self.sp[k] - self.sy[k]) / self.n
    }

    /// Kobayashi–Salam split of percentile k (population moments).
    pub fn split(&self, k: usize) -> MsdSplit {
        let n = self.n;
        let (my, mp) = (self.sy[k] / n, self.sp[k] / n);
        let vy = (self.syy[k] / n - my * my).max(0.0);
        let vp = (self.spp[k] / n - mp * mp).max(0.0);
        let cov = self.syp[k] / n - my * mp;
        let (sy, sp) = (vy.sqrt(), vp.sqrt());
        MsdSplit { sb: (my - mp).powi(2), sdsd: (sy - sp).powi(2), lcs: 2.0 * (sy * sp - cov), n: n as usize }
    }
}

/// Sums of one set of (shot, algorithm) pairs.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GapSums {
    /// RH frame.
    pub rh: Moments,
    /// ALS frame.
    pub als: Moments,
    /// Σ and Σ² of the ground difference, real − simulated (GEDI ground − ALS ground, m).
    pub ground: [f64; 2],
    /// Shots the pairs come from (the pairs of one shot share its waveform, so the standard
    /// error of a bias counts shots, not pairs).
    pub n_shots: f64,
}

impl GapSums {
    /// Add one pair: real and simulated RH0..RH100 and grounds.
    pub fn add(&mut self, real_rh: &[f32], real_ground: f64, sim_rh: &[f32], sim_ground: f64) {
        let g = real_ground - sim_ground;
        if !g.is_finite() || real_rh.len() < N_PCT + 2 || sim_rh.len() < N_PCT + 2 {
            return;
        }
        let y = |k: usize| f64::from(real_rh[k + 1]);
        let p = |k: usize| f64::from(sim_rh[k + 1]);
        if (0..N_PCT).any(|k| !y(k).is_finite() || !p(k).is_finite()) {
            return;
        }
        self.rh.add(y, p);
        self.als.add(|k| y(k) + g, p);
        self.ground[0] += g;
        self.ground[1] += g * g;
    }

    pub fn merge(&mut self, o: &GapSums) {
        self.rh.merge(&o.rh);
        self.als.merge(&o.als);
        self.ground[0] += o.ground[0];
        self.ground[1] += o.ground[1];
        self.n_shots += o.n_shots;
    }

    /// Number of pairs.
    pub fn n(&self) -> f64 {
        self.rh.n
    }

    pub fn metrics(&self) -> GapMetrics {
        let n = self.rh.n;
        if n == 0.0 {
            return GapMetrics::default();
        }
        let mut m = GapMetrics { n_pairs: n as usize, ..Default::default() };
        for k in 0..N_PCT {
            let (br, ba) = (self.rh.bias(k), self.als.bias(k));
            m.bias_rh[k] = br;
            m.bias_als[k] = ba;
            m.mean_abs_bias_rh += br.abs() / N_PCT as f64;
            m.mean_abs_bias_als += ba.abs() / N_PCT as f64;
            let shots = self.n_shots.max(1.0);
            let excess = |mo: &Moments, b: f64| {
                let var = ((mo.syy[k] - 2.0 * mo.syp[k] + mo.spp[k]) / n - b * b).max(0.0);
                (b * b - var / shots).max(0.0).sqrt()
            };
            let (er, ea) = (excess(&self.rh, br), excess(&self.als, ba));
            m.systematic_rh += er / N_PCT as f64;
            m.systematic_als += ea / N_PCT as f64;
            m.systematic += (er + ea) / (2.0 * N_PCT as f64);
            let (sr, sa) = (self.rh.split(k), self.als.split(k));
            m.sb += (sr.sb + sa.sb) / (2.0 * N_PCT as f64);
            m.sdsd += (sr.sdsd + sa.sdsd) / (2.0 * N_PCT as f64);
            m.lcs += (sr.lcs + sa.lcs) / (2.0 * N_PCT as f64);
        }
        m.mean_abs_bias = 0.5 * (m.mean_abs_bias_rh + m.mean_abs_bias_als);
        m.msd = m.sb + m.sdsd + m.lcs;
        m.ground_bias = self.ground[0] / n;
        m.ground_rmse = (self.ground[1] / n).sqrt();
        m
    }
}

/// Where an effect is judged (docs/diagnosis.md, "Each effect judged where it acts"): a datum
/// moves GEDI's ground and RH points together, which only the ALS frame sees; a ground detection
/// moves GEDI's ground against its RH, which only the RH frame sees; the other effects act on
/// the waveform and show in both.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Frame {
    Both,
    Rh,
    Als,
}

impl Frame {
    /// The frame an effect acts in.
    pub fn of(effect: EffectKind) -> Frame {
        match effect {
            EffectKind::Datum => Frame::Als,
            EffectKind::GroundDetection | EffectKind::Noise => Frame::Rh,
            EffectKind::Geolocation
            | EffectKind::Weighting
            | EffectKind::Pulse
            | EffectKind::Footprint
            | EffectKind::CanopyChange
            | EffectKind::Occlusion => Frame::Both,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Frame::Both => "both",
            Frame::Rh => "rh",
            Frame::Als => "als",
        }
    }
}

impl GapMetrics {
    /// The systematic gap seen in `frame`.
    pub fn systematic_in(&self, frame: Frame) -> f64 {
        match frame {
            Frame::Both => self.systematic,
            Frame::Rh => self.systematic_rh,
            Frame::Als => self.systematic_als,
        }
    }
}

/// Summary of a gap.
#[derive(Debug, Clone, PartialEq)]
pub struct GapMetrics {
    pub n_pairs: usize,
    /// ½ (mean |bias| over RH1..RH99 in the RH frame + the same in the ALS frame), m.
    pub mean_abs_bias: f64,
    pub mean_abs_bias_rh: f64,
    pub mean_abs_bias_als: f64,
    /// The systematic gap: like `mean_abs_bias`, with each percentile's |bias| corrected for its
    /// sampling noise, √max(0, bias² − se²), se² = var(real − sim)/shots. A gap made of noise
    /// alone is ≈ 0 here while its `mean_abs_bias` is not (E|b̂| ≈ 0.8·se when the bias is 0).
    pub systematic: f64,
    /// The systematic gap of each frame alone (`systematic` is their mean).
    pub systematic_rh: f64,
    pub systematic_als: f64,
    /// MSD averaged over RH1..RH99 and the two frames (m²) = sb + sdsd + lcs.
    pub msd: f64,
    pub sb: f64,
    pub sdsd: f64,
    pub lcs: f64,
    /// Mean and RMS of ground_real − ground_sim (m).
    pub ground_bias: f64,
    pub ground_rmse: f64,
    /// Per-percentile bias RH1..RH99 in each frame (m).
    pub bias_rh: [f64; N_PCT],
    pub bias_als: [f64; N_PCT],
}

impl Default for GapMetrics {
    fn default() -> Self {
        GapMetrics {
            n_pairs: 0,
            mean_abs_bias: f64::NAN,
            mean_abs_bias_rh: 0.0,
            mean_abs_bias_als: 0.0,
            systematic: 0.0,
            systematic_rh: 0.0,
            systematic_als: 0.0,
            msd: f64::NAN,
            sb: 0.0,
            sdsd: 0.0,
            lcs: 0.0,
            ground_bias: f64::NAN,
            ground_rmse: f64::NAN,
            bias_rh: [0.0; N_PCT],
            bias_als: [0.0; N_PCT],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rh(f: impl Fn(usize) -> f32) -> Vec<f32> {
        (0..=100).map(f).collect()
    }

    #[test]
    fn datum_offset_shows_in_the_als_frame_only() {
        let mut s = GapSums::default();
        s.add(&rh(|k| k as f32 * 0.2), 101.0, &rh(|k| k as f32 * 0.2), 100.0);
        let m = s.metrics();
        assert!(m.mean_abs_bias_rh.abs() < 1e-12);
        assert!((m.mean_abs_bias_als - 1.0).abs() < 1e-9);
        assert!((m.mean_abs_bias - 0.5).abs() < 1e-9);
        assert!((m.ground_bias - 1.0).abs() < 1e-12);
        // GEDI's RH points sit 1 m higher above the ALS ground than the simulated ones: the
        // simulation is 1 m short in that frame (simulated − real = −1 m).
        assert!(m.bias_als.iter().all(|b| (b + 1.0).abs() < 1e-6), "{:?}", &m.bias_als[..3]);
    }

    #[test]
    fn bias_is_simulated_minus_real() {
        // Simulated canopy 2 m taller than GEDI's at every percentile, same grounds.
        let mut s = GapSums::default();
        s.add(&rh(|k| k as f32 * 0.2), 100.0, &rh(|k| k as f32 * 0.2 + 2.0), 100.0);
        let m = s.metrics();
        assert!(m.bias_rh.iter().chain(&m.bias_als).all(|b| (b - 2.0).abs() < 1e-6), "{:?}", &m.bias_rh[..3]);
        assert!(m.ground_bias.abs() < 1e-12);
    }

    #[test]
    fn ground_detection_offset_shows_in_the_rh_frame_only() {
        // GEDI ground 0.5 m high, RH 0.5 m low: the RH points sit where the simulated ones do.
        let mut s = GapSums::default();
        s.add(&rh(|k| k as f32 * 0.2 - 0.5), 100.5, &rh(|k| k as f32 * 0.2), 100.0);
        let m = s.metrics();
        assert!((m.mean_abs_bias_rh - 0.5).abs() < 1e-6);
        assert!(m.mean_abs_bias_als.abs() < 1e-6);
    }

    #[test]
    fn msd_parts_add_up_and_merge_is_addition() {
        let mut a = GapSums::default();
        let mut b = GapSums::default();
        for i in 0..20 {
            let t = i as f32;
            let s = if i % 2 == 0 { &mut a } else { &mut b };
            s.add(&rh(|k| k as f32 * 0.1 + t * 0.3), 10.0 + t as f64 * 0.01, &rh(|k| k as f32 * 0.11 + t * 0.2), 10.0);
        }
        let mut all = a.clone();
        all.merge(&b);
        let m = all.metrics();
        assert_eq!(m.n_pairs, 20);
        // MSD recomputed directly.
        let mut direct = 0.0;
        for i in 0..20 {
            let t = i as f64;
            for k in 1..=99 {
                let (y, p) = (k as f64 * 0.1 + t * 0.3, k as f64 * 0.11 + t * 0.2);
                let g = t * 0.01;
                direct += ((y - p).powi(2) + (y + g - p).powi(2)) / 2.0;
            }
        }
        direct /= 20.0 * 99.0;
        assert!((m.msd - direct).abs() < 1e-4, "{} vs {direct}", m.msd);
    }
}
