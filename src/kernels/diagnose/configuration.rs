//! The study's configuration first (docs/diagnosis.md, "Configuration first"): which simulator
//! configuration — return weighting (`count`, `frac`, `int`, `share`) × transmit pulse (the
//! study's Gaussian, each shot's recorded one) × reflectances (equal, the reference's) —
//! reproduces the real waveforms, chosen on calibration tracks and scored on held-out ones, with
//! the ground bias of each L2A algorithm under it.
//! Effects are ranked on top of the chosen configuration (`super::rank`), so a configuration
//! difference is never reported as an unmodelled effect.
//!
//! Every configuration is evaluated once on every shot, with the shots of short segments
//! re-placed for it (`chain::reposition`, within a track and so within a fold). The choice for
//! fold f uses the other fold's shots only: the configuration with the least waveform-level gap
//! (χ² against the study configuration's between-shot variance, `profile::ProfileSums::chi2_against`),
//! the measure every waveform-shaping fit minimises, with the ground/vegetation ratio ρ profiled
//! out: otherwise a method would absorb a reflectance ratio (`count` over-weights the canopy of
//! multi-return pulses much as a darker ground does), and the ratio is the `weighting` effect,
//! judged on top of the choice.

use super::case::ShotCase;
use super::chain::{reposition, Configuration, Model, PulseChoice, Reflectance, REFERENCE_RHO_GROUND_OVER_VEG};
use super::fit::{minimise, ShotGap, RHO_GRID};
use super::gap::{Frame, GapMetrics};
use super::profile::{self, ProfileSums};
use super::rank::{compare, interval, Comparison, Folds};
use crate::gedi::N_ALGORITHMS;
use crate::scenario::effects::{Effect, WeightMethod};
use crate::sim::Weighting;

/// The configurations tried: every weighting (the study's three and the intensity share) × the
/// Gaussian and, when some shot has one, the recorded pulse, with equal reflectances.
pub fn candidates(recorded: bool) -> Vec<Configuration> {
    let pulses: &[PulseChoice] =
        if recorded { &[PulseChoice::Gaussian, PulseChoice::Recorded] } else { &[PulseChoice::Gaussian] };
    Weighting::ALL
        .into_iter()
        .flat_map(|weighting| {
            pulses.iter().map(move |&pulse| Configuration { weighting, pulse, reflectance: Reflectance::Equal })
        })
        .collect()
}

/// One configuration evaluated on every shot.
#[derive(Debug, Clone)]
pub struct ConfigurationTrial {
    pub config: Configuration,
    /// The RH gap on every shot (both frames).
    pub metrics: GapMetrics,
    /// The waveform-level gap against the study configuration's between-shot variance.
    pub waveform_chi2: f64,
    /// The same at the configuration's best ground/vegetation ratio, the real waveforms at their
    /// best vertical shift: what the choice of weighting and pulse is made by.
    pub waveform_chi2_profiled: f64,
    /// Per-shot gaps, in case order.
    pub gaps: Vec<ShotGap>,
}

/// GEDI ground − ALS ground of one L2A algorithm under the chosen configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct AlgorithmGround {
    /// 1..6.
    pub algorithm: u8,
    /// Shots with this algorithm's ground.
    pub n: usize,
    /// Mean (m).
    pub bias_m: f64,
    /// 95 % bootstrap interval over tracks (m).
    pub ci95: [f64; 2],
}

/// The configuration stage of a diagnosis.
#[derive(Debug, Clone)]
pub struct ConfigurationChoice {
    /// Every candidate, in [`candidates`] order.
    pub trials: Vec<ConfigurationTrial>,
    /// Chosen on all tracks (what the diagnosis reports).
    pub chosen: Configuration,
    /// Chosen on each fold's calibration set (the other fold): fold f is scored with `fold_chosen[f]`.
    pub fold_chosen: [Configuration; 2],
    /// The study's configuration (before) against the cross-fitted choice (after), held out.
    pub held_out: Comparison,
    /// Held-out gaps per shot of the cross-fitted choice: what every effect is ranked against.
    pub gaps: Vec<ShotGap>,
    /// Ground bias of each algorithm under the cross-fitted choice.
    pub ground: Vec<AlgorithmGround>,
    /// The vertical shift (m) of the real waveforms, on all tracks, the configurations were
    /// compared at ([`vertical_shift`]; `None` when none was compared).
    pub vertical_shift_m: Option<f64>,
}

impl ConfigurationChoice {
    /// The algorithm whose ground is least biased (smallest |mean|), if any has shots.
    pub fn least_biased_algorithm(&self) -> Option<&AlgorithmGround> {
        self.ground.iter().filter(|g| g.n > 0).min_by(|a, b| a.bias_m.abs().total_cmp(&b.bias_m.abs()))
    }
}

/// Index of the least gap of `chi2` (one per candidate); ties (no waveform information) keep the
/// study's configuration `study`.
fn pick(chi2: &[f64], study: usize) -> usize {
    (0..chi2.len()).fold(study, |b, i| if chi2[i] < chi2[b] - 1e-9 { i } else { b })
}

/// The waveform-level gaps of one candidate: at its best ground/vegetation ratio, and at each
/// configuration's reflectances.
#[derive(Debug, Clone, Copy)]
struct Scores {
    profiled: f64,
    equal: f64,
    reference: f64,
}

impl Scores {
    /// The reflectances whose gap is less (a tie keeps them equal, as gediRat simulates).
    fn reflectance(&self) -> Reflectance {
        if self.reference < self.equal - 1e-9 {
            Reflectance::Reference
        } else {
            Reflectance::Equal
        }
    }
}

/// The grid (m) of the vertical shift of the real waveforms the configurations are compared at.
const SHIFT_GRID: [f64; 7] = [-1.5, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5];

/// `ln ρ` as a ground/vegetation ratio on the configuration's own weighting.
fn ratio(ln_rho: f64) -> Effect {
    Effect::Weighting { method: WeightMethod::Ratio, rho_ground_over_veg: ln_rho.exp() }
}

/// The vertical shift of the real waveforms (as a datum shifts them, `Effect::Datum`) that best
/// matches them with the nominal configuration at its best ratio. The configurations are compared
/// at it: otherwise a datum offset, which moves every real waveform against the ALS ground, chooses
/// the configuration whose waveforms it resembles (the study's wider Gaussian, or the reference's
/// reflectances), and is then no longer what remains to explain.
fn vertical_shift(cases: &[&ShotCase], reference: &ProfileSums) -> f64 {
    let base = reposition(cases, &Model::configured(Configuration::default()));
    let grid: Vec<f64> = RHO_GRID.iter().map(|r: &f64| r.ln()).collect();
    let mut at = |dz: f64| {
        let placed = profile::AfterPulse::new(cases, &base.with(Effect::Datum { dz_m: dz }));
        minimise(&mut |lr| placed.sums(&ratio(lr)).chi2_against(reference), &grid, 6).1
    };
    minimise(&mut at, &SHIFT_GRID, 5).0
}

/// The waveform-level gaps of every candidate on `cases` (re-placed for it with equal
/// reflectances, the real waveforms at their [`vertical_shift`]), against the between-shot
/// variance of the study's configuration (index `study`): at its best ground/vegetation ratio ρ
/// (grid and golden section on ln ρ, as the `weighting` fit), with equal reflectances and with the
/// reference's.
/// Returns them with the shift (`None` without cases).
fn scores(cases: &[&ShotCase], candidates: &[Configuration], study: usize) -> (Vec<Scores>, Option<f64>) {
    if cases.is_empty() {
        return (vec![Scores { profiled: 0.0, equal: 0.0, reference: 0.0 }; candidates.len()], None);
    }
    let reference = profile::sums(cases, &reposition(cases, &Model::configured(candidates[study])));
    let dz_m = vertical_shift(cases, &reference);
    let shift = Effect::Datum { dz_m };
    let grid: Vec<f64> = RHO_GRID.iter().map(|r: &f64| r.ln()).collect();
    let scores = candidates
        .iter()
        .map(|&config| {
            let config = Configuration { reflectance: Reflectance::Equal, ..config };
            let placed =
                profile::AfterPulse::new(cases, &reposition(cases, &Model::configured(config)).with(shift.clone()));
            let mut chi2 = |lr: f64| placed.sums(&ratio(lr)).chi2_against(&reference);
            Scores {
                profiled: minimise(&mut chi2, &grid, 6).1,
                equal: chi2(0.0),
                reference: chi2(REFERENCE_RHO_GROUND_OVER_VEG.ln()),
            }
        })
        .collect();
    (scores, Some(dz_m))
}

/// The configuration chosen on `cases`: the weighting and pulse of the least gap at their best
/// ratio, then the reflectances of the lesser gap for them; with every candidate's scores and the
/// vertical shift they were compared at.
fn choice_on(
    cases: &[&ShotCase],
    candidates: &[Configuration],
    study: usize,
) -> (Configuration, Vec<Scores>, Option<f64>) {
    let (scores, shift) = scores(cases, candidates, study);
    let profiled: Vec<f64> = scores.iter().map(|s| s.profiled).collect();
    let i = pick(&profiled, study);
    (Configuration { reflectance: scores[i].reflectance(), ..candidates[i] }, scores, shift)
}

/// Evaluate every candidate, choose per fold and on all tracks, and score the choice held out.
/// `on_step` hears each configuration tried.
pub fn choose(folds: &Folds, candidates: &[Configuration], on_step: &dyn Fn(&str)) -> ConfigurationChoice {
    let mut candidates = candidates.to_vec();
    if !candidates.contains(&Configuration::study()) {
        candidates.insert(0, Configuration::study());
    }
    let study = candidates.iter().position(|c| *c == Configuration::study()).unwrap_or(0);
    let trial = |config: Configuration| {
        on_step(&format!("configuration {}", config.label()));
        let m = Model::configured(config);
        let gaps = folds.held_out(&[m.clone(), m]);
        let metrics = super::fit::total(&gaps).metrics();
        ConfigurationTrial { config, metrics, waveform_chi2: f64::NAN, waveform_chi2_profiled: f64::NAN, gaps }
    };
    let mut trials: Vec<ConfigurationTrial> = candidates.iter().map(|&c| trial(c)).collect();
    on_step("configuration choice");
    let (chosen, all, vertical_shift_m) = choice_on(&folds.cases, &candidates, study);
    let fold_chosen: [Configuration; 2] = std::array::from_fn(|f| choice_on(&folds.of(1 - f), &candidates, study).0);
    // A choice with the reference's reflectances is evaluated through the chain too.
    for c in std::iter::once(chosen).chain(fold_chosen) {
        if !trials.iter().any(|t| t.config == c) {
            trials.push(trial(c));
        }
    }
    let reference: ProfileSums = trials[study].gaps.iter().filter_map(|g| g.profile.as_ref()).collect();
    for t in &mut trials {
        let sums: ProfileSums = t.gaps.iter().filter_map(|g| g.profile.as_ref()).collect();
        t.waveform_chi2 = sums.chi2_against(&reference);
        let same = |c: &Configuration| c.weighting == t.config.weighting && c.pulse == t.config.pulse;
        t.waveform_chi2_profiled = candidates.iter().position(same).map_or(f64::NAN, |i| all[i].profiled);
    }
    let at = |c: Configuration| trials.iter().position(|t| t.config == c).expect("every choice is a trial");
    let gaps: Vec<ShotGap> =
        (0..folds.cases.len()).map(|i| trials[at(fold_chosen[folds.fold[i]])].gaps[i].clone()).collect();
    let held_out = compare(folds, &trials[study].gaps, &gaps, "configuration", Frame::Both);
    let ground = (0..N_ALGORITHMS).map(|a| algorithm_ground(folds, &gaps, a)).collect();
    ConfigurationChoice { fold_chosen, trials, chosen, held_out, gaps, ground, vertical_shift_m }
}

/// `config` taken as chosen, without trying others: its held-out gaps (what effects are ranked
/// against) and the ground bias per algorithm. The self-test's twins (`super::selftest`) are made
/// with the configuration already chosen; the comparison with the study's is not made (`held_out`
/// compares the choice with itself).
pub fn fixed(folds: &Folds, config: Configuration) -> ConfigurationChoice {
    let m = Model::configured(config);
    let gaps = folds.held_out(&[m.clone(), m]);
    let metrics = super::fit::total(&gaps).metrics();
    let held_out = compare(folds, &gaps, &gaps, "configuration", Frame::Both);
    let ground = (0..N_ALGORITHMS).map(|a| algorithm_ground(folds, &gaps, a)).collect();
    let trial = ConfigurationTrial {
        config,
        metrics,
        waveform_chi2: f64::NAN,
        waveform_chi2_profiled: f64::NAN,
        gaps: gaps.clone(),
    };
    ConfigurationChoice {
        trials: vec![trial],
        chosen: config,
        fold_chosen: [config; 2],
        held_out,
        gaps,
        ground,
        vertical_shift_m: None,
    }
}

/// Mean ground difference of algorithm index `a` over the shots that have it, with its
/// bootstrap interval over tracks.
fn algorithm_ground(folds: &Folds, gaps: &[ShotGap], a: usize) -> AlgorithmGround {
    let mut per_track = vec![(0.0, 0usize); folds.n_tracks];
    for (g, &t) in gaps.iter().zip(&folds.track) {
        if let Some(d) = g.ground[a] {
            per_track[t].0 += d;
            per_track[t].1 += 1;
        }
    }
    let mean = |pick: &mut dyn Iterator<Item = usize>| {
        let (s, n) = pick.fold((0.0, 0), |(s, n), t| (s + per_track[t].0, n + per_track[t].1));
        (n > 0).then(|| s / n as f64)
    };
    let n = per_track.iter().map(|t| t.1).sum();
    let bias_m = mean(&mut (0..folds.n_tracks)).unwrap_or(f64::NAN);
    let resampled: Vec<f64> =
        folds.resamples(&format!("ground a{}", a + 1)).iter().filter_map(|p| mean(&mut p.iter().copied())).collect();
    AlgorithmGround { algorithm: a as u8 + 1, n, bias_m, ci95: interval(resampled) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn candidates_cover_every_weighting_and_the_pulses_there_are() {
        let all = candidates(true);
        assert_eq!(all.len(), 8);
        assert!(all.contains(&Configuration::study()));
        assert!(all.contains(&Configuration::default()));
        let gaussian = candidates(false);
        assert_eq!(gaussian.len(), 4);
        assert!(gaussian.iter().all(|c| c.pulse == PulseChoice::Gaussian));
    }

    #[test]
    fn the_least_gap_is_picked_and_a_tie_keeps_the_study() {
        assert_eq!(pick(&[5.0, 3.0, 4.0], 0), 1);
        assert_eq!(pick(&[5.0, 5.0, 5.0], 2), 2);
        assert_eq!(pick(&[0.0, 0.0], 1), 1);
    }
}
