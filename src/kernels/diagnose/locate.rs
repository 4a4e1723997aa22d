//! Where the gap lies, for the study's baseline: real RH of the selected algorithm as stored
//! versus the noise-free simulated RH of the nominal physics from the ALS ground, decomposed by
//! RH percentile, by stratum (with each stratum's share of the squared error), and as the
//! waveform-level residual by height above the ALS ground.

use std::collections::BTreeMap;

use super::case::ShotCase;
use super::chain::Model;
use super::gap::{GapMetrics, GapSums, N_PCT};
use super::profile::{heights, real_profile, simulated_profile, PROFILE_BINS};

/// One percentile of the baseline gap (RH frame, m / m²).
#[derive(Debug, Clone, PartialEq)]
pub struct PercentileGap {
    pub k: usize,
    pub bias: f64,
    pub bias_als_frame: f64,
    pub rmse: f64,
    pub sb: f64,
    pub sdsd: f64,
    pub lcs: f64,
}

/// One stratum's gap.
#[derive(Debug, Clone, PartialEq)]
pub struct StratumGap {
    pub kind: String,
    pub label: String,
    pub n_shots: usize,
    pub metrics: GapMetrics,
    /// Share of the total squared error (RH frame, summed over RH1..RH99) from this stratum's shots.
    pub share_of_squared_error: f64,
}

/// The mean normalised real and simulated waveforms by height above the ALS ground.
#[derive(Debug, Clone, PartialEq)]
pub struct WaveResidual {
    /// Bin centres (m above the ALS ground).
    pub height: Vec<f64>,
    pub real: Vec<f64>,
    pub simulated: Vec<f64>,
    /// simulated − real (fraction of the waveform energy per bin): positive where the simulation
    /// puts energy that GEDI did not record.
    pub residual: Vec<f64>,
    pub n_shots: usize,
}

/// The decomposition.
#[derive(Debug, Clone, PartialEq)]
pub struct Where {
    pub overall: GapMetrics,
    pub percentiles: Vec<PercentileGap>,
    pub strata: Vec<StratumGap>,
    pub waveform: WaveResidual,
}

/// Baseline gap sums of one shot (selected algorithm vs the noise-free nominal simulation).
pub fn baseline_sums(c: &ShotCase) -> GapSums {
    let mut s = GapSums { n_shots: 1.0, ..Default::default() };
    if let Some(r) = c.selected() {
        s.add(&r.rh, r.ground, &c.sim.rh_nominal, c.sim.collocated().als_ground);
    }
    s
}

/// Squared error of one shot's RH1..RH99 (RH frame).
fn squared_error(s: &GapSums) -> f64 {
    (0..N_PCT).map(|k| s.rh.syy[k] - 2.0 * s.rh.syp[k] + s.rh.spp[k]).sum()
}

pub fn locate(cases: &[&ShotCase]) -> Where {
    let per: Vec<GapSums> = cases.iter().map(|c| baseline_sums(c)).collect();
    let mut all = GapSums::default();
    per.iter().for_each(|s| all.merge(s));
    let overall = all.metrics();
    let percentiles = (0..N_PCT)
        .map(|k| {
            let split = all.rh.split(k);
            PercentileGap {
                k: k + 1,
                bias: overall.bias_rh[k],
                bias_als_frame: overall.bias_als[k],
                rmse: split.msd().sqrt(),
                sb: split.sb,
                sdsd: split.sdsd,
                lcs: split.lcs,
            }
        })
        .collect();
    let total_se: f64 = per.iter().map(squared_error).sum();
    let mut groups: BTreeMap<(&str, String), (usize, GapSums, f64)> = BTreeMap::new();
    for (c, s) in cases.iter().zip(&per) {
        if s.n() == 0.0 {
            continue;
        }
        for (kind, label) in c.real.strata.pairs() {
            let e = groups.entry((kind, label.to_string())).or_default();
            e.0 += 1;
            e.1.merge(s);
            e.2 += squared_error(s);
        }
    }
    let strata = groups
        .into_iter()
        .map(|((kind, label), (n, s, se))| StratumGap {
            kind: kind.to_string(),
            label,
            n_shots: n,
            metrics: s.metrics(),
            share_of_squared_error: if total_se > 0.0 { se / total_se } else { 0.0 },
        })
        .collect();
    Where { overall, percentiles, strata, waveform: residual(cases) }
}

/// Mean of the real and simulated waveforms (each normalised to unit energy) on the height grid
/// of [`profile`](super::profile), the nominal chain's simulation against the real waveform at
/// the nominal geoid.
pub fn residual(cases: &[&ShotCase]) -> WaveResidual {
    let mut real = vec![0.0; PROFILE_BINS];
    let mut sim = vec![0.0; PROFILE_BINS];
    let mut n = 0;
    let nominal = Model::default();
    for c in cases.iter().filter(|c| c.selected().is_some()) {
        let (Some(r), Some(m)) = (real_profile(c, c.sim.collocated(), 0.0), simulated_profile(c, &nominal)) else {
            continue;
        };
        n += 1;
        real.iter_mut().zip(&r).for_each(|(a, b)| *a += b);
        sim.iter_mut().zip(&m).for_each(|(a, b)| *a += b);
    }
    let scale = if n > 0 { 1.0 / n as f64 } else { 0.0 };
    real.iter_mut().chain(sim.iter_mut()).for_each(|v| *v *= scale);
    WaveResidual {
        height: heights(),
        residual: sim.iter().zip(&real).map(|(s, r)| s - r).collect(),
        real,
        simulated: sim,
        n_shots: n,
    }
}
