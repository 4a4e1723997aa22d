//! A verdict that says how often it is right (docs/diagnosis.md, "The self-test"). After the
//! ranking, twins of the dataset's own shots are made from the chosen configuration — with each
//! leading candidate planted at its fitted magnitude, and with nothing planted — and ranked the
//! same way. What each twin names first gives, for the named effect, how often it was recovered
//! where it was planted, how often it was named where nothing was, and what each other candidate
//! was taken for. The verdict follows from those rates ([`verdict`]).
//!
//! A twin is the shot's own record (track, segment, window, energy, recorded pulse, noise level,
//! the algorithms that passed the study's filter) with its waveform and L2A products replaced by a
//! noise twin of the hypothesis's simulation, at the position the chosen configuration places the
//! real shot (short segments: anywhere in that site's cell; a planted per-shot geolocation error:
//! moved by it). The chain ranks the twins with a noise draw of its own, as it ranks real shots.

use rayon::prelude::*;

use super::case::{set_nominal_noise, ShotCase, SITE_STEP_M};
use super::chain::{reposition, twin_case, Configuration, Model, PulsedSites, Scratch};
use super::rank::{named_first, rank_effects, Folds, Ranking, State};
use crate::scenario::effects::{Effect, EffectKind, GeoLevel};
use crate::scenario::rng::{derive_seed, Stream};

/// Twins per planted hypothesis (`--twins`).
pub const TWINS: usize = 10;
/// Candidates planted besides the ranking's first.
pub const OTHER_CANDIDATES: usize = 2;
/// The named effect is `unexplained` when twins without any effect name it this often.
pub const MAX_FALSE_RATE: f64 = 0.3;
/// …and ambiguous with another candidate when twins with that one planted name it this often.
pub const MAX_CONFUSION_RATE: f64 = 0.3;

/// One hypothesis planted in twins, and what their diagnoses named first.
#[derive(Debug, Clone, PartialEq)]
pub struct Planting {
    /// At the magnitude fitted on the real shots; `None`: nothing planted.
    pub effect: Option<Effect>,
    /// The effect each twin's ranking named first (`None`: unexplained), twin by twin.
    pub named: Vec<Option<String>>,
}

impl Planting {
    /// The planted effect's name, or `none`.
    pub fn label(&self) -> &str {
        self.effect.as_ref().map_or("none", Effect::name)
    }

    /// Twins that named `name` first (`None`: that named nothing).
    pub fn count(&self, name: Option<&str>) -> usize {
        self.named.iter().filter(|n| n.as_deref() == name).count()
    }

    /// Share of twins that named `name` first.
    pub fn rate(&self, name: Option<&str>) -> f64 {
        if self.named.is_empty() {
            return 0.0;
        }
        self.count(name) as f64 / self.named.len() as f64
    }

    /// What the twins named first, most often first: (name, twins), `None` = unexplained.
    pub fn outcomes(&self) -> Vec<(Option<String>, usize)> {
        let mut out: Vec<(Option<String>, usize)> = Vec::new();
        for n in &self.named {
            match out.iter_mut().find(|(m, _)| m == n) {
                Some((_, k)) => *k += 1,
                None => out.push((n.clone(), 1)),
            }
        }
        out.sort_by_key(|o| std::cmp::Reverse(o.1));
        out
    }
}

/// The self-test of a diagnosis.
#[derive(Debug, Clone, PartialEq)]
pub struct SelfTest {
    /// The configuration the twins were made and ranked with.
    pub configuration: Configuration,
    /// Twins per planting.
    pub twins: usize,
    /// The leading candidates, then nothing planted.
    pub plantings: Vec<Planting>,
}

impl SelfTest {
    /// The effect the self-test reports on: the one `verdict` names first, else the best candidate
    /// (the first planted).
    pub fn subject<'a>(&'a self, verdict: &'a Verdict) -> Option<&'a str> {
        verdict.first().or(self.plantings.first().and_then(|p| p.effect.as_ref()).map(Effect::name))
    }

    /// The planting of effect `name` (`None`: nothing planted).
    pub fn planting(&self, name: Option<&str>) -> Option<&Planting> {
        self.plantings.iter().find(|p| p.effect.as_ref().map(Effect::name) == name)
    }
}

/// What the diagnosis concludes.
#[derive(Debug, Clone, PartialEq)]
pub enum Verdict {
    /// This effect explains the gap.
    Named(String),
    /// The first of these explains the gap, but data with one of the others would be read the same.
    Ambiguous(Vec<String>),
    /// No effect explains the gap, or the one that seems to is named as often without it.
    Unexplained,
}

impl Verdict {
    /// The effect named or named first, if any.
    pub fn first(&self) -> Option<&str> {
        match self {
            Verdict::Named(e) => Some(e),
            Verdict::Ambiguous(v) => v.first().map(String::as_str),
            Verdict::Unexplained => None,
        }
    }
}

/// The verdict of `ranking`, decided by its self-test when there is one:
/// - the ranking names nothing → `Unexplained`;
/// - twins without any effect name its first effect E in ≥ [`MAX_FALSE_RATE`] of them →
///   `Unexplained` (E is what this chain finds in data like these when nothing is there);
/// - twins with another candidate M planted name E in ≥ [`MAX_CONFUSION_RATE`] → `Ambiguous`
///   between E and every such M;
/// - else `Named(E)`.
///
/// Without a self-test the ranking's intervals decide alone (`Ambiguous` with its near ties).
pub fn verdict(ranking: &Ranking, test: Option<&SelfTest>) -> Verdict {
    let Some(first) = ranking.effects.first().filter(|_| !ranking.unexplained) else {
        return Verdict::Unexplained;
    };
    let e = first.effect.name().to_string();
    let with: Vec<String> = match test {
        None => ranking.ambiguous_with.clone(),
        Some(t) => {
            if t.planting(None).is_some_and(|p| p.rate(Some(&e)) >= MAX_FALSE_RATE) {
                return Verdict::Unexplained;
            }
            t.plantings
                .iter()
                .filter(|p| p.effect.as_ref().is_some_and(|m| m.name() != e))
                .filter(|p| p.rate(Some(&e)) >= MAX_CONFUSION_RATE)
                .map(|p| p.label().to_string())
                .collect()
        }
    };
    if with.is_empty() {
        Verdict::Named(e)
    } else {
        Verdict::Ambiguous(std::iter::once(e).chain(with).collect())
    }
}

/// The hypotheses planted: the ranking's first effect (named or not), the effects it is
/// ambiguous with, then the next credible effects in ranking order, [`OTHER_CANDIDATES`] besides
/// the first in all — only fits inside their ranges that are not a simpler effect in disguise. An
/// effect that is not credible on the real shots (its intervals, or for geolocation offsets
/// under 1 m) is not an alternative the data support, and is not planted beside the first.
pub fn leading(ranking: &Ranking) -> Vec<Effect> {
    let nameable = ranking.effects.iter().filter(|t| t.nameable());
    let mut out: Vec<Effect> = Vec::new();
    let by_tie = ranking.ambiguous_with.iter().filter_map(|n| ranking.effects.iter().find(|t| t.effect.name() == n));
    let others = nameable.clone().filter(|t| t.credible());
    for t in nameable.take(1).chain(by_tie.filter(|t| t.nameable())).chain(others) {
        if out.len() > OTHER_CANDIDATES {
            break;
        }
        if !out.iter().any(|e| e.name() == t.effect.name()) {
            out.push(t.effect.clone());
        }
    }
    out
}

/// Run the self-test: `twins` twins of `cases` for each leading candidate of `ranking` and for
/// nothing planted, each set ranked with `kinds` on `configuration`. `on_step` hears each set.
pub fn run(
    cases: &[ShotCase],
    configuration: Configuration,
    pulsed: &PulsedSites,
    ranking: &Ranking,
    kinds: &[EffectKind],
    twins: usize,
    on_step: &dyn Fn(&str),
) -> SelfTest {
    let refs: Vec<&ShotCase> = cases.iter().collect();
    // The real shots' positions under the chosen configuration: where their twins are made.
    let placed = reposition(&refs, &Model::configured(configuration).with_pulsed(pulsed));
    let reference_dz = median(cases.iter().filter_map(|c| c.real.collocation_dz).collect());
    let hypotheses: Vec<Option<Effect>> = leading(ranking).into_iter().map(Some).chain([None]).collect();
    let plantings = hypotheses
        .into_iter()
        .map(|effect| {
            let truth = match &effect {
                Some(e) => placed.with(e.clone()),
                None => placed.clone(),
            };
            let label = effect.as_ref().map_or("none", Effect::name).to_string();
            let named = (0..twins)
                .map(|r| {
                    on_step(&format!("self-test: {label} planted, twin set {} of {twins}", r + 1));
                    let set = twin_set(cases, &truth, reference_dz, &format!("{label} {r}"));
                    diagnose_twins(set, configuration, pulsed, kinds)
                })
                .collect();
            Planting { effect, named }
        })
        .collect();
    SelfTest { configuration, twins, plantings }
}

/// The effect a set of twins is named first for, ranked as the real shots are (their noise level
/// and ground mismatches assessed anew) on the configuration given.
fn diagnose_twins(
    mut twins: Vec<ShotCase>,
    configuration: Configuration,
    pulsed: &PulsedSites,
    kinds: &[EffectKind],
) -> Option<String> {
    set_nominal_noise(&mut twins);
    super::flag_ground_mismatches(&mut twins);
    let folds = Folds::new(&twins);
    let state = State::configured(&super::configuration::fixed(&folds, configuration), pulsed);
    let trials = rank_effects(&folds, &state, kinds, &|_| ());
    named_first(&trials).map(|t| t.effect.name().to_string())
}

/// One twin of every case under `truth` (seeded by `label`: each set draws its own noise and
/// positions). Only the algorithms the real shot has are kept; a collocation vertical offset
/// keeps its shot's scatter around the truth's datum (the real offsets less their median, plus the
/// truth's vertical offset).
fn twin_set(cases: &[ShotCase], truth: &Model, reference_dz: Option<f64>, label: &str) -> Vec<ShotCase> {
    let vo = truth.vertical_offset_m();
    let sigma = truth
        .effects
        .iter()
        .find_map(|e| match e {
            Effect::Geolocation { level: GeoLevel::Shot, shot_sigma_m } => Some(*shot_sigma_m),
            _ => None,
        })
        .unwrap_or(0.0);
    cases
        .par_iter()
        .map_init(Scratch::new, |scratch, c| {
            let seed = derive_seed(c.real.shot_number, &["self-test", label]);
            let mut rng = Stream::new(seed, &["twin position"]);
            let here = truth.site(c).offset;
            let movable = c.sim.sites.len() > 1;
            let mut target = here;
            if movable && c.sim.short_segment {
                target.0 += (rng.uniform() - 0.5) * SITE_STEP_M;
                target.1 += (rng.uniform() - 0.5) * SITE_STEP_M;
            }
            if movable && sigma > 0.0 {
                target.0 += sigma * rng.normal();
                target.1 += sigma * rng.normal();
            }
            let target = within_sites(c, target);
            let mut t = twin_case(c, truth, target, seed, scratch)?;
            for (a, r) in t.real.algorithms.iter_mut().zip(&c.real.algorithms) {
                if r.is_none() {
                    *a = None;
                }
            }
            t.real.collocation_dz = c.real.collocation_dz.zip(reference_dz).map(|(d, m)| d - m + vo);
            t.mismatch = Default::default();
            Some(t)
        })
        .flatten()
        .collect()
}

/// `p` clamped to the extent of the case's simulated sites.
fn within_sites(c: &ShotCase, p: (f64, f64)) -> (f64, f64) {
    let sites = c.sim.sites.iter().filter(|s| !s.variants.is_empty());
    let (mut lo, mut hi) = ((f64::INFINITY, f64::INFINITY), (f64::NEG_INFINITY, f64::NEG_INFINITY));
    for s in sites {
        lo = (lo.0.min(s.offset.0), lo.1.min(s.offset.1));
        hi = (hi.0.max(s.offset.0), hi.1.max(s.offset.1));
    }
    if !(lo.0 <= hi.0) {
        return p;
    }
    (p.0.clamp(lo.0, hi.0), p.1.clamp(lo.1, hi.1))
}

fn median(mut v: Vec<f64>) -> Option<f64> {
    v.retain(|x| x.is_finite());
    v.sort_by(|a, b| a.total_cmp(b));
    (!v.is_empty()).then(|| v[v.len() / 2])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::rank::{tests, Trial};

    fn trial(effect: Effect) -> Trial {
        tests::trial(effect, 0.5, [0.3, 0.6], [0.05, 0.1])
    }

    fn ranking(unexplained: bool) -> Ranking {
        Ranking {
            effects: vec![
                trial(Effect::Weighting {
                    method: crate::scenario::effects::WeightMethod::Ratio,
                    rho_ground_over_veg: 0.7,
                }),
                trial(Effect::CanopyChange { height_m: 2.0, fraction: -0.4 }),
                trial(Effect::CanopyChange { height_m: 8.0, fraction: 0.3 }),
                tests::trial(Effect::Pulse { pulse_sigma_m: 1.0 }, 0.5, [-0.2, 0.4], [0.05, 0.1]),
                trial(Effect::Datum { dz_m: 0.3 }),
                trial(Effect::Noise { noise_sigma_factor: 1.1 }),
            ],
            ladder: Vec::new(),
            unexplained,
            ambiguous_with: Vec::new(),
        }
    }

    fn planting(effect: Option<Effect>, named: &[Option<&str>]) -> Planting {
        Planting { effect, named: named.iter().map(|n| n.map(str::to_string)).collect() }
    }

    #[test]
    fn leading_candidates_are_nameable_fits_in_ranking_order() {
        let names: Vec<&str> = leading(&ranking(false)).iter().map(Effect::name).collect();
        // The canopy change on its 2 m bound is skipped, and so is the pulse its intervals do not
        // support; the next nameable, credible one counts.
        assert_eq!(names, ["weighting", "canopy_change", "datum"]);
        let lead = leading(&ranking(false));
        assert_eq!(lead[1], Effect::CanopyChange { height_m: 8.0, fraction: 0.3 });
    }

    #[test]
    fn the_self_test_decides_named_ambiguous_and_unexplained() {
        let r = ranking(false);
        let w = Effect::Weighting { method: crate::scenario::effects::WeightMethod::Ratio, rho_ground_over_veg: 0.7 };
        let c = Effect::CanopyChange { height_m: 8.0, fraction: 0.3 };
        let test = |canopy: &[Option<&str>], none: &[Option<&str>]| SelfTest {
            configuration: Configuration::default(),
            twins: 4,
            plantings: vec![
                planting(Some(w.clone()), &[Some("weighting"); 4]),
                planting(Some(c.clone()), canopy),
                planting(None, none),
            ],
        };
        let quiet = [None, None, None, Some("datum")];
        let named = test(&[Some("canopy_change"), Some("canopy_change"), Some("weighting"), None], &quiet);
        assert_eq!(verdict(&r, Some(&named)), Verdict::Named("weighting".into()));
        // Two of four canopy twins read as weighting: the data could be either.
        let confused = test(&[Some("weighting"), Some("canopy_change"), Some("weighting"), None], &quiet);
        assert_eq!(verdict(&r, Some(&confused)), Verdict::Ambiguous(vec!["weighting".into(), "canopy_change".into()]));
        // Twins without any effect name weighting too: it is what the chain finds in nothing.
        let noisy = test(&[Some("canopy_change"); 4], &[Some("weighting"), None, Some("weighting"), None]);
        assert_eq!(verdict(&r, Some(&noisy)), Verdict::Unexplained);
        // A ranking that names nothing stays unexplained; without a self-test the ranking decides.
        assert_eq!(verdict(&ranking(true), Some(&named)), Verdict::Unexplained);
        assert_eq!(verdict(&r, None), Verdict::Named("weighting".into()));
        assert_eq!(named.planting(None).unwrap().count(None), 3);
        assert_eq!(named.plantings[1].outcomes()[0], (Some("canopy_change".to_string()), 2));
    }
}
