//! Transmitted pulse shapes (docs/simulator-reference.md §1.6): Gaussian from σ or FWHM, tabulated from
//! (range, amplitude) pairs (a pulse file or a per-shot GEDI transmit waveform), or a Dirac.

use crate::error::{Error, Result};

use super::footprint::{gaussian, I_THRESH};

/// A sampled pulse: sample j sits at range offset `x[j]` (m, increasing with time, 0 at the
/// peak) with weight `y[j]` (Σy = 1). All in f32, as the reference holds them.
#[derive(Debug, Clone, PartialEq)]
pub struct Pulse {
    /// Range offsets of the samples from the peak (m).
    pub x: Vec<f32>,
    /// Sample weights, normalised to a unit sum.
    pub y: Vec<f32>,
    /// Index of the sample at the peak (offset 0).
    pub cent_bin: usize,
    /// Sample spacing (m).
    pub res: f32,
    /// Pulse width σ (m): the Gaussian σ, or the rms width of a tabulated pulse.
    pub sigma: f32,
}

impl Pulse {
    /// Gaussian pulse of standard deviation `sigma` (m) sampled every `res` m and truncated where
    /// it falls below the intensity cut-off (50 samples for σ = 0.955 m, res = 0.15 m); σ ≤ 0
    /// gives a Dirac.
    pub fn gaussian(sigma: f32, res: f32) -> Result<Pulse> {
        if !(sigma > 0.0) {
            return Ok(Pulse::dirac());
        }
        if !(res > 0.0) || !sigma.is_finite() || !res.is_finite() {
            return Err(Error::Usage(format!("pulse: bad Gaussian pulse sigma {sigma} m / res {res} m")));
        }
        // Half-length: steps (including the failing one) until G < cut-off, two samples each.
        let mut n = 0usize;
        let mut x = 0f32;
        loop {
            let y = gaussian(x as f64, sigma as f64) as f32;
            x += res;
            n += 2;
            if !(y >= I_THRESH) || n > 1_000_000 {
                break;
            }
        }
        let centre = n / 2;
        let mut xs = Vec::with_capacity(n);
        let mut ys = Vec::with_capacity(n);
        let mut x = -(centre as f32) * res;
        let (mut max, mut cent_bin, mut tot) = (-100f32, centre, 0f32);
        for i in 0..n {
            let y = gaussian(x as f64, sigma as f64) as f32;
            if y > max {
                max = y;
                cent_bin = i;
            }
            tot += y;
            xs.push(x);
            ys.push(y);
            x += res; // repeated f32 addition, as the reference samples it
        }
        ys.iter_mut().for_each(|y| *y /= tot);
        Ok(Pulse { x: xs, y: ys, cent_bin, res, sigma })
    }

    /// Gaussian pulse from its full width at half maximum in ns (two-way range: σ =
    /// FWHM·0.2998/2/2.35482 m; 15 ns gives 0.9548501 m, the gediRat default).
    pub fn from_fwhm_ns(fwhm_ns: f32, res: f32) -> Result<Pulse> {
        let fwhm_m = (fwhm_ns as f64 * 0.2998 / 2.0) as f32;
        Pulse::gaussian((fwhm_m as f64 / 2.35482) as f32, res)
    }

    /// A single sample of weight 1 (no pulse broadening).
    pub fn dirac() -> Pulse {
        Pulse { x: vec![0.0], y: vec![1.0], cent_bin: 0, res: 0.0, sigma: 0.0 }
    }

    /// Tabulated pulse from (range m increasing with time, amplitude any scale) pairs, centred as
    /// gediRat `readSimPulse` does: shifted so that the (last) maximum sits at 0; sample spacing =
    /// span/(n−1); σ = rms width about the centre of gravity; weights normalised to Σ = 1.
    pub fn tabulated(pairs: &[(f32, f32)]) -> Result<Pulse> {
        let n = pairs.len();
        if n < 2 {
            return Err(Error::Usage(format!("pulse: need at least 2 samples, got {n}")));
        }
        if pairs.iter().any(|(x, y)| !x.is_finite() || !y.is_finite() || *y < 0.0) {
            return Err(Error::Usage("pulse: non-finite or negative sample".into()));
        }
        let res = ((pairs[n - 1].0 - pairs[0].0).abs() as f64 / (n - 1) as f64) as f32;
        let (mut cofg, mut tot, mut max, mut centre) = (0f32, 0f32, -1000f32, 0f32);
        for &(x, y) in pairs {
            cofg += x * y;
            if y >= max {
                max = y;
                centre = x;
            }
            tot += y;
        }
        if !(tot > 0.0) || !(res > 0.0) {
            return Err(Error::Usage("pulse: zero total amplitude or zero range span".into()));
        }
        cofg = cofg / tot - centre;
        let x: Vec<f32> = pairs.iter().map(|&(x, _)| x - centre).collect();
        let mut cent_bin = 0;
        let mut min_sep = 1000f32;
        for (i, xi) in x.iter().enumerate() {
            if xi.abs() < min_sep {
                min_sep = xi.abs();
                cent_bin = i;
            }
        }
        let var: f32 = x.iter().zip(pairs).fold(0f32, |acc, (xi, &(_, y))| acc + (xi - cofg) * (xi - cofg) * y);
        let sigma = ((var / tot) as f64).sqrt() as f32;
        let y = pairs.iter().map(|&(_, y)| y / tot).collect();
        Ok(Pulse { x, y, cent_bin, res, sigma })
    }
}

impl Pulse {
    /// A pulse already on a regular grid: `pairs` (range offset m, amplitude ≥ 0) every `res` m,
    /// the reference point at index `cent_bin`; zero samples at either end are dropped, weights
    /// normalised to a unit sum, σ the rms width about the centre of gravity.
    pub fn on_grid(pairs: &[(f64, f64)], cent_bin: usize, res: f64) -> Pulse {
        let first = pairs.iter().position(|p| p.1 > 0.0).unwrap_or(0).min(cent_bin);
        let last = pairs.iter().rposition(|p| p.1 > 0.0).unwrap_or(0).max(cent_bin);
        let kept = &pairs[first..=last.min(pairs.len().saturating_sub(1))];
        let tot: f64 = kept.iter().map(|p| p.1).sum();
        if kept.is_empty() || !(tot > 0.0) {
            return Pulse::dirac();
        }
        let mean = kept.iter().map(|p| p.0 * p.1).sum::<f64>() / tot;
        let var = kept.iter().map(|p| (p.0 - mean).powi(2) * p.1).sum::<f64>() / tot;
        Pulse {
            x: kept.iter().map(|p| p.0 as f32).collect(),
            y: kept.iter().map(|p| (p.1 / tot) as f32).collect(),
            cent_bin: cent_bin - first,
            res: res as f32,
            sigma: var.sqrt() as f32,
        }
    }

    /// This pulse convolved with a zero-mean Gaussian of σ `sigma` (m) on its own grid (a system
    /// response beyond the pulse: the `pulse` effect); the reference point stays at offset 0.
    pub fn broadened(&self, sigma: f64) -> Pulse {
        if !(sigma > 0.0) {
            return self.clone();
        }
        let res = if self.res > 0.0 { f64::from(self.res) } else { 0.15 };
        let x0 = f64::from(self.x[0]);
        // Room for the Gaussian's reach (4σ, where `gaussian_blur` truncates it) on both sides.
        let pad = (4.0 * sigma / res).ceil() as usize;
        let mut base = vec![0.0; self.y.len() + 2 * pad];
        base[pad..pad + self.y.len()].iter_mut().zip(&self.y).for_each(|(b, &v)| *b = f64::from(v));
        let wide = gaussian_blur(&base, sigma, res);
        let pairs: Vec<(f64, f64)> =
            wide.iter().enumerate().map(|(k, &v)| (x0 + (k as f64 - pad as f64) * res, v)).collect();
        Pulse::on_grid(&pairs, self.cent_bin + pad, res)
    }

    /// This pulse on a grid of spacing `res` (m), interpolated linearly, offset 0 kept at its
    /// reference point; itself when already on that spacing.
    pub fn resampled(&self, res: f64) -> Pulse {
        if (f64::from(self.res) - res).abs() < 1e-9 || self.x.len() < 2 {
            return self.clone();
        }
        let (x0, x1) = (f64::from(self.x[0]), f64::from(self.x[self.x.len() - 1]));
        let (k0, k1) = ((x0 / res).floor() as i64, (x1 / res).ceil() as i64);
        let at = |x: f64| -> f64 {
            let i = self.x.partition_point(|&v| f64::from(v) <= x);
            if i == 0 || i >= self.x.len() {
                return 0.0;
            }
            let (xa, xb) = (f64::from(self.x[i - 1]), f64::from(self.x[i]));
            let t = if xb > xa { (x - xa) / (xb - xa) } else { 0.0 };
            (1.0 - t) * f64::from(self.y[i - 1]) + t * f64::from(self.y[i])
        };
        let pairs: Vec<(f64, f64)> = (k0..=k1).map(|k| (k as f64 * res, at(k as f64 * res))).collect();
        Pulse::on_grid(&pairs, (-k0).max(0) as usize, res)
    }

    /// The mean of pulses on one grid spacing, aligned at their reference points (offset 0).
    /// `None` without pulses or with different spacings.
    pub fn mean(pulses: &[&Pulse]) -> Option<Pulse> {
        let res = pulses.first()?.res;
        if pulses.iter().any(|p| (p.res - res).abs() > 1e-6 * res.max(1e-6)) {
            return None;
        }
        let lead = pulses.iter().map(|p| p.cent_bin).max()?;
        let tail = pulses.iter().map(|p| p.x.len() - p.cent_bin).max()?;
        let mut y = vec![0.0f64; lead + tail];
        for p in pulses {
            for (j, &v) in p.y.iter().enumerate() {
                y[lead - p.cent_bin + j] += f64::from(v) / pulses.len() as f64;
            }
        }
        let pairs: Vec<(f64, f64)> =
            y.iter().enumerate().map(|(k, &v)| ((k as f64 - lead as f64) * f64::from(res), v)).collect();
        Some(Pulse::on_grid(&pairs, lead, f64::from(res)))
    }

    /// `x` (bins of this pulse's spacing, top first) convolved with the pulse, same length, zero
    /// outside: a return in bin i spreads to bin i + k with the weight of the sample k bins after
    /// the reference point (later in time = lower).
    pub fn convolve_same(&self, x: &[f64]) -> Vec<f64> {
        let y: Vec<f64> = self.y.iter().map(|&w| f64::from(w)).collect();
        spread(x, &y, self.cent_bin as isize)
    }

    /// The pulse as a pulse file (`x y` per line, range m and weight), readable by
    /// [`parse_pulse_text`] and by gediRat's `-readPulse` (which centres it on its peak).
    pub fn to_text(&self, comment: &str) -> String {
        let mut s = String::new();
        for line in comment.lines() {
            s.push_str("# ");
            s.push_str(line);
            s.push('\n');
        }
        for (x, y) in self.x.iter().zip(&self.y) {
            s.push_str(&format!("{x:.6} {y:.9}\n"));
        }
        s
    }
}

/// Convolve with a unit-sum Gaussian of σ `sigma` (m) on bins of `dz` (same length, zero outside).
pub fn gaussian_blur(x: &[f64], sigma: f64, dz: f64) -> Vec<f64> {
    if !(sigma > 0.0) || x.is_empty() {
        return x.to_vec();
    }
    let half = (4.0 * sigma / dz).ceil() as isize;
    let mut kernel: Vec<f64> = (-half..=half).map(|i| (-0.5 * (i as f64 * dz / sigma).powi(2)).exp()).collect();
    let sum: f64 = kernel.iter().sum();
    kernel.iter_mut().for_each(|k| *k /= sum);
    spread(x, &kernel, half)
}

/// `x` spread by `kernel` (same length, zero outside): bin i adds `x[i]·kernel[j]` to bin
/// i + j − `centre`. Bins are visited in order and zero bins skipped, so each output sums its
/// terms in the order of i; the inner loop runs over the slice of taps that land inside.
fn spread(x: &[f64], kernel: &[f64], centre: isize) -> Vec<f64> {
    let n = x.len() as isize;
    let mut out = vec![0.0; x.len()];
    for (i, &v) in x.iter().enumerate() {
        if v == 0.0 {
            continue;
        }
        // Taps j with 0 ≤ i + j − centre < n.
        let lo = (centre - i as isize).max(0);
        let hi = (n + centre - i as isize).min(kernel.len() as isize);
        if lo >= hi {
            continue;
        }
        let start = (i as isize + lo - centre) as usize;
        let taps = &kernel[lo as usize..hi as usize];
        for (o, &k) in out[start..start + taps.len()].iter_mut().zip(taps) {
            *o += v * k;
        }
    }
    out
}

/// Parse a pulse text file: lines `x y` (range m, amplitude), lines starting with `#` and blank
/// lines ignored, extra columns ignored.
pub fn parse_pulse_text(text: &str) -> Result<Vec<(f32, f32)>> {
    let mut pairs = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut cols = line.split_whitespace().map(str::parse::<f64>);
        match (cols.next(), cols.next()) {
            // atof then a store into a float, as the reference reads it
            (Some(Ok(x)), Some(Ok(y))) => pairs.push((x as f32, y as f32)),
            _ => return Err(Error::Usage(format!("pulse: line {}: expected two numbers, got {line:?}", n + 1))),
        }
    }
    Ok(pairs)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_gaussian_pulse_has_50_samples() {
        let p = Pulse::from_fwhm_ns(15.0, 0.15).unwrap();
        assert!((p.sigma - 0.9548501).abs() < 1e-6);
        assert_eq!(p.x.len(), 50);
        assert_eq!(p.cent_bin, 25);
        assert!((p.y.iter().sum::<f32>() - 1.0).abs() < 1e-5);
    }

    #[test]
    fn tabulated_pulse_is_centred_on_its_last_maximum() {
        let p = Pulse::tabulated(&[(0.0, 1.0), (0.15, 3.0), (0.3, 3.0), (0.45, 1.0)]).unwrap();
        assert_eq!(p.cent_bin, 2);
        assert_eq!(p.x[2], 0.0);
        assert!((p.res - 0.15).abs() < 1e-6);
        assert!((p.y.iter().sum::<f32>() - 1.0).abs() < 1e-6);
    }

    #[test]
    fn bad_pulses_are_errors() {
        assert!(Pulse::tabulated(&[(0.0, 1.0)]).is_err());
        assert!(Pulse::tabulated(&[(0.0, 0.0), (0.15, 0.0)]).is_err());
        assert!(parse_pulse_text("# c\n0 1\nfoo\n").is_err());
        assert_eq!(parse_pulse_text("# c\n0 1\n\n0.15 2 9\n").unwrap(), vec![(0.0, 1.0), (0.15, 2.0)]);
        assert_eq!(Pulse::gaussian(0.0, 0.15).unwrap(), Pulse::dirac());
    }

    #[test]
    fn broadening_adds_variances_and_keeps_the_reference() {
        let p = Pulse::gaussian(0.6, 0.15).unwrap();
        let b = p.broadened(0.8);
        assert_eq!(b.x[b.cent_bin], 0.0);
        assert!((b.sigma - 1.0).abs() < 0.01, "{}", b.sigma);
        assert!((b.y.iter().sum::<f32>() - 1.0).abs() < 1e-5);
        let m = Pulse::mean(&[&p, &b]).unwrap();
        assert!((m.y.iter().sum::<f32>() - 1.0).abs() < 1e-5);
        assert_eq!(m.x[m.cent_bin], 0.0);
        let text = m.to_text("mean");
        let back = Pulse::tabulated(&parse_pulse_text(&text).unwrap()).unwrap();
        assert_eq!(back.x.len(), m.x.len());
    }

    #[test]
    fn convolution_moves_energy_later_by_the_pulse_delay() {
        // A pulse whose energy lies one and two bins after its reference.
        let p = Pulse::on_grid(&[(0.0, 0.0), (0.15, 1.0), (0.3, 1.0)], 0, 0.15);
        assert_eq!(p.cent_bin, 0);
        let mut x = vec![0.0; 10];
        x[4] = 2.0;
        let y = p.convolve_same(&x);
        assert_eq!(&y[4..7], &[0.0, 1.0, 1.0]);
    }

    #[test]
    fn blur_keeps_the_sum_and_the_centre() {
        let mut x = vec![0.0; 101];
        x[50] = 1.0;
        let y = gaussian_blur(&x, 0.955, 0.15);
        assert!((y.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        let mean: f64 = y.iter().enumerate().map(|(i, v)| i as f64 * v).sum();
        assert!((mean - 50.0).abs() < 1e-9);
        let var: f64 = y.iter().enumerate().map(|(i, v)| (i as f64 - 50.0).powi(2) * v).sum::<f64>() * 0.15 * 0.15;
        assert!((var.sqrt() - 0.955).abs() < 0.01, "{}", var.sqrt());
    }
}
