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
}
