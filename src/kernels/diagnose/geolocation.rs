//! The ground test of per-shot geolocation (docs/diagnosis.md, "Geolocation: evidence that
//! model mismatch cannot make").
//!
//! Re-placing single shots among nearby sites absorbs whatever the model gets wrong: any site
//! whose simulated waveform happens to resemble a mis-modelled real one gains. A real
//! displacement leaves a trace a wrong model cannot: the whole footprint moved, so the position
//! its **canopy** asks for also explains where GEDI found the **ground** on a slope. The test:
//!
//! 1. each shot's canopy is matched on its own — real and simulated waveforms each taken from
//!    [`CANOPY_FROM_M`] above their own ground (GEDI's lowest mode; the site's ALS ground), the
//!    best Pearson r over a free vertical shift at every site — which holds every elevation out of
//!    the fit and is blind to the ground/canopy energy ratio (weighting, occlusion, datum);
//! 2. the ground elevation that position predicts, relative to the segment's own site
//!    (ALS ground at the canopy's site − at the segment's), against the one GEDI reports
//!    (GEDI ground − ALS ground at the segment's site);
//! 3. both centred within each track — what is constant along a track (a beam slanted off nadir
//!    displaces its canopy from its ground alike at every shot; a per-track offset) is not a
//!    per-shot displacement — the regression slope β of reported on predicted, through the
//!    origin, with a bootstrap interval over tracks. A true displacement gives β near 1; a displacement the canopy asks
//!    for only to mend a wrong model predicts nothing about the ground: β near 0. On flat
//!    ground the test has no power and per-shot geolocation is not named.

use std::collections::HashMap;

use rayon::prelude::*;

use super::case::ShotCase;
use super::chain::{pearson, real_products, reposition, simulated_wave_at, value_at, Model};
use super::fit::geolocation;
use super::rank::{interval, Folds};
use crate::gedi::N_ALGORITHMS;
use crate::scenario::effects::GeoLevel;
use crate::waveform::noise_twin::GEDI_BIN_M;

/// Height above ground (m) from which a waveform counts as canopy in the match.
pub const CANOPY_FROM_M: f64 = 3.0;
/// Per-shot geolocation passes when the lower end of β's 95 % interval reaches this: a clear
/// agreement of the ground with the canopy's positions, not a hint.
pub const MIN_BETA_LOWER: f64 = 0.25;
/// Shots a track needs in the test (its changes are centred within it).
pub const MIN_TRACK_SHOTS: usize = 3;
/// Reported ground elevations farther than this (m) from the median are another mode, not a
/// displaced ground (as `super::MISMATCH_MIN_M`).
const OUTLIER_M: f64 = super::MISMATCH_MIN_M;

/// The outcome of the ground test.
#[derive(Debug, Clone, PartialEq)]
pub struct GroundTest {
    /// Shots with a canopy match and a reported ground, on tracks of at least [`MIN_TRACK_SHOTS`].
    pub n_shots: usize,
    /// Of which the canopy asked for another site than their segment's.
    pub n_moved: usize,
    /// RMS (m) of the predicted ground elevation changes: the test's power (0 on flat ground).
    pub rms_predicted_m: f64,
    /// Regression slope of the reported ground change on the predicted one.
    pub beta: f64,
    /// Its 95 % bootstrap interval over tracks.
    pub ci95: [f64; 2],
}

impl GroundTest {
    /// The ground agrees with the canopy's positions ([`MIN_BETA_LOWER`]).
    pub fn passes(&self) -> bool {
        self.ci95[0] >= MIN_BETA_LOWER
    }
}

/// One shot's ground elevation change (m), predicted by its canopy's site and reported by GEDI.
struct Pair {
    track: usize,
    predicted: f64,
    reported: f64,
}

/// The ground test on held-out folds: fold f's shots with `models[f]`, each segment first
/// re-placed as one (the per-track reference).
pub fn ground_test(folds: &Folds, models: &[Model; 2]) -> GroundTest {
    let mut pairs: Vec<Pair> = Vec::new();
    for (f, model) in models.iter().enumerate() {
        let idx: Vec<usize> = (0..folds.cases.len()).filter(|&i| folds.fold[i] == f).collect();
        let cases: Vec<&ShotCase> = idx.iter().map(|&i| folds.cases[i]).collect();
        let placed = reposition(&cases, &model.with(geolocation(GeoLevel::Beam)));
        let found: Vec<Option<Pair>> = idx
            .par_iter()
            .zip(&cases)
            .map(|(&i, c)| {
                let (predicted, reported) = shot_pair(c, &placed)?;
                Some(Pair { track: folds.track[i], predicted, reported })
            })
            .collect();
        pairs.extend(found.into_iter().flatten());
    }
    summarise(pairs, folds)
}

/// β and its interval from the shots' pairs: outliers (another mode) left out, then both changes
/// centred within each track, so that what is constant along a track — a per-track offset the
/// collocation leaves, a beam slanted off nadir that displaces the canopy from the ground by the
/// same amount all along — predicts nothing; tracks of fewer than [`MIN_TRACK_SHOTS`] shots
/// carry no within-track information and are left out.
fn summarise(mut pairs: Vec<Pair>, folds: &Folds) -> GroundTest {
    let mut r: Vec<f64> = pairs.iter().map(|p| p.reported).collect();
    r.sort_by(|a, b| a.total_cmp(b));
    let median = if r.is_empty() { 0.0 } else { r[r.len() / 2] };
    pairs.retain(|p| (p.reported - median).abs() <= OUTLIER_M);
    let mut means: HashMap<usize, [f64; 3]> = HashMap::new();
    for p in &pairs {
        let m = means.entry(p.track).or_default();
        m[0] += p.predicted;
        m[1] += p.reported;
        m[2] += 1.0;
    }
    pairs.retain(|p| means[&p.track][2] >= MIN_TRACK_SHOTS as f64);
    for p in &mut pairs {
        let m = means[&p.track];
        p.predicted -= m[0] / m[2];
        p.reported -= m[1] / m[2];
    }
    let mut per_track: HashMap<usize, [f64; 2]> = HashMap::new();
    for p in &pairs {
        let t = per_track.entry(p.track).or_default();
        t[0] += p.predicted * p.reported;
        t[1] += p.predicted * p.predicted;
    }
    let slope = |tracks: &mut dyn Iterator<Item = usize>| {
        let [xy, xx] = tracks.fold([0.0, 0.0], |[a, b], t| {
            let s = per_track.get(&t).copied().unwrap_or_default();
            [a + s[0], b + s[1]]
        });
        (xx > 1e-12).then(|| xy / xx)
    };
    let beta = slope(&mut (0..folds.n_tracks)).unwrap_or(f64::NAN);
    let resampled: Vec<f64> =
        folds.resamples("ground test").iter().map(|p| slope(&mut p.iter().copied()).unwrap_or(0.0)).collect();
    let n = pairs.len();
    let sum_pp: f64 = pairs.iter().map(|p| p.predicted * p.predicted).sum();
    GroundTest {
        n_shots: n,
        n_moved: pairs.iter().filter(|p| p.predicted.abs() > 1e-9).count(),
        rms_predicted_m: if n > 0 { (sum_pp / n as f64).sqrt() } else { 0.0 },
        beta,
        ci95: if beta.is_finite() { interval(resampled) } else { [f64::NAN, f64::NAN] },
    }
}

/// The ground elevation change (m) the canopy's best site predicts relative to the shot's site
/// under `model`, and the one GEDI reports; `None` for a shot without sites, a usable ground or
/// a canopy to match.
fn shot_pair(case: &ShotCase, model: &Model) -> Option<(f64, f64)> {
    if case.sim.sites.len() < 2 {
        return None;
    }
    let ground = real_ground(case, model)?;
    let base = model.site(case);
    let top = case.real.bin0 - model.vertical_offset_m();
    let scores: Vec<f64> = case
        .sim
        .sites
        .iter()
        .map(|s| {
            if s.variants.is_empty() {
                return f64::NAN;
            }
            let wave = simulated_wave_at(case.sim.dz, s, model, case.real.pulse.as_deref());
            canopy_correlation(&case.real.wave, top, ground, &wave, s.z0, case.sim.dz, s.als_ground)
        })
        .collect();
    let best = (0..scores.len()).filter(|&k| scores[k].is_finite()).max_by(|&a, &b| scores[a].total_cmp(&scores[b]))?;
    let site = &case.sim.sites[best];
    Some((site.als_ground - base.als_ground, ground - base.als_ground))
}

/// GEDI's ground of the shot (m, ALS datum, the model's real-side offsets undone): the selected
/// algorithm's, else the first that passes and is not a ground mismatch.
fn real_ground(case: &ShotCase, model: &Model) -> Option<f64> {
    let usable = |a: u8| !case.mismatch[usize::from(a) - 1];
    std::iter::once(case.real.selected)
        .chain(1..=N_ALGORITHMS as u8)
        .filter(|&a| (1..=N_ALGORITHMS as u8).contains(&a) && usable(a))
        .find_map(|a| real_products(case, model, a))
        .map(|p| p.ground)
}

/// Largest vertical shift (m) tried between the canopy parts of a real and a simulated waveform.
const MAX_LAG_M: f64 = 3.0;

/// Best Pearson r between the canopy parts of a real waveform (`real[k]` at elevation `top − k ·
/// GEDI_BIN_M`, ground at `real_ground`) and a simulated one (`sim[i]` at `z0 − i · dz`, ground at
/// `sim_ground`), each from [`CANOPY_FROM_M`] above its own ground, over vertical shifts of the
/// simulated one within ±[`MAX_LAG_M`] (steps of `dz`). The shift is free so that no elevation enters
/// the match: with the two read by height above their own grounds alone, overlapping sites that
/// differ only in their ground elevation would be told apart by GEDI's ground, and the test would
/// find the ground it was meant to hold out.
fn canopy_correlation(real: &[f32], top: f64, real_ground: f64, sim: &[f64], z0: f64, dz: f64, sim_ground: f64) -> f64 {
    let canopy: Vec<(f64, f64)> = real
        .iter()
        .enumerate()
        .map(|(k, &r)| (top - k as f64 * GEDI_BIN_M - real_ground, f64::from(r)))
        .filter(|(h, _)| *h >= CANOPY_FROM_M)
        .collect();
    let lags = (MAX_LAG_M / dz).round() as i64;
    (-lags..=lags)
        .map(|l| {
            let shift = l as f64 * dz;
            pearson(canopy.iter().map(|&(h, r)| (r, value_at(sim, z0, dz, sim_ground + h + shift))), 3)
        })
        .filter(|r| r.is_finite())
        .fold(f64::NAN, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pairs(f: &dyn Fn(usize) -> (f64, f64)) -> Vec<Pair> {
        (0..200)
            .map(|i| {
                let (predicted, reported) = f(i);
                Pair { track: i % 20, predicted, reported }
            })
            .collect()
    }

    /// Folds of 20 tracks (the test's pairs carry their own track).
    fn test_folds(cases: &[ShotCase]) -> Folds<'_> {
        Folds { n_tracks: 20, ..Folds::new(cases) }
    }

    #[test]
    fn a_ground_that_follows_the_canopy_passes_and_one_that_does_not_fails() {
        let cases = Vec::new();
        let folds = test_folds(&cases);
        // A deterministic scatter standing for L2A's ground noise, ±0.1 m.
        let noise = |i: usize| 0.1 * ((i * 7919 % 200) as f64 / 100.0 - 1.0);
        let slope = |i: usize| 0.2 * ((i * 104_729 % 9) as f64 - 4.0) / 4.0;
        let follows = summarise(pairs(&|i| (slope(i), slope(i) + noise(i) + 0.3)), &folds);
        assert!((follows.beta - 1.0).abs() < 0.1, "{follows:?}");
        assert!(follows.passes(), "{follows:?}");
        // The same predicted changes, the reported ground unrelated to them.
        let unrelated = summarise(pairs(&|i| (slope(i), noise(i) + 0.3)), &folds);
        assert!(unrelated.beta.abs() < 0.3, "{unrelated:?}");
        assert!(!unrelated.passes(), "{unrelated:?}");
        // A per-track constant in both (a slanted beam, what the collocation leaves) is not a
        // per-shot displacement.
        let constant = summarise(
            pairs(&|i| {
                let c = 0.3 * ((i % 20) as f64 - 10.0) / 10.0;
                (c + 0.1 * slope(i), c + noise(i))
            }),
            &folds,
        );
        assert!(!constant.passes(), "{constant:?}");
        // Flat ground: nothing predicted, no power, no pass.
        let flat = summarise(pairs(&|i| (0.0, noise(i))), &folds);
        assert_eq!(flat.rms_predicted_m, 0.0);
        assert!(!flat.passes(), "{flat:?}");
    }

    #[test]
    fn canopy_correlation_matches_shapes_whatever_the_grounds() {
        // The same canopy layer 12 m above two grounds 5 m apart correlates fully; one at 20 m
        // does not; and a ground misplaced by up to the largest shift changes nothing, so the
        // match cannot tell sites apart by their ground elevation.
        let layer = |ground: f64, h: f64, z: f64| (-0.5 * ((z - ground - h) / 1.0).powi(2)).exp();
        let real: Vec<f32> = (0..300).map(|k| layer(100.0, 12.0, 130.0 - k as f64 * GEDI_BIN_M) as f32).collect();
        let dz = 0.15;
        let sim = |h: f64| -> Vec<f64> { (0..400).map(|i| layer(105.0, h, 140.0 - i as f64 * dz)).collect() };
        let same = canopy_correlation(&real, 130.0, 100.0, &sim(12.0), 140.0, dz, 105.0);
        let other = canopy_correlation(&real, 130.0, 100.0, &sim(20.0), 140.0, dz, 105.0);
        assert!(same > 0.99, "{same}");
        assert!(other < 0.2, "{other}");
        let misplaced = canopy_correlation(&real, 130.0, 100.0, &sim(12.0), 140.0, dz, 106.5);
        assert!((misplaced - same).abs() < 1e-3, "{misplaced} vs {same}");
    }
}
