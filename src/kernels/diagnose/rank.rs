//! Which effect: every effect fitted on calibration tracks and scored on held-out tracks (two-fold
//! cross-fitting, split by track, never by shot), with bootstrap confidence intervals over tracks;
//! a greedy ladder for combined causes; `unexplained` when no effect's interval
//! admits a real gain.
//!
//! The sim-to-real gap is observed twice: in the RH metrics and in the waveforms themselves
//! ([`super::profile`]). Effects that reshape the waveform can move the RH percentiles alike —
//! a weighting change, a canopy change and an occlusion all shift energy between ground and
//! canopy — while only one of them reproduces the waveform's shape. Effects are therefore ranked
//! by their held-out reduction of both gaps ([`Comparison::score`]); whether an effect explains
//! anything is decided on the RH gap alone, the contract's measure.

use std::collections::BTreeMap;

use super::case::ShotCase;
use super::chain::{null_cases, reposition, Model, PulsedSites};
use super::configuration::ConfigurationChoice;
use super::fit::{evaluate, fit, geolocation, ShotGap};
use super::gap::{Frame, GapMetrics, GapSums};
use super::geolocation::{ground_test, GroundTest};
use super::profile::ProfileSums;
use crate::scenario::effects::{Effect, EffectKind, GeoLevel};
use crate::scenario::rng::Stream;

/// An effect is named only when the lower bound of its held-out shrink's 95 % interval reaches
/// this: a gain that could be noise, or a few percent, leaves the gap `unexplained`.
pub const MIN_SHRINK_LOWER: f64 = 0.10;
/// …and the lower end of its gain's interval must reach this (m of systematic gap): a relative
/// shrink of a gap that is already within a few centimetres of nothing names nothing either.
pub const MIN_GAIN_M: f64 = 0.02;
/// Smallest per-shot geolocation offset (RMS per axis, m) named: half the spacing of the sites a
/// shot can be re-placed to. Finer offsets cannot be told from what the collocation leaves of
/// the per-track offset (on the long-track control, per-shot re-placement still "finds" offsets
/// of 0.5–0.7 m RMS above the noise-twin floor).
pub const MIN_SHOT_SIGMA_M: f64 = super::case::SITE_STEP_M / 2.0;
/// Bootstrap resamples of the tracks.
pub const BOOTSTRAP: usize = 400;
/// Most effects on the ladder.
pub const MAX_LADDER: usize = 3;

/// Fold (0 or 1) of a track: a stable hash of its name.
pub fn fold_of(track: &str) -> usize {
    (crate::scenario::rng::derive_seed(0x5EED, &["fold", track]) & 1) as usize
}

/// The cases split by the fold of their track.
#[derive(Debug, Clone)]
pub struct Folds<'a> {
    pub cases: Vec<&'a ShotCase>,
    pub fold: Vec<usize>,
    /// Track index of every case (for the bootstrap).
    pub track: Vec<usize>,
    pub n_tracks: usize,
}

impl<'a> Folds<'a> {
    pub fn new(cases: &'a [ShotCase]) -> Folds<'a> {
        let mut ids: BTreeMap<&str, usize> = BTreeMap::new();
        for c in cases {
            let n = ids.len();
            ids.entry(c.real.track.as_str()).or_insert(n);
        }
        Folds {
            cases: cases.iter().collect(),
            fold: cases.iter().map(|c| fold_of(&c.real.track)).collect(),
            track: cases.iter().map(|c| ids[c.real.track.as_str()]).collect(),
            n_tracks: ids.len(),
        }
    }

    pub(super) fn of(&self, f: usize) -> Vec<&'a ShotCase> {
        self.cases.iter().zip(&self.fold).filter(|(_, &g)| g == f).map(|(c, _)| *c).collect()
    }

    /// Evaluate each fold's cases with its own model, its shots re-placed for it; gaps in case
    /// order.
    #[allow(clippy::needless_range_loop)] // the fold index selects in several arrays
    pub fn held_out(&self, models: &[Model; 2]) -> Vec<ShotGap> {
        let mut out: Vec<Option<ShotGap>> = vec![None; self.cases.len()];
        for f in 0..2 {
            let idx: Vec<usize> = (0..self.cases.len()).filter(|&i| self.fold[i] == f).collect();
            let cases: Vec<&ShotCase> = idx.iter().map(|&i| self.cases[i]).collect();
            let placed = reposition(&cases, &models[f]);
            for (i, g) in idx.into_iter().zip(evaluate(&cases, &placed)) {
                out[i] = Some(g);
            }
        }
        out.into_iter().map(|g| g.unwrap_or_default()).collect()
    }

    fn per_track(&self, gaps: &[ShotGap]) -> Vec<GapSums> {
        self.per_track_of(gaps, &self.track)
    }

    /// Sums per track of `gaps`, the track of gap i being `track[i]`.
    fn per_track_of(&self, gaps: &[ShotGap], track: &[usize]) -> Vec<GapSums> {
        let mut t = vec![GapSums::default(); self.n_tracks];
        for (g, &i) in gaps.iter().zip(track) {
            t[i].merge(&g.sums);
        }
        t
    }

    /// Track indices of `BOOTSTRAP` resamples (seeded by `label`: reproducible).
    pub(super) fn resamples(&self, label: &str) -> Vec<Vec<usize>> {
        let n = self.n_tracks;
        if n < 2 {
            return Vec::new();
        }
        let mut rng = Stream::new(0xB007, &["bootstrap", label]);
        (0..BOOTSTRAP).map(|_| (0..n).map(|_| ((rng.uniform() * n as f64) as usize).min(n - 1)).collect()).collect()
    }
}

/// Sum of the per-track sums of the tracks `pick`.
fn sum_of(t: &[GapSums], pick: &[usize]) -> GapSums {
    let mut s = GapSums::default();
    pick.iter().for_each(|&i| s.merge(&t[i]));
    s
}

/// The waveform-level sums of a set of shot gaps.
fn profile_sums(gaps: &[ShotGap]) -> ProfileSums {
    gaps.iter().filter_map(|g| g.profile.as_ref()).collect()
}

/// Held-out comparison of two gaps on the same shots.
#[derive(Debug, Clone)]
pub struct Comparison {
    /// The frame the systematic gap, `shrink` and the intervals are measured in.
    pub frame: Frame,
    pub before: GapMetrics,
    pub after: GapMetrics,
    /// 1 − after/before of the systematic gap in `frame` (`GapMetrics::systematic_in`).
    pub shrink: f64,
    /// 95 % bootstrap interval of the shrink (over tracks).
    pub ci95: [f64; 2],
    /// 95 % interval of before − after of the systematic gap (m).
    pub gain_ci95: [f64; 2],
    /// 1 − after/before of the raw `mean_abs_bias` (noise floor included).
    pub shrink_mean_abs_bias: f64,
    /// Waveform-level gap before and after, both against the between-shot variance before
    /// (`profile::ProfileSums::chi2_against`).
    pub profile_chi2: [f64; 2],
    /// For an effect judged on spread (`geolocation`): the excess MSD over the noise-twin floor,
    /// from which `shrink`, `ci95` and `gain_ci95` then come.
    pub spread: Option<Spread>,
}

/// The spread gap of a `geolocation` hypothesis on held-out tracks: the MSD of the real shots
/// above that of their noise-twin nulls (`chain::null_case`, re-placed the same way), with every
/// segment re-placed as one (before) and every shot on its own (after). The null absorbs what
/// re-placement gains by fitting noise; what remains is what per-shot offsets explain.
#[derive(Debug, Clone, PartialEq)]
pub struct Spread {
    /// MSD (m²) of the real shots, segments re-placed / shots re-placed.
    pub msd: [f64; 2],
    /// MSD (m²) of the nulls, likewise.
    pub floor: [f64; 2],
}

impl Spread {
    /// Excess MSD (m²) before and after.
    pub fn excess(&self) -> [f64; 2] {
        [self.msd[0] - self.floor[0], self.msd[1] - self.floor[1]]
    }
}

/// 1 − after/before of the excess MSD, and the gain in excess RMS (m: √before − √after, each
/// clipped at 0); (0, 0) without excess before.
fn spread_shrink(s: &Spread) -> (f64, f64) {
    let [b, a] = s.excess();
    if !(b > 1e-12) || !a.is_finite() {
        return (0.0, 0.0);
    }
    (1.0 - a / b, b.sqrt() - a.max(0.0).sqrt())
}

impl Comparison {
    /// 1 − after/before of the waveform-level gap; `None` when the effect leaves it unchanged
    /// (it acts on L2A's noise or products only: noise, ground detection).
    pub fn profile_shrink(&self) -> Option<f64> {
        let [b, a] = self.profile_chi2;
        (b > 0.0 && (a - b).abs() > 1e-9 * b).then(|| 1.0 - a / b)
    }

    /// The held-out gap reduction effects are ranked by: the mean of the RH shrink and the
    /// waveform-level shrink, or the RH shrink alone for an effect that leaves the waveforms
    /// unchanged.
    pub fn score(&self) -> f64 {
        if self.spread.is_some() {
            return self.shrink;
        }
        match self.profile_shrink() {
            Some(p) => 0.5 * (self.shrink + p),
            None => self.shrink,
        }
    }
}

/// 1 − after/before of the systematic gap in `frame`; 0 when there is no systematic gap before.
fn shrink_of(before: &GapMetrics, after: &GapMetrics, frame: Frame) -> f64 {
    let (b, a) = (before.systematic_in(frame), after.systematic_in(frame));
    if b > 1e-9 && a.is_finite() {
        1.0 - a / b
    } else {
        0.0
    }
}

/// Compare held-out gaps in `frame` with a bootstrap over tracks (seeded: reproducible).
pub fn compare(folds: &Folds, before: &[ShotGap], after: &[ShotGap], seed_label: &str, frame: Frame) -> Comparison {
    let (tb, ta) = (folds.per_track(before), folds.per_track(after));
    let all: Vec<usize> = (0..folds.n_tracks).collect();
    let (b, a) = (sum_of(&tb, &all).metrics(), sum_of(&ta, &all).metrics());
    let shrink = shrink_of(&b, &a, frame);
    let shrink_mean_abs_bias = 1.0 - a.mean_abs_bias / b.mean_abs_bias;
    let mut shrinks = Vec::with_capacity(BOOTSTRAP);
    let mut gains = Vec::with_capacity(BOOTSTRAP);
    for pick in folds.resamples(seed_label) {
        let (bb, aa) = (sum_of(&tb, &pick).metrics(), sum_of(&ta, &pick).metrics());
        if bb.n_pairs > 0 && aa.n_pairs > 0 {
            shrinks.push(shrink_of(&bb, &aa, frame));
            gains.push(bb.systematic_in(frame) - aa.systematic_in(frame));
        }
    }
    let profile_before = profile_sums(before);
    let profile_chi2 = [profile_before.chi2(), profile_sums(after).chi2_against(&profile_before)];
    Comparison {
        frame,
        before: b,
        after: a,
        shrink,
        ci95: interval(shrinks),
        gain_ci95: interval(gains),
        shrink_mean_abs_bias,
        profile_chi2,
        spread: None,
    }
}

/// The held-out comparison of `geolocation` (`models`: the state's fold models with it): the
/// RH gap as [`compare`] gives it against the state's, and the shrink, intervals and gain from
/// the spread ([`Spread`]) with a bootstrap over tracks.
#[allow(clippy::needless_range_loop)] // the fold index selects in several arrays
fn compare_spread(folds: &Folds, state: &State, models: &[Model; 2], after: &[ShotGap]) -> Comparison {
    let n = folds.cases.len();
    let mut real_before = vec![ShotGap::default(); n];
    let mut null_track: Vec<usize> = Vec::new();
    let (mut null_before, mut null_after) = (Vec::new(), Vec::new());
    for f in 0..2 {
        let idx: Vec<usize> = (0..n).filter(|&i| folds.fold[i] == f).collect();
        let cases: Vec<&ShotCase> = idx.iter().map(|&i| folds.cases[i]).collect();
        let beam = state.folds[f].with(geolocation(GeoLevel::Beam));
        let placed = reposition(&cases, &beam);
        for (&i, g) in idx.iter().zip(evaluate(&cases, &placed)) {
            real_before[i] = g;
        }
        let nulls = null_cases(&cases, &placed);
        let refs: Vec<&ShotCase> = nulls.iter().map(|(_, c)| c).collect();
        null_track.extend(nulls.iter().map(|(j, _)| folds.track[idx[*j]]));
        null_before.extend(evaluate(&refs, &reposition(&refs, &beam)));
        null_after.extend(evaluate(&refs, &reposition(&refs, &models[f])));
    }
    let sets = [
        folds.per_track(&real_before),
        folds.per_track(after),
        folds.per_track_of(&null_before, &null_track),
        folds.per_track_of(&null_after, &null_track),
    ];
    let spread_of = |pick: &[usize]| {
        let m: Vec<f64> = sets.iter().map(|t| sum_of(t, pick).metrics().msd).collect();
        Spread { msd: [m[0], m[1]], floor: [m[2], m[3]] }
    };
    let all: Vec<usize> = (0..folds.n_tracks).collect();
    let spread = spread_of(&all);
    let (shrink, _) = spread_shrink(&spread);
    let (mut shrinks, mut gains) = (Vec::new(), Vec::new());
    for pick in folds.resamples(EffectKind::Geolocation.name()) {
        let s = spread_of(&pick);
        if s.msd.iter().chain(&s.floor).all(|v| v.is_finite()) {
            let (sh, g) = spread_shrink(&s);
            shrinks.push(sh);
            gains.push(g);
        }
    }
    let base = compare(folds, &state.gaps, after, EffectKind::Geolocation.name(), Frame::Both);
    Comparison { shrink, ci95: interval(shrinks), gain_ci95: interval(gains), spread: Some(spread), ..base }
}

/// Order trials: credible and nameable first (fit inside its range, not equivalent to a simpler
/// effect), then credible, then nameable; within each group by held-out score
/// ([`Comparison::score`]), best first. Whether the gap is explained at all is decided apart
/// ([`explained`]): once it is, the best-scoring credible candidate is named, even when its own
/// gain interval is too wide to clear [`MIN_GAIN_M`] alone.
fn order(trials: &mut [Trial]) {
    let tier = |t: &Trial| (!t.credible(), !t.nameable());
    trials.sort_by(|a, b| tier(a).cmp(&tier(b)).then(b.held_out.score().total_cmp(&a.held_out.score())));
}

/// Some trial explains the gap ([`Trial::explains`]); the first of trials ordered by [`order`] is
/// then credible and is the one named.
fn explained(trials: &[Trial]) -> bool {
    trials.iter().any(Trial::explains)
}

/// 95 % bootstrap interval (over tracks, paired) of shrink(a) − shrink(b), both against `before`
/// in `frame`.
fn shrink_difference_ci(folds: &Folds, before: &[ShotGap], a: &[ShotGap], b: &[ShotGap], frame: Frame) -> [f64; 2] {
    let (tb, ta, tc) = (folds.per_track(before), folds.per_track(a), folds.per_track(b));
    let mut d = Vec::with_capacity(BOOTSTRAP);
    for pick in folds.resamples("ambiguity") {
        let bb = sum_of(&tb, &pick).metrics();
        let (aa, cc) = (sum_of(&ta, &pick).metrics(), sum_of(&tc, &pick).metrics());
        if bb.n_pairs > 0 && aa.n_pairs > 0 && cc.n_pairs > 0 {
            d.push(shrink_of(&bb, &aa, frame) - shrink_of(&bb, &cc, frame));
        }
    }
    interval(d)
}

/// The effects that explain as well as the first within noise: nameable, credible, judged on the
/// systematic gap like it, and the paired interval of their shrink difference with the first
/// contains 0.
fn near_ties(folds: &Folds, before: &[ShotGap], trials: &[Trial]) -> Vec<String> {
    let Some(first) = trials.first().filter(|t| explained(trials) && t.held_out.spread.is_none()) else {
        return Vec::new();
    };
    trials[1..]
        .iter()
        .filter(|t| t.credible() && t.nameable() && t.held_out.spread.is_none())
        .filter(|t| {
            // Both judged in the first's frame: the one its shrink was measured in.
            let ci = shrink_difference_ci(folds, before, &first.gaps, &t.gaps, first.held_out.frame);
            ci[0] <= 0.0 && ci[1] >= 0.0
        })
        .map(|t| t.effect.name().to_string())
        .collect()
}

pub(super) fn interval(mut v: Vec<f64>) -> [f64; 2] {
    if v.is_empty() {
        return [f64::NAN, f64::NAN];
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let q = |p: f64| v[((p * (v.len() - 1) as f64).round() as usize).min(v.len() - 1)];
    [q(0.025), q(0.975)]
}

/// One effect tried on top of a model.
#[derive(Debug, Clone)]
pub struct Trial {
    /// Parameters fitted on all shots (what the diagnosis reports).
    pub effect: Effect,
    /// Parameters fitted on each fold's calibration set (the other fold).
    pub fold_effects: [Option<Effect>; 2],
    pub held_out: Comparison,
    /// Held-out gaps per shot with the effect.
    pub gaps: Vec<ShotGap>,
    /// For `geolocation`: the held-out ground test ([`super::geolocation`]), evidence that a wrong
    /// physics model cannot make.
    pub ground_test: Option<GroundTest>,
}

impl Trial {
    /// A candidate the intervals support: shrink ≥ [`MIN_SHRINK_LOWER`] and a gain above 0 at
    /// their lower ends. An effect judged on spread (`geolocation`) must also be resolved — its
    /// per-shot offsets, fitted on each calibration fold, at least [`MIN_SHOT_SIGMA_M`] — and
    /// pass the ground test: the positions its canopy asks for explain the ground elevations.
    pub fn credible(&self) -> bool {
        let resolved = self.held_out.spread.is_none()
            || (self.fold_effects.iter().all(
                |e| matches!(e, Some(Effect::Geolocation { shot_sigma_m, .. }) if *shot_sigma_m >= MIN_SHOT_SIGMA_M),
            ) && self.ground_test.as_ref().is_some_and(GroundTest::passes));
        resolved && self.held_out.ci95[0] >= MIN_SHRINK_LOWER && self.held_out.gain_ci95[0] > 0.0
    }

    /// The intervals admit a real gain, and the fit can be named: credible, nameable (a fit on a
    /// bound, or a simpler effect in disguise, is reported as such and never named) and a gain ≥
    /// [`MIN_GAIN_M`] at the lower end.
    pub fn explains(&self) -> bool {
        self.credible() && self.nameable() && self.held_out.gain_ci95[0] >= MIN_GAIN_M
    }

    /// The fitted parameter on a bound of its range ([`super::fit::at_bound`]), if any.
    pub fn at_bound(&self) -> Option<String> {
        super::fit::at_bound(&self.effect)
    }

    /// The simpler effect the fitted one is equivalent to ([`super::fit::simpler_equivalent`]).
    pub fn equivalent(&self) -> Option<Effect> {
        super::fit::simpler_equivalent(&self.effect)
    }

    /// Its fit lies inside its range and it is not a simpler effect in disguise: only such an
    /// effect is named over another.
    pub fn nameable(&self) -> bool {
        self.at_bound().is_none() && self.equivalent().is_none()
    }
}

/// A step of the ladder: the models of each fold and the held-out gaps they give.
#[derive(Debug, Clone)]
pub struct State {
    pub full: Model,
    pub folds: [Model; 2],
    pub gaps: Vec<ShotGap>,
}

impl State {
    /// The chosen configuration without effects: what the first effects are tried on.
    /// `pulsed`: the chosen configuration's pulsed parts, which its models use.
    pub fn configured(choice: &ConfigurationChoice, pulsed: &PulsedSites) -> State {
        State {
            full: Model::configured(choice.chosen).with_pulsed(pulsed),
            folds: choice.fold_chosen.map(|c| Model::configured(c).with_pulsed(pulsed)),
            gaps: choice.gaps.clone(),
        }
    }
}

/// A state's models re-placed for fitting ([`reposition`]): the full model on every case, fold f's
/// on the calibration cases of fold f (the other fold's). Every effect tried on the state starts
/// from them, so they are computed once per state.
pub struct Placed {
    full: Model,
    folds: [Model; 2],
}

impl Placed {
    pub fn new(folds: &Folds, state: &State) -> Placed {
        Placed {
            full: reposition(&folds.cases, &state.full),
            folds: std::array::from_fn(|f| reposition(&folds.of(1 - f), &state.folds[f])),
        }
    }
}

/// Fit `kind` on top of `state` (per fold on the other fold's tracks; once on all for the
/// reported parameters) and score it on the held-out tracks. `placed` is [`Placed::new`] of
/// `folds` and `state`.
pub fn try_effect(folds: &Folds, state: &State, placed: &Placed, kind: EffectKind) -> Option<Trial> {
    let effect = fit(kind, &state.full, &placed.full, &folds.cases)?;
    // Fold f is scored with the parameters fitted on fold 1 − f.
    let fitted: [Option<Effect>; 2] =
        std::array::from_fn(|f| fit(kind, &state.folds[f], &placed.folds[f], &folds.of(1 - f)));
    let models: [Model; 2] = std::array::from_fn(|f| match &fitted[f] {
        Some(e) => state.folds[f].with(e.clone()),
        None => state.folds[f].clone(),
    });
    let gaps = folds.held_out(&models);
    let (held_out, ground_test) = if kind == EffectKind::Geolocation {
        (compare_spread(folds, state, &models, &gaps), Some(ground_test(folds, &state.folds)))
    } else {
        (compare(folds, &state.gaps, &gaps, kind.name(), Frame::of(kind)), None)
    };
    Some(Trial { effect, fold_effects: fitted, held_out, gaps, ground_test })
}

/// The ranking and the ladder.
#[derive(Debug, Clone)]
pub struct Ranking {
    /// Every effect tried on the nominal chain, best held-out shrink first.
    pub effects: Vec<Trial>,
    /// Effects added one after another while each explains part of what remains.
    pub ladder: Vec<Trial>,
    /// No effect's interval admits a real gain.
    pub unexplained: bool,
    /// Effects that explain as well as the first within noise (`near_ties`): the diagnosis is
    /// then ambiguous between the first and these.
    pub ambiguous_with: Vec<String>,
}

/// Rank `kinds` on the chosen configuration, then climb the ladder. `on_step` is told each
/// effect tried.
pub fn rank(
    folds: &Folds,
    choice: &ConfigurationChoice,
    pulsed: &PulsedSites,
    kinds: &[EffectKind],
    on_step: &dyn Fn(&str),
) -> Ranking {
    let nominal = State::configured(choice, pulsed);
    let effects = rank_effects(folds, &nominal, kinds, on_step);
    let unexplained = !explained(&effects);
    let ambiguous_with = near_ties(folds, &nominal.gaps, &effects);
    let mut ladder: Vec<Trial> = Vec::new();
    if !unexplained {
        let first = effects[0].clone();
        let mut state = advance(&nominal, &first);
        ladder.push(first);
        while ladder.len() < MAX_LADDER {
            let used: Vec<EffectKind> = ladder.iter().map(|t| t.effect.kind()).collect();
            let placed = Placed::new(folds, &state);
            let mut step: Vec<Trial> = kinds
                .iter()
                .filter(|k| !used.contains(k))
                .filter_map(|&k| {
                    on_step(&format!("ladder step {}: {}", ladder.len() + 1, k.name()));
                    try_effect(folds, &state, &placed, k)
                })
                .collect();
            order(&mut step);
            if !explained(&step) {
                break;
            }
            let t = step.swap_remove(0);
            state = advance(&state, &t);
            ladder.push(t);
        }
    }
    Ranking { effects, ladder, unexplained, ambiguous_with }
}

/// Every effect of `kinds` tried on `state`, best first ([`order`]).
pub fn rank_effects(folds: &Folds, state: &State, kinds: &[EffectKind], on_step: &dyn Fn(&str)) -> Vec<Trial> {
    let placed = Placed::new(folds, state);
    let mut effects: Vec<Trial> = kinds
        .iter()
        .filter_map(|&k| {
            on_step(k.name());
            try_effect(folds, state, &placed, k)
        })
        .collect();
    order(&mut effects);
    effects
}

/// The effect [`rank_effects`]'s ordered `trials` name first, if the gap is explained.
pub fn named_first(trials: &[Trial]) -> Option<&Trial> {
    trials.first().filter(|_| explained(trials))
}

fn advance(state: &State, t: &Trial) -> State {
    State {
        full: state.full.with(t.effect.clone()),
        folds: std::array::from_fn(|f| match &t.fold_effects[f] {
            Some(e) => state.folds[f].with(e.clone()),
            None => state.folds[f].clone(),
        }),
        gaps: t.gaps.clone(),
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    #[test]
    fn folds_are_stable_and_both_used() {
        let n0 = (0..200).filter(|i| fold_of(&format!("g{i}/BEAM0101")) == 0).count();
        assert!(n0 > 70 && n0 < 130, "{n0}");
        assert_eq!(fold_of("a/BEAM0000"), fold_of("a/BEAM0000"));
    }

    #[test]
    fn score_averages_the_two_shrinks_only_when_the_waveform_moves() {
        let c = |chi2: [f64; 2]| Comparison {
            frame: Frame::Both,
            before: GapMetrics::default(),
            after: GapMetrics::default(),
            shrink: 0.6,
            ci95: [0.4, 0.7],
            gain_ci95: [0.05, 0.1],
            shrink_mean_abs_bias: 0.5,
            profile_chi2: chi2,
            spread: None,
        };
        assert_eq!(c([1000.0, 1000.0]).profile_shrink(), None);
        assert_eq!(c([1000.0, 1000.0]).score(), 0.6);
        assert!((c([1000.0, 800.0]).score() - 0.4).abs() < 1e-12);
    }

    /// A trial of `effect` with these held-out figures (also the self-test's tests').
    pub(in crate::diagnose) fn trial(effect: Effect, shrink: f64, ci95: [f64; 2], gain_ci95: [f64; 2]) -> Trial {
        let held_out = Comparison {
            frame: Frame::Both,
            before: GapMetrics::default(),
            after: GapMetrics::default(),
            shrink,
            ci95,
            gain_ci95,
            shrink_mean_abs_bias: shrink,
            profile_chi2: [1000.0, 1000.0],
            spread: None,
        };
        Trial { effect, fold_effects: [None, None], held_out, gaps: Vec::new(), ground_test: None }
    }

    #[test]
    fn the_best_credible_candidate_is_named_once_the_gap_is_explained() {
        // The occlusion world of the independent generator (docs/diagnosis.md, "Ranking"):
        // occlusion fits best but its gain interval starts below MIN_GAIN_M; a weaker
        // canopy change clears it.
        let occlusion = || trial(Effect::Occlusion { height_m: 5.2, gain: 0.3 }, 0.73, [0.13, 0.78], [0.007, 0.097]);
        let canopy = trial(Effect::CanopyChange { height_m: 6.5, fraction: 0.1 }, 0.3, [0.15, 0.4], [0.03, 0.05]);
        let noise = trial(Effect::Noise { noise_sigma_factor: 1.2 }, 0.9, [0.05, 0.95], [-0.01, 0.2]);
        let mut trials = vec![noise.clone(), canopy, occlusion()];
        order(&mut trials);
        assert!(explained(&trials));
        let names: Vec<&str> = trials.iter().map(|t| t.effect.name()).collect();
        assert_eq!(names, ["occlusion", "canopy_change", "noise"]);
        // Without an effect that clears both bars, nothing is named.
        let mut trials = vec![noise, occlusion()];
        order(&mut trials);
        assert!(!explained(&trials));
        assert_eq!(trials[0].effect.name(), "occlusion");
    }

    #[test]
    fn a_fit_on_a_bound_or_in_disguise_is_never_named() {
        // A canopy change at the lowest height of its range (2 m) with a gain: a bound, and a
        // weighting ratio in disguise. Its intervals clear every bar, yet it explains nothing.
        let bound = trial(Effect::CanopyChange { height_m: 2.0, fraction: -0.41 }, 0.8, [0.5, 0.9], [0.1, 0.3]);
        assert!(bound.credible() && !bound.nameable() && !bound.explains());
        let mut trials = vec![bound.clone()];
        order(&mut trials);
        assert!(!explained(&trials), "an effect on a bound alone leaves the gap unexplained");
        // With an interior fit that explains, that one is first and named.
        let interior = trial(Effect::Pulse { pulse_sigma_m: 1.1 }, 0.5, [0.3, 0.6], [0.05, 0.1]);
        let mut trials = vec![bound, interior];
        order(&mut trials);
        assert!(explained(&trials));
        assert_eq!(trials[0].effect.name(), "pulse");
    }

    #[test]
    fn each_effect_is_judged_in_its_frame() {
        // A datum shows in the ALS frame alone: judged there, its shrink is not diluted by the RH
        // frame's mismatch, which no datum can touch.
        let before = GapMetrics { systematic_rh: 0.4, systematic_als: 1.0, systematic: 0.7, ..Default::default() };
        let after = GapMetrics { systematic_rh: 0.4, systematic_als: 0.3, systematic: 0.35, ..Default::default() };
        assert!((shrink_of(&before, &after, Frame::of(EffectKind::Datum)) - 0.7).abs() < 1e-12);
        assert!((shrink_of(&before, &after, Frame::Both) - 0.5).abs() < 1e-12);
        assert_eq!(shrink_of(&before, &after, Frame::of(EffectKind::GroundDetection)), 0.0);
    }

    #[test]
    fn interval_of_a_constant_is_the_constant() {
        assert_eq!(interval(vec![0.3; 50]), [0.3, 0.3]);
        assert!(interval(vec![]).iter().all(|v| v.is_nan()));
    }
}
