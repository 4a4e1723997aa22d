//! Evaluating a hypothesis on a set of shots, and fitting each effect's parameters to a
//! calibration set: closed forms where the effect has one (datum, ground detection, noise); for
//! the effects that reshape the waveform (weighting, pulse, footprint, canopy_change, occlusion)
//! a coarse grid refined by golden-section search minimising the waveform-level gap
//! ([`profile::ProfileSums::chi2_against`]), which sees the shape of the waveform that RH percentiles blur.

use rayon::prelude::*;

use super::case::{ShotCase, FSIGMA_GRID};
use super::chain::{null_cases, predict, real_products, reposition, Model, Scratch};
use super::gap::GapSums;
use super::profile::{self, ShotProfile};
use crate::gedi::N_ALGORITHMS;
use crate::scenario::effects::{Effect, EffectKind, GeoLevel, WeightMethod};

/// The effects the diagnosis fits: every effect of the registry, in its order.
pub const FITTED_EFFECTS: [EffectKind; 9] = EffectKind::ALL;

/// The `geolocation` hypotheses: every segment re-placed as one (`beam`: the reference a per-shot
/// error is judged against, since the per-track collocation leaves an error of its own) and every
/// shot on its own (`shot`).
pub fn geolocation(level: GeoLevel) -> Effect {
    Effect::Geolocation { level, shot_sigma_m: 0.0 }
}

/// The gap of one shot under a model, and its ground differences per algorithm.
#[derive(Debug, Clone, Default)]
pub struct ShotGap {
    pub sums: GapSums,
    /// ground_real − ground_sim of a1..a6 (m), where both exist.
    pub ground: [Option<f64>; N_ALGORITHMS],
    /// The shot's waveform-level difference (real − simulated).
    pub profile: Option<ShotProfile>,
}

/// Evaluate `model` on every case (in parallel), in case order.
pub fn evaluate(cases: &[&ShotCase], model: &Model) -> Vec<ShotGap> {
    cases
        .par_iter()
        .map_init(Scratch::new, |scratch, case| {
            let pred = predict(case, model, scratch);
            let mut out = ShotGap { profile: profile::shot_profile(case, model), ..Default::default() };
            out.sums.n_shots = 1.0;
            for a in 1..=N_ALGORITHMS as u8 {
                if case.mismatch[usize::from(a) - 1] {
                    continue;
                }
                if let (Some(r), Some(p)) = (real_products(case, model, a), &pred[usize::from(a) - 1]) {
                    out.sums.add(&r.rh, r.ground, &p.rh, p.ground);
                    out.ground[usize::from(a) - 1] = Some(r.ground - p.ground);
                }
            }
            out
        })
        .collect()
}

/// Sum of the shots' gaps.
pub fn total(gaps: &[ShotGap]) -> GapSums {
    let mut s = GapSums::default();
    gaps.iter().for_each(|g| s.merge(&g.sums));
    s
}

/// Mean of the central 80 % (robust to mis-detected grounds, and unlike the median not stuck on
/// the 0.15 m lattice of L2A ground positions).
fn trimmed_mean(mut v: Vec<f64>) -> Option<f64> {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return None;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let cut = v.len() / 10;
    let kept = &v[cut..v.len() - cut];
    Some(kept.iter().sum::<f64>() / kept.len() as f64)
}

fn median(mut v: Vec<f64>) -> Option<f64> {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return None;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    Some(if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) })
}

/// Minimise `f` over a sorted `grid`, then refine by golden-section search between the best grid
/// point's neighbours. Returns (argmin, min).
pub fn minimise(f: &mut dyn FnMut(f64) -> f64, grid: &[f64], iterations: usize) -> (f64, f64) {
    let values: Vec<f64> = grid.iter().map(|&x| f(x)).collect();
    let (i, _) =
        values.iter().enumerate().fold((0, f64::INFINITY), |(bi, bv), (i, &v)| if v < bv { (i, v) } else { (bi, bv) });
    let (mut best_x, mut best_v) = (grid[i], values[i]);
    let (mut a, mut b) = (grid[i.saturating_sub(1)], grid[(i + 1).min(grid.len() - 1)]);
    let phi = (5f64.sqrt() - 1.0) / 2.0;
    let mut c = b - phi * (b - a);
    let mut d = a + phi * (b - a);
    let (mut fc, mut fd) = (f(c), f(d));
    for _ in 0..iterations {
        if fc < fd {
            b = d;
            d = c;
            fd = fc;
            c = b - phi * (b - a);
            fc = f(c);
        } else {
            a = c;
            c = d;
            fc = fd;
            d = a + phi * (b - a);
            fd = f(d);
        }
    }
    for (x, v) in [(c, fc), (d, fd)] {
        if v < best_v {
            (best_x, best_v) = (x, v);
        }
    }
    (best_x, best_v)
}

/// Re-placements of the shots alternated with re-fits of a reshaping effect.
const REPLACEMENTS: usize = 2;

/// Fit the effect `kind` on top of `base` to `cases`, with the shots of short segments re-placed
/// for each hypothesis ([`reposition`]): first for `base` (`placed`, which is `reposition(cases,
/// base)`: every effect tried on one base shares it), then — for an effect that reshapes the
/// waveform ([`EffectKind::reshapes_waveform`]) — alternately re-placed for the fitted model and
/// re-fitted (positions and parameters are fitted jointly). `None` when the cases carry no
/// information about the effect (e.g. no ground differences).
pub fn fit(kind: EffectKind, base: &Model, placed: &Model, cases: &[&ShotCase]) -> Option<Effect> {
    if cases.is_empty() {
        return None;
    }
    if kind == EffectKind::Geolocation {
        return fit_geolocation(base, cases);
    }
    let mut effect = fit_placed(kind, placed, cases)?;
    if kind.reshapes_waveform() {
        let mut current = placed.clone();
        for _ in 0..REPLACEMENTS {
            let next = reposition(cases, &current.with(effect.clone()));
            if next.placement == current.placement {
                break;
            }
            current = placed.placed_as(&next);
            effect = fit_placed(kind, &current, cases)?;
        }
    }
    Some(effect)
}

/// Fit `geolocation` on top of `base`: the RMS per axis of the shots' own re-placements away from
/// their segment's (`level` shot against `beam`), with the same RMS of the noise-twin nulls (a
/// shot whose segment position is exact still moves, to fit its noise) removed in quadrature.
/// `None` without shots that can move.
fn fit_geolocation(base: &Model, cases: &[&ShotCase]) -> Option<Effect> {
    let beam = base.with(geolocation(GeoLevel::Beam));
    let shot = base.with(geolocation(GeoLevel::Shot));
    let placed = reposition(cases, &beam);
    let real = mean_square_move(cases, &placed, &reposition(cases, &shot))?;
    let nulls = null_cases(cases, &placed);
    let refs: Vec<&ShotCase> = nulls.iter().map(|(_, c)| c).collect();
    let floor = mean_square_move(&refs, &reposition(&refs, &beam), &reposition(&refs, &shot)).unwrap_or(0.0);
    Some(Effect::Geolocation { level: GeoLevel::Shot, shot_sigma_m: (real - floor).max(0.0).sqrt() })
}

/// Mean over the shots that have sites of ½|site offset under `to` − under `from`|² (m², per
/// axis); `None` without such shots.
fn mean_square_move(cases: &[&ShotCase], from: &Model, to: &Model) -> Option<f64> {
    let d: Vec<f64> = cases
        .iter()
        .filter(|c| c.sim.sites.len() > 1)
        .map(|c| {
            let (p, q) = (from.site(c).offset, to.site(c).offset);
            0.5 * ((q.0 - p.0).powi(2) + (q.1 - p.1).powi(2))
        })
        .collect();
    (!d.is_empty()).then(|| d.iter().sum::<f64>() / d.len() as f64)
}

/// Fit the effect `kind` on top of `base` (positions as `base` places them) to `cases`.
fn fit_placed(kind: EffectKind, base: &Model, cases: &[&ShotCase]) -> Option<Effect> {
    // Every parameter value weighed against the base model's between-shot variance (computed
    // once, and only for the effects fitted on the waveforms).
    let reference = std::cell::OnceCell::new();
    let prepared = profile::AfterPulse::new(cases, base);
    let obj = |e: Effect| prepared.sums(&e).chi2_against(reference.get_or_init(|| profile::sums(cases, base)));
    match kind {
        // Fitted from the re-placements themselves (`fit_geolocation`), not at fixed positions.
        EffectKind::Geolocation => None,
        EffectKind::Datum => {
            // The collocation's vertical offsets come from whole waveforms, so a GEDI ground
            // found elsewhere than the ALS one does not bias them: preferred when present.
            let dz: Vec<f64> = cases.iter().filter_map(|c| c.real.collocation_dz).collect();
            if dz.len() >= 5 {
                return Some(Effect::Datum { dz_m: median(dz)? });
            }
            let gaps = evaluate(cases, base);
            let all: Vec<f64> = gaps.iter().flat_map(|g| g.ground.iter().flatten().copied()).collect();
            Some(Effect::Datum { dz_m: trimmed_mean(all)? })
        }
        EffectKind::GroundDetection => {
            let gaps = evaluate(cases, base);
            let per: Vec<Option<f64>> = (0..N_ALGORITHMS)
                .map(|a| {
                    let v: Vec<f64> = gaps.iter().filter_map(|g| g.ground[a]).collect();
                    if v.len() >= 5 {
                        trimmed_mean(v)
                    } else {
                        None
                    }
                })
                .collect();
            let pooled = trimmed_mean(gaps.iter().flat_map(|g| g.ground.iter().flatten().copied()).collect())?;
            // One algorithm stands out from the others ⇒ that algorithm; else all of them.
            let (alg, off) = per
                .iter()
                .enumerate()
                .filter_map(|(a, o)| o.map(|o| (a as u8 + 1, o)))
                .max_by(|x, y| (x.1 - pooled).abs().total_cmp(&(y.1 - pooled).abs()))?;
            let others =
                median(per.iter().enumerate().filter(|(a, _)| *a as u8 + 1 != alg).filter_map(|(_, o)| *o).collect());
            let stands_out = others.is_some_and(|m| (off - m).abs() > 0.15_f64.max(0.5 * m.abs()));
            Some(if stands_out {
                Effect::GroundDetection { algorithm: alg, offset_m: off - others.unwrap_or(0.0) }
            } else {
                Effect::GroundDetection { algorithm: 0, offset_m: pooled }
            })
        }
        EffectKind::Noise => {
            let ratios: Vec<f64> = cases.iter().map(|c| c.real.noise.stddev / c.real.nominal_noise_stddev).collect();
            Some(Effect::Noise { noise_sigma_factor: median(ratios)? })
        }
        EffectKind::Pulse => {
            let (x, _) = minimise(&mut |s| obj(Effect::Pulse { pulse_sigma_m: s }), &PULSE_GRID, 8);
            Some(Effect::Pulse { pulse_sigma_m: x })
        }
        EffectKind::Footprint => {
            let (x, _) = minimise(&mut |s| obj(Effect::Footprint { fsigma_m: s }), &FSIGMA_GRID, 8);
            Some(Effect::Footprint { fsigma_m: x })
        }
        EffectKind::Weighting => {
            // ρ on the configuration's own weighting: a change of method is a configuration
            // (`super::configuration`), chosen before any effect, never an effect.
            let grid: Vec<f64> = RHO_GRID.iter().map(|r: &f64| r.ln()).collect();
            let method = WeightMethod::Ratio;
            let (x, _) = minimise(&mut |lr| obj(Effect::Weighting { method, rho_ground_over_veg: lr.exp() }), &grid, 8);
            Some(Effect::Weighting { method, rho_ground_over_veg: x.exp() })
        }
        EffectKind::CanopyChange => two_parameter(&CANOPY_HEIGHTS, &CANOPY_FRACTIONS, &|h, f| {
            obj(Effect::CanopyChange { height_m: h, fraction: f })
        })
        .map(|(h, f)| Effect::CanopyChange { height_m: h, fraction: f }),
        EffectKind::Occlusion => {
            two_parameter(&OCCLUSION_HEIGHTS, &OCCLUSION_GAINS, &|h, g| obj(Effect::Occlusion { height_m: h, gain: g }))
                .map(|(h, g)| Effect::Occlusion { height_m: h, gain: g })
        }
    }
}

/// σ (m) of a response beyond the transmit pulse: 0 (none) is its lower bound.
pub const PULSE_GRID: [f64; 10] = [0.0, 0.3, 0.6, 0.9, 1.2, 1.6, 2.0, 2.5, 3.1, 3.8];
/// ρ_ground/ρ_veg, both directions of 1.
pub const RHO_GRID: [f64; 10] = [0.25, 0.4, 0.6, 0.8, 1.0, 1.25, 1.6, 2.2, 3.0, 4.0];
/// Canopy change: heights (m) and fractions (loss > 0, gain < 0).
pub const CANOPY_HEIGHTS: [f64; 11] = [2.0, 3.0, 4.0, 6.0, 8.0, 10.0, 12.0, 15.0, 18.0, 22.0, 27.0];
pub const CANOPY_FRACTIONS: [f64; 8] = [-0.9, -0.4, -0.1, 0.1, 0.3, 0.5, 0.7, 0.9];
/// Occlusion: band tops (m) and gains (more understorey > 0, less < 0).
pub const OCCLUSION_HEIGHTS: [f64; 10] = [1.5, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 13.0, 16.0];
pub const OCCLUSION_GAINS: [f64; 8] = [-0.8, -0.4, 0.0, 0.3, 0.6, 1.0, 1.6, 2.5];

/// The parameter of a fitted effect that sits on a bound of its search range (within 2 % of the
/// range), as `name = value (lower|upper bound)`: the fit wanted to go further, so the effect
/// does not describe the gap with a value it can take (docs/diagnosis.md, identifiability).
pub fn at_bound(e: &Effect) -> Option<String> {
    let check = |name: &str, v: f64, grid: &[f64]| -> Option<String> {
        let (lo, hi) = (grid[0], grid[grid.len() - 1]);
        let tol = 0.02 * (hi - lo);
        if v <= lo + tol {
            Some(format!("{name} = {v:.3} (lower bound)"))
        } else if v >= hi - tol {
            Some(format!("{name} = {v:.3} (upper bound)"))
        } else {
            None
        }
    };
    let ln = |g: &[f64]| g.iter().map(|v: &f64| v.ln()).collect::<Vec<f64>>();
    match *e {
        Effect::Pulse { pulse_sigma_m } => check("pulse_sigma_m", pulse_sigma_m, &PULSE_GRID),
        Effect::Footprint { fsigma_m } => check("fsigma_m", fsigma_m, &FSIGMA_GRID),
        Effect::Weighting { rho_ground_over_veg, .. } => {
            check("rho_ground_over_veg", rho_ground_over_veg.ln(), &ln(&RHO_GRID))
                .map(|_| format!("rho_ground_over_veg = {rho_ground_over_veg:.3} (bound)"))
        }
        Effect::CanopyChange { height_m, fraction } => {
            check("height_m", height_m, &CANOPY_HEIGHTS).or_else(|| check("fraction", fraction, &CANOPY_FRACTIONS))
        }
        Effect::Occlusion { height_m, gain } => {
            check("height_m", height_m, &OCCLUSION_HEIGHTS).or_else(|| check("gain", gain, &OCCLUSION_GAINS))
        }
        _ => None,
    }
}

/// The simpler effect a fitted effect is equivalent to: a canopy change from the lowest height of
/// its range scales (nearly) all canopy energy by 1 − fraction, and so does an occlusion up to
/// the top of its range by 1 + gain — which is `weighting` with ρ_ground/ρ_veg = 1/that factor.
pub fn simpler_equivalent(e: &Effect) -> Option<Effect> {
    let whole = |factor: f64| {
        (factor > 0.0).then(|| Effect::Weighting { method: WeightMethod::Ratio, rho_ground_over_veg: 1.0 / factor })
    };
    match *e {
        Effect::CanopyChange { height_m, fraction } if height_m <= CANOPY_HEIGHTS[0] + 0.5 => whole(1.0 - fraction),
        Effect::Occlusion { height_m, gain } if height_m >= OCCLUSION_HEIGHTS[OCCLUSION_HEIGHTS.len() - 1] - 0.5 => {
            whole(1.0 + gain)
        }
        _ => None,
    }
}

/// Minimise a two-parameter objective: for each height of `heights`, the best strength (grid +
/// golden section); then the height refined between its neighbours with the strength re-fitted.
fn two_parameter(heights: &[f64], strengths: &[f64], f: &dyn Fn(f64, f64) -> f64) -> Option<(f64, f64)> {
    let best_strength = |h: f64| minimise(&mut |s| f(h, s), strengths, 5);
    let per: Vec<(f64, f64, f64)> = heights
        .iter()
        .map(|&h| {
            let (s, v) = best_strength(h);
            (h, s, v)
        })
        .collect();
    let i = per.iter().enumerate().min_by(|a, b| a.1 .2.total_cmp(&b.1 .2))?.0;
    let mut best = per[i];
    let (lo, hi) = (heights[i.saturating_sub(1)], heights[(i + 1).min(heights.len() - 1)]);
    let mut strength_at = std::collections::HashMap::new();
    let (h, v) = minimise(
        &mut |h| {
            let (s, v) = best_strength(h);
            strength_at.insert(h.to_bits(), s);
            v
        },
        &[lo, best.0, hi],
        3,
    );
    if v < best.2 {
        best = (h, strength_at.get(&h.to_bits()).copied().unwrap_or(best.1), v);
    }
    Some((best.0, best.1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounds_and_equivalences_are_recognised() {
        assert!(at_bound(&Effect::Footprint { fsigma_m: 3.5 }).unwrap().contains("lower bound"));
        assert!(at_bound(&Effect::Footprint { fsigma_m: 10.0 }).unwrap().contains("upper bound"));
        assert_eq!(at_bound(&Effect::Footprint { fsigma_m: 4.2 }), None);
        assert!(at_bound(&Effect::Pulse { pulse_sigma_m: 0.0 }).is_some());
        let w = |rho| Effect::Weighting { method: WeightMethod::Int, rho_ground_over_veg: rho };
        assert!(at_bound(&w(4.0)).is_some() && at_bound(&w(0.25)).is_some() && at_bound(&w(1.3)).is_none());
        assert_eq!(at_bound(&Effect::Datum { dz_m: 100.0 }), None);
        let gain = simpler_equivalent(&Effect::CanopyChange { height_m: 2.0, fraction: -0.25 }).unwrap();
        assert_eq!(gain, Effect::Weighting { method: WeightMethod::Ratio, rho_ground_over_veg: 0.8 });
        assert!(simpler_equivalent(&Effect::Occlusion { height_m: 16.0, gain: 0.25 }).is_some());
        assert_eq!(simpler_equivalent(&Effect::Occlusion { height_m: 5.0, gain: 0.25 }), None);
    }

    #[test]
    fn minimise_finds_a_parabola_minimum_between_grid_points() {
        let (x, v) = minimise(&mut |x| (x - 1.37).powi(2) + 2.0, &[0.0, 0.5, 1.0, 1.5, 2.0, 3.0], 20);
        assert!((x - 1.37).abs() < 1e-3, "{x}");
        assert!((v - 2.0).abs() < 1e-6);
    }

    #[test]
    fn two_parameter_search_finds_both() {
        let (h, s) = two_parameter(&[2.0, 4.0, 8.0, 16.0], &[-1.0, 0.0, 0.5, 1.0], &|h, s| {
            (h - 6.0).powi(2) * 0.01 + (s - 0.3).powi(2)
        })
        .unwrap();
        assert!((h - 6.0).abs() < 0.3, "{h}");
        assert!((s - 0.3).abs() < 0.05, "{s}");
    }
}
