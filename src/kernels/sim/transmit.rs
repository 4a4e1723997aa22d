//! The recorded transmit pulse (docs/pulse.md): a shot's L1B `txwaveform` (1 ns samples) made into
//! a [`Pulse`] — noise floor removed, normalised, and placed on the range axis so that a chosen
//! reference point of the pulse ([`PulseReference`]) lands on the surface that reflects it.

use std::fmt;
use std::str::FromStr;

use super::pulse::Pulse;
use crate::waveform::noise_twin::GEDI_BIN_M;

/// Range spacing of the transmit record's samples (m): 1 ns, two-way.
pub const TX_SAMPLE_M: f64 = GEDI_BIN_M;

/// The point of a transmit pulse that GEDI's ranging refers to: where a surface's return is
/// placed in the received waveform's geolocation (docs/pulse.md has the sources).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PulseReference {
    /// The mean of a Gaussian (+ baseline) least-squares fit to the record: L1B `tx_gloc`, the
    /// only transmit-pulse location the product carries.
    #[default]
    GaussianFit,
    /// The energy centroid (ICESat/GLAS ranged to the transmit centroid).
    Centroid,
    /// The peak (vertex of the parabola through the highest sample and its neighbours), where
    /// gediRat's `-readPulse` centres a read pulse.
    Peak,
}

impl PulseReference {
    /// Every reference, the default first.
    pub const ALL: [PulseReference; 3] = [PulseReference::GaussianFit, PulseReference::Centroid, PulseReference::Peak];

    /// The option value (`gaussian-fit`, `centroid`, `peak`).
    pub fn name(self) -> &'static str {
        match self {
            PulseReference::GaussianFit => "gaussian-fit",
            PulseReference::Centroid => "centroid",
            PulseReference::Peak => "peak",
        }
    }
}

impl fmt::Display for PulseReference {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for PulseReference {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        PulseReference::ALL
            .into_iter()
            .find(|r| r.name() == s)
            .ok_or_else(|| format!("unknown pulse reference '{s}' (known: gaussian-fit, centroid, peak)"))
    }
}

/// The transmit pulse a simulation uses (docs/pulse.md).
#[derive(Debug, Clone, PartialEq)]
pub enum PulseModel {
    /// Gaussian of σ (m), or the study's 15 ns FWHM when `None`.
    Gaussian(Option<f32>),
    /// Each shot's recorded L1B `txwaveform`, placed at this reference point; positions without a
    /// shot use the mean recorded pulse.
    Recorded(PulseReference),
    /// A two-column pulse file (range m, amplitude).
    File(std::path::PathBuf),
}

impl PulseModel {
    /// The `--pulse` value: `gaussian`, `recorded`, or a pulse file's path.
    pub fn parse(text: &str, psigma: Option<f32>, reference: PulseReference) -> PulseModel {
        match text {
            "gaussian" => PulseModel::Gaussian(psigma),
            "recorded" => PulseModel::Recorded(reference),
            file => PulseModel::File(file.into()),
        }
    }
}

/// Why a transmit record gives no pulse.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TransmitError {
    #[error("transmit record of {0} samples is too short (need ≥ {MIN_SAMPLES})")]
    TooShort(usize),
    #[error("transmit record holds a non-finite sample")]
    NotFinite,
    #[error("transmit record has no pulse above its noise floor (peak {0:.1} noise σ)")]
    NoPulse(f64),
}

/// Shortest usable transmit record (samples).
const MIN_SAMPLES: usize = 24;
/// Samples before the peak that are left out of the noise-floor estimate (the pulse's rise).
const RISE_SAMPLES: usize = 16;
/// A record whose peak stands less than this many noise σ above its floor holds no pulse.
const MIN_PEAK_SNR: f64 = 10.0;
/// Below this many noise σ the tail is smoothed (running mean of [`TAIL_MEAN`] samples) before
/// negative values are cut: the slow tail of GEDI's pulse sits at 0.5–1 % of the peak, a few σ.
const TAIL_SNR: f64 = 10.0;
const TAIL_MEAN: usize = 7;

/// A transmit record with its noise floor removed: `samples[i]` (DN above the floor, ≥ 0) at
/// record sample i, and the pulse's reference points in (fractional) samples of the record.
#[derive(Debug, Clone, PartialEq)]
pub struct TransmitPulse {
    pub samples: Vec<f64>,
    /// Noise floor (DN) and its σ, from the samples before the pulse's rise.
    pub floor: f64,
    pub floor_sigma: f64,
    pub peak: f64,
    pub centroid: f64,
    pub gaussian_fit: f64,
}

impl TransmitPulse {
    /// Clean a raw transmit record: the floor is the median of the samples before the rise
    /// ([`RISE_SAMPLES`] before the highest sample), its σ their scaled MAD; samples before the
    /// pulse's onset (the last one below 2σ going back from the peak) are zero; the tail below
    /// [`TAIL_SNR`]·σ is smoothed, then every negative value is cut to 0.
    pub fn from_record(tx: &[f32]) -> Result<TransmitPulse, TransmitError> {
        if tx.len() < MIN_SAMPLES {
            return Err(TransmitError::TooShort(tx.len()));
        }
        if tx.iter().any(|v| !v.is_finite()) {
            return Err(TransmitError::NotFinite);
        }
        let raw: Vec<f64> = tx.iter().map(|&v| f64::from(v)).collect();
        let imax = argmax(&raw);
        let pre_end = imax.saturating_sub(RISE_SAMPLES).max(MIN_SAMPLES / 3).min(raw.len());
        let mut pre: Vec<f64> = raw[..pre_end].to_vec();
        let floor = median(&mut pre);
        let mut dev: Vec<f64> = pre.iter().map(|v| (v - floor).abs()).collect();
        // A floor of constant samples (synthetic records) has no spread: keep σ positive.
        let floor_sigma = (1.4826 * median(&mut dev)).max(1e-6 * (raw[imax] - floor).abs()).max(f64::MIN_POSITIVE);
        let snr = (raw[imax] - floor) / floor_sigma;
        if !(snr >= MIN_PEAK_SNR) {
            return Err(TransmitError::NoPulse(snr));
        }
        let mut s: Vec<f64> = raw.iter().map(|v| v - floor).collect();
        let onset = (0..imax).rev().find(|&i| s[i] < 2.0 * floor_sigma).unwrap_or(0);
        s[..onset].iter_mut().for_each(|v| *v = 0.0);
        let raw_s = s.clone();
        let h = TAIL_MEAN / 2;
        for i in imax + 1..s.len() {
            if raw_s[i] < TAIL_SNR * floor_sigma {
                let (a, b) = (i.saturating_sub(h), (i + h + 1).min(s.len()));
                s[i] = raw_s[a..b].iter().sum::<f64>() / (b - a) as f64;
            }
        }
        s.iter_mut().for_each(|v| *v = v.max(0.0));
        let peak = parabolic_peak(&s, imax);
        let total: f64 = s.iter().sum();
        let centroid = s.iter().enumerate().map(|(i, v)| i as f64 * v).sum::<f64>() / total;
        let gaussian_fit = gaussian_fit_mean(&raw, imax, floor).unwrap_or(peak);
        Ok(TransmitPulse { samples: s, floor, floor_sigma, peak, centroid, gaussian_fit })
    }

    /// The cleaned pulse at fractional record sample `i` (linear interpolation, 0 outside).
    pub fn sample_at(&self, i: f64) -> f64 {
        if !(i >= 0.0 && i <= (self.samples.len() - 1) as f64) {
            return 0.0;
        }
        let j = i.floor() as usize;
        let t = i - j as f64;
        (1.0 - t) * self.samples[j] + t * self.samples.get(j + 1).copied().unwrap_or(0.0)
    }

    /// The record sample (fractional) of reference point `r`.
    pub fn reference_sample(&self, r: PulseReference) -> f64 {
        match r {
            PulseReference::GaussianFit => self.gaussian_fit,
            PulseReference::Centroid => self.centroid,
            PulseReference::Peak => self.peak,
        }
    }

    /// The pulse on the range axis at spacing `res` (m), offset 0 at reference point `r`: the
    /// cleaned samples interpolated linearly (record sample i sits at (i − ref)·[`TX_SAMPLE_M`]),
    /// normalised to a unit sum, σ its rms width.
    pub fn to_pulse(&self, r: PulseReference, res: f64) -> Pulse {
        let reference = self.reference_sample(r);
        let first = self.samples.iter().position(|&v| v > 0.0).unwrap_or(0) as f64;
        let last = self.samples.iter().rposition(|&v| v > 0.0).unwrap_or(0) as f64;
        let step = res / TX_SAMPLE_M;
        let k_lo = ((first - reference) / step).floor() as i64;
        let k_hi = ((last - reference) / step).ceil() as i64;
        let pairs: Vec<(f64, f64)> =
            (k_lo..=k_hi).map(|k| (k as f64 * res, self.sample_at(reference + k as f64 * step))).collect();
        Pulse::on_grid(&pairs, (-k_lo) as usize, res)
    }
}

/// Index of the (first) largest value.
fn argmax(v: &[f64]) -> usize {
    (0..v.len()).fold(0, |b, i| if v[i] > v[b] { i } else { b })
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Vertex of the parabola through samples i − 1, i, i + 1 (i itself at an end).
fn parabolic_peak(s: &[f64], i: usize) -> f64 {
    if i == 0 || i + 1 >= s.len() {
        return i as f64;
    }
    let (a, b, c) = (s[i - 1], s[i], s[i + 1]);
    let d = a - 2.0 * b + c;
    if d < 0.0 {
        i as f64 + (0.5 * (a - c) / d).clamp(-0.5, 0.5)
    } else {
        i as f64
    }
}

/// Mean of the least-squares fit of `b + A·exp(−(i − μ)²/2s²)` to the raw record (Levenberg–
/// Marquardt on four parameters from the peak, the half-maximum width and the floor); `None`
/// when it does not converge to a mean inside the record.
fn gaussian_fit_mean(raw: &[f64], imax: usize, floor: f64) -> Option<f64> {
    let amp = raw[imax] - floor;
    let half = floor + 0.5 * amp;
    let above = raw.iter().filter(|&&v| v >= half).count().max(1) as f64;
    let mut p = [amp, imax as f64, above / 2.3548, floor];
    let model = |p: &[f64; 4], i: f64| {
        let e = (-0.5 * ((i - p[1]) / p[2]).powi(2)).exp();
        (p[3] + p[0] * e, [e, p[0] * e * (i - p[1]) / (p[2] * p[2]), p[0] * e * (i - p[1]).powi(2) / p[2].powi(3), 1.0])
    };
    let cost = |p: &[f64; 4]| raw.iter().enumerate().map(|(i, &y)| (y - model(p, i as f64).0).powi(2)).sum::<f64>();
    let mut c = cost(&p);
    let mut lambda = 1e-3;
    for _ in 0..200 {
        let mut jtj = [[0.0; 4]; 4];
        let mut jtr = [0.0; 4];
        for (i, &y) in raw.iter().enumerate() {
            let (m, g) = model(&p, i as f64);
            for a in 0..4 {
                jtr[a] += g[a] * (y - m);
                for b in 0..4 {
                    jtj[a][b] += g[a] * g[b];
                }
            }
        }
        let mut improved = false;
        while lambda < 1e12 {
            let mut m = jtj;
            (0..4).for_each(|a| m[a][a] *= 1.0 + lambda);
            let Some(step) = solve4(m, jtr) else { break };
            let q = [p[0] + step[0], p[1] + step[1], p[2] + step[2], p[3] + step[3]];
            let cq = if q[2] > 0.0 { cost(&q) } else { f64::INFINITY };
            if cq < c {
                let done = (c - cq) <= 1e-12 * c.max(1e-300) || step[1].abs() < 1e-9;
                p = q;
                c = cq;
                lambda = (lambda / 10.0).max(1e-12);
                improved = true;
                if done {
                    return (p[1] >= 0.0 && p[1] <= (raw.len() - 1) as f64).then_some(p[1]);
                }
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    (p[1].is_finite() && p[1] >= 0.0 && p[1] <= (raw.len() - 1) as f64).then_some(p[1])
}

/// Solve the 4 × 4 system `m·x = v` by Gaussian elimination with partial pivoting.
fn solve4(mut m: [[f64; 4]; 4], mut v: [f64; 4]) -> Option<[f64; 4]> {
    for col in 0..4 {
        let piv = (col..4).max_by(|&a, &b| m[a][col].abs().total_cmp(&m[b][col].abs()))?;
        if !(m[piv][col].abs() > 1e-300) {
            return None;
        }
        m.swap(col, piv);
        v.swap(col, piv);
        let (pivot, pv) = (m[col], v[col]);
        for r in col + 1..4 {
            let f = m[r][col] / pivot[col];
            m[r].iter_mut().zip(&pivot).skip(col).for_each(|(a, b)| *a -= f * b);
            v[r] -= f * pv;
        }
    }
    let mut x = [0.0; 4];
    for r in (0..4).rev() {
        let s: f64 = (r + 1..4).map(|c| m[r][c] * x[c]).sum();
        x[r] = (v[r] - s) / m[r][r];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The noise-free shape of [`asymmetric`] at sample i: a Gaussian core (σ 3 samples at sample
    /// 50, 800 DN) and a slow tail rising after the peak (at most ≈ 3 % of it, decay 20 samples),
    /// like GEDI's transmit pulse (its centroid ≈ 2 samples after the peak).
    fn shape(i: usize) -> f64 {
        shape_at(i as f64)
    }

    fn shape_at(t: f64) -> f64 {
        let x = t - 50.0;
        let core = 800.0 * (-0.5 * (x / 3.0).powi(2)).exp();
        let tail = if x > 0.0 { 30.0 * (-x / 20.0).exp() * (1.0 - (-x / 2.0).exp()) } else { 0.0 };
        core + tail
    }

    /// [`shape`] on a floor of 240 DN with a deterministic ±0.7 DN ripple, 128 samples.
    fn asymmetric() -> Vec<f32> {
        (0..128).map(|i| (240.0 + shape(i) + 0.7 * (i as f64 * 1.7).sin()) as f32).collect()
    }

    #[test]
    fn the_three_references_are_ordered_on_a_slow_tail() {
        let t = TransmitPulse::from_record(&asymmetric()).unwrap();
        assert!((t.floor - 240.0).abs() < 0.5, "floor {}", t.floor);
        // The tail's rise moves the shape's maximum a little after the core's centre; the
        // parabola through three samples finds it within 0.15 sample.
        let top =
            (0..20_000).map(|k| 49.0 + k as f64 * 1e-4).max_by(|a, b| shape_at(*a).total_cmp(&shape_at(*b))).unwrap();
        assert!((t.peak - top).abs() < 0.15, "peak {} max {top}", t.peak);
        // The centroid of the cleaned record is that of the noise-free shape: the tail is kept.
        let total: f64 = (0..128).map(shape).sum();
        let want = (0..128).map(|i| i as f64 * shape(i)).sum::<f64>() / total;
        assert!(want > 51.5, "the synthetic tail moves the centroid {want}");
        assert!((t.centroid - want).abs() < 0.1, "centroid {} want {want}", t.centroid);
        // The least-squares Gaussian follows the core: between the peak and the centroid.
        assert!(t.gaussian_fit > t.peak && t.gaussian_fit < t.centroid, "fit {}", t.gaussian_fit);
    }

    #[test]
    fn a_symmetric_gaussian_has_one_reference() {
        let tx: Vec<f32> =
            (0..128).map(|i| (200.0 + 500.0 * (-0.5 * ((i as f64 - 60.3) / 2.8).powi(2)).exp()) as f32).collect();
        let t = TransmitPulse::from_record(&tx).unwrap();
        assert!((t.gaussian_fit - 60.3).abs() < 1e-3, "{}", t.gaussian_fit);
        assert!((t.centroid - 60.3).abs() < 1e-3, "{}", t.centroid);
        assert!((t.peak - 60.3).abs() < 0.05, "{}", t.peak);
    }

    #[test]
    fn the_pulse_is_placed_at_its_reference() {
        let t = TransmitPulse::from_record(&asymmetric()).unwrap();
        for r in PulseReference::ALL {
            let p = t.to_pulse(r, 0.15);
            assert_eq!(p.x[p.cent_bin], 0.0);
            assert!((p.y.iter().sum::<f32>() - 1.0).abs() < 1e-5);
            // The energy centroid of the placed pulse, in metres after its reference point.
            let mean: f64 = p.x.iter().zip(&p.y).map(|(&x, &y)| f64::from(x) * f64::from(y)).sum();
            let want = (t.centroid - t.reference_sample(r)) * TX_SAMPLE_M;
            assert!((mean - want).abs() < 0.01, "{r}: centroid at {mean} m, want {want}");
        }
        let c = t.to_pulse(PulseReference::Centroid, 0.15);
        let mean: f32 = c.x.iter().zip(&c.y).map(|(x, y)| x * y).sum();
        assert!(mean.abs() < 0.01);
    }

    #[test]
    fn records_without_a_pulse_are_errors() {
        assert_eq!(TransmitPulse::from_record(&[1.0; 10]), Err(TransmitError::TooShort(10)));
        let flat: Vec<f32> = (0..128).map(|i| 240.0 + (i as f32 * 1.3).sin()).collect();
        assert!(matches!(TransmitPulse::from_record(&flat), Err(TransmitError::NoPulse(_))));
        let mut nan = asymmetric();
        nan[3] = f32::NAN;
        assert_eq!(TransmitPulse::from_record(&nan), Err(TransmitError::NotFinite));
        assert_eq!("centroid".parse::<PulseReference>(), Ok(PulseReference::Centroid));
        assert!("middle".parse::<PulseReference>().is_err());
    }
}
