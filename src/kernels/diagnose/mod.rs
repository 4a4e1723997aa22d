//! The diagnosis of the sim-to-real gap (docs/diagnosis.md), as pure kernels over in-memory shots
//! ([`case::ShotCase`]); `crate::ops::diagnose` reads them from a dataset and writes the results.
//!
//! - [`locate`]: **where** — the study's baseline gap by RH percentile, by stratum, and as the
//!   waveform residual by height above the ALS ground.
//! - [`chain`]: the forward model of a hypothesis — a simulator configuration (weighting, pulse)
//!   of the GEDI chain (ALS waveform, pulse, noise twin, L2A a1–a6) with effects from the shared
//!   registry (`scenario::effects`), and the hypothesis's placement of the shots of short
//!   collocation segments.
//! - [`configuration`]: the study's question first — which configuration reproduces the real
//!   waveforms, chosen on calibration tracks and scored on held-out ones, and the ground bias of
//!   each L2A algorithm under it.
//! - [`gap`]: the gap of a set of shots in the RH frame and the ALS frame, as additive sums.
//! - [`profile`]: the waveform-level gap (mean normalised waveforms by height, as a χ²).
//! - [`fit`]: each effect's parameters fitted to a calibration set.
//! - [`rank`]: **which** and **how far** — cross-fitted on tracks, held-out shrink with bootstrap
//!   intervals, the greedy ladder, `unexplained`.
//! - [`geolocation`]: the ground test that per-shot geolocation must pass.
//! - [`sample`]: the shots the effects are ranked on (whole tracks, up to a number of shots).
//! - [`selftest`]: how often the verdict is right — twins of the shots with each leading
//!   candidate planted, and with none, ranked the same way; the verdict follows from them.

pub mod case;
pub mod chain;
pub mod configuration;
pub mod fit;
pub mod gap;
pub mod geolocation;
pub mod json;
pub mod locate;
pub mod profile;
pub mod rank;
pub mod sample;
pub mod selftest;

use crate::scenario::effects::EffectKind;
pub use case::ShotCase;

/// The whole diagnosis of a set of shots.
#[derive(Debug, Clone)]
pub struct Diagnosis {
    pub where_: locate::Where,
    /// The configuration stage: every configuration's gap, the chosen one, the ground bias per
    /// algorithm under it.
    pub configuration: configuration::ConfigurationChoice,
    /// The chosen configuration's held-out gap (what every first effect's "before" is).
    pub nominal: gap::GapMetrics,
    pub ranking: rank::Ranking,
    /// Twins of the shots, ranked the same way (`None` with `twins` 0).
    pub self_test: Option<selftest::SelfTest>,
    /// What the diagnosis concludes: the ranking, decided by the self-test ([`selftest::verdict`]).
    pub verdict: selftest::Verdict,
    /// Shots ranked (the configuration, the effects, the self-test).
    pub n_shots: usize,
    /// Shots whose baseline gap `where_` measures: the ranked ones and the others
    /// ([`sample::ranked_tracks`]).
    pub n_located: usize,
    /// Tracks of the shots located.
    pub n_located_tracks: usize,
    /// Shots of short collocation segments, which each hypothesis re-places (`chain::reposition`).
    pub n_replaceable: usize,
    pub n_tracks: usize,
    /// (shot, algorithm) pairs left out as ground mismatches.
    pub mismatched: usize,
}

/// Diagnose `cases` with the effects `kinds` (normally [`fit::FITTED_EFFECTS`]) and a self-test of
/// `twins` twin sets per planted hypothesis (0: none, the ranking's intervals decide alone);
/// `on_step` hears each effect tried. `located` are shots outside the ranked sample
/// ([`sample`]): only where the gap lies is measured on them (with `cases`).
pub fn diagnose(
    mut cases: Vec<ShotCase>,
    located: &[ShotCase],
    kinds: &[EffectKind],
    twins: usize,
    on_step: &dyn Fn(&str),
) -> Diagnosis {
    let every: Vec<&ShotCase> = cases.iter().chain(located).collect();
    let where_ = locate::locate(&every);
    let n_located_tracks = every.iter().map(|c| c.real.track.as_str()).collect::<std::collections::BTreeSet<_>>().len();
    let n_located = every.len();
    drop(every);
    case::set_nominal_noise(&mut cases);
    let mismatched = flag_ground_mismatches(&mut cases);
    let cases = &cases;
    let folds = rank::Folds::new(cases);
    let recorded = cases.iter().any(|c| c.real.pulse.is_some());
    let configuration = configuration::choose(&folds, &configuration::candidates(recorded), on_step);
    // Every site's pulsed parts under the chosen configuration, shared by the ranking and the
    // self-test (its twins have their shots' sites).
    let pulsed = chain::PulsedSites::new(&folds.cases, &chain::Model::configured(configuration.chosen));
    let ranking = rank::rank(&folds, &configuration, &pulsed, kinds, on_step);
    let nominal = fit::total(&configuration.gaps).metrics();
    let self_test = (twins > 0 && !ranking.effects.is_empty())
        .then(|| selftest::run(cases, configuration.chosen, &pulsed, &ranking, kinds, twins, on_step));
    let verdict = selftest::verdict(&ranking, self_test.as_ref());
    let n_replaceable = cases.iter().filter(|c| c.sim.short_segment && c.sim.sites.len() > 1).count();
    Diagnosis {
        where_,
        configuration,
        nominal,
        ranking,
        self_test,
        verdict,
        n_shots: cases.len(),
        n_located,
        n_located_tracks,
        n_replaceable,
        n_tracks: folds.n_tracks,
        mismatched,
    }
}

/// A pair is a ground mismatch when its ground difference (real − nominal chain) lies more than
/// max([`MISMATCH_MIN_M`], 4 robust σ) from the median of its algorithm: one side found another
/// mode. Such pairs shift all 99 RH of a shot by metres and would dominate every mean; a uniform
/// offset (datum, ground detection of an algorithm) moves the median with them and flags nothing.
/// Returns the number of pairs flagged.
pub fn flag_ground_mismatches(cases: &mut [ShotCase]) -> usize {
    let refs: Vec<&ShotCase> = cases.iter().collect();
    let gaps = fit::evaluate(&refs, &chain::Model::default());
    let mut flagged = 0;
    for a in 0..crate::gedi::N_ALGORITHMS {
        let mut g: Vec<f64> = gaps.iter().filter_map(|s| s.ground[a]).collect();
        if g.len() < 3 {
            continue;
        }
        g.sort_by(|x, y| x.total_cmp(y));
        let med = g[g.len() / 2];
        let mut dev: Vec<f64> = g.iter().map(|x| (x - med).abs()).collect();
        dev.sort_by(|x, y| x.total_cmp(y));
        let limit = MISMATCH_MIN_M.max(4.0 * 1.4826 * dev[dev.len() / 2]);
        for (c, s) in cases.iter_mut().zip(&gaps) {
            if s.ground[a].is_some_and(|x| (x - med).abs() > limit) {
                c.mismatch[a] = true;
                flagged += 1;
            }
        }
    }
    flagged
}

/// Smallest ground disagreement (m) counted as a mismatch.
pub const MISMATCH_MIN_M: f64 = 1.5;
