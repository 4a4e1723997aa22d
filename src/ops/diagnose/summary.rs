//! Present: the summary lines of a diagnosis, as the terminal, diagnosis.json and the report show
//! them.

use crate::kernels::diagnose::selftest::{SelfTest, Verdict};
use crate::kernels::diagnose::Diagnosis;
use crate::kernels::scenario::effects::ParamValue;

/// "shrink 62 % (95 % CI 40–80 %)", saying so when the estimate lies outside its interval (as printed): the
/// resampled tracks then add a spread between tracks that the systematic gap of all tracks together does not have
/// (docs/diagnosis.md, "Which effect, and how far").
fn shrink_text(c: &crate::kernels::diagnose::rank::Comparison) -> String {
    let [shrink, lo, hi] = [c.shrink, c.ci95[0], c.ci95[1]].map(|x| (100.0 * x).round());
    let outside = if (lo..=hi).contains(&shrink) || !(lo <= hi) {
        ""
    } else {
        ", the estimate outside its interval: the gap differs between tracks more than within them"
    };
    format!("shrink {shrink:.0} % (95 % CI {lo:.0}–{hi:.0} %{outside})")
}

/// The configuration stage in a few lines: the choice and how far it takes the study's gap, every
/// configuration's gap, the ground bias per algorithm.
fn configuration_lines(c: &crate::kernels::diagnose::configuration::ConfigurationChoice) -> Vec<String> {
    let h = &c.held_out;
    let folds = if c.fold_chosen.iter().all(|k| *k == c.chosen) {
        String::new()
    } else {
        format!(" (the calibration folds chose {} and {})", c.fold_chosen[0].label(), c.fold_chosen[1].label())
    };
    let rows: Vec<String> = c
        .trials
        .iter()
        .map(|t| {
            format!(
                "{} {:.2} m, MSD {:.2} m², RH98 {:+.2} m",
                t.config.label(),
                t.metrics.mean_abs_bias,
                t.metrics.msd,
                t.metrics.bias_rh[97]
            )
        })
        .collect();
    let grounds: Vec<String> = c
        .ground
        .iter()
        .filter(|g| g.n > 0)
        .map(|g| format!("a{} {:+.2} m ({:+.2} to {:+.2})", g.algorithm, g.bias_m, g.ci95[0], g.ci95[1]))
        .collect();
    let shift = c
        .vertical_shift_m
        .map(|dz| format!(" and the real waveforms' best vertical shift, {dz:+.2} m"))
        .unwrap_or_default();
    let mut lines = vec![
        format!(
            "Configuration first (weighting × pulse chosen on calibration tracks by the waveforms at the best \
             ground/vegetation ratio{shift}, then equal or the reference's reflectances, scored on held-out ones): \
             {}{folds}; from the study's count + Gaussian 15 ns the held-out gap goes {:.2} → {:.2} m at ρg/ρv = \
             {:.2} ({}). A configuration is never reported as an effect: the causes below, a ratio ρ among them \
             (relative to these reflectances), are ranked on top of it.",
            c.chosen.label(),
            h.before.mean_abs_bias,
            h.after.mean_abs_bias,
            c.chosen.reflectance.rho_ground_over_veg(),
            shrink_text(h)
        ),
        format!("  every configuration (mean |RH bias| RH1–RH99, MSD, RH98 bias): {}.", rows.join("; ")),
    ];
    if let Some(best) = c.least_biased_algorithm() {
        lines.push(format!(
            "  ground bias (GEDI − ALS, 95 % CI) per L2A algorithm: {}; least biased: a{}.",
            grounds.join(", "),
            best.algorithm
        ));
    }
    lines
}

/// "its ground test failed: β 0.05 (95 % CI −0.3 to 0.4) …" (docs/diagnosis.md, "Geolocation").
fn ground_test_text(g: &crate::kernels::diagnose::geolocation::GroundTest) -> String {
    format!(
        "its ground test failed: the ground elevations GEDI reports follow the positions the canopy asks for with \
         slope β {:.2} (95 % CI {:.2} to {:.2}, needs ≥ {}; {} shots, predicted changes {:.2} m RMS), so the \
         re-placement mends the model rather than the positions",
        g.beta,
        g.ci95[0],
        g.ci95[1],
        crate::kernels::diagnose::geolocation::MIN_BETA_LOWER,
        g.n_shots,
        g.rms_predicted_m
    )
}

/// An effect's parameters as `name = value, …` (numbers to 3 decimals), in its own order.
pub fn params_text(e: &crate::kernels::scenario::effects::Effect) -> String {
    let p: Vec<(String, ParamValue)> = e.params().into_iter().map(|(k, v)| (k.to_string(), v)).collect();
    crate::kernels::diagnose::json::params_text(&p)
}

/// The self-test in one line: what the twins of each planting were named first, and the named
/// effect's recovery.
fn self_test_line(t: &SelfTest, verdict: &Verdict) -> String {
    let outcome = |n: &Option<String>| n.clone().unwrap_or_else(|| "nothing".into());
    let plantings: Vec<String> = t
        .plantings
        .iter()
        .map(|p| {
            let what: Vec<String> = p.outcomes().iter().map(|(n, k)| format!("{} {k}", outcome(n))).collect();
            let planted = match &p.effect {
                Some(e) => format!("{} planted ({})", e.name(), params_text(e)),
                None => "nothing planted".into(),
            };
            format!("{planted} → named first: {}", what.join(", "))
        })
        .collect();
    let head = match t.subject(verdict) {
        Some(e) => match (t.planting(Some(e)), t.planting(None)) {
            (Some(p), Some(none)) => format!(
                "on data like yours, {e} was named first in {} of {} twins where it was planted and in {} of {} \
                 where nothing was",
                p.count(Some(e)),
                p.named.len(),
                none.count(Some(e)),
                none.named.len()
            ),
            _ => String::new(),
        },
        None => String::new(),
    };
    format!(
        "Self-test ({} twin sets of these shots per hypothesis, made from {} and ranked the same way): {head}. {}.",
        t.twins,
        t.configuration.label(),
        plantings.join("; ")
    )
}

/// The diagnosis in a few lines a scientist can read.
pub fn summary_lines(d: &Diagnosis) -> Vec<String> {
    let mut lines = Vec::new();
    let w = &d.where_;
    let ranked = if d.n_shots < d.n_located {
        format!(
            " The configuration, the effects and the self-test use the {} shots of {} tracks drawn at random \
             (--ranked-shots); where the gap lies uses them all.",
            d.n_shots, d.n_tracks
        )
    } else {
        String::new()
    };
    lines.push(format!(
        "{} shots on {} tracks.{ranked} Signs: RH bias = simulated − GEDI RH; ground bias = GEDI ground − ALS \
         ground (positive: GEDI's ground is higher; GEDI's brought into the ALS datum through the geoid).",
        d.n_located, d.n_located_tracks
    ));
    lines.push(format!(
        "Baseline (the study's simulation — noise-free, 15 ns Gaussian pulse, at the collocated position — against \
         each shot's L2A selected algorithm, before the study's filters): mean |RH bias| over RH1–RH99 {:.2} m, \
         ground bias {:+.2} m.",
        w.overall.mean_abs_bias_rh, w.overall.ground_bias
    ));
    let (k, b) = w
        .overall
        .bias_rh
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
        .map_or((0, 0.0), |(k, b)| (k + 1, *b));
    let mut place = format!("Where: the largest RH bias is at RH{k} ({b:+.2} m)");
    // Among strata of kinds with at least two labels: the one holding most of the squared error
    // relative to its share of the shots.
    let labels = |kind: &str| w.strata.iter().filter(|s| s.kind == kind).count();
    let worst = w.strata.iter().filter(|s| labels(&s.kind) >= 2 && s.n_shots >= 5).max_by(|a, b| {
        (a.share_of_squared_error / a.n_shots as f64).total_cmp(&(b.share_of_squared_error / b.n_shots as f64))
    });
    if let Some(s) = worst {
        place += &format!(
            "; {} = {} holds {:.0} % of the squared error with {:.0} % of the shots",
            s.kind,
            s.label,
            100.0 * s.share_of_squared_error,
            100.0 * s.n_shots as f64 / d.n_shots.max(1) as f64
        );
    }
    lines.push(place + ".");
    lines.extend(configuration_lines(&d.configuration));
    lines.push(
        "Held-out gap, what the causes below are judged by (not comparable with the baseline): mean |RH bias| over \
         RH1–RH99 of the full chain (noise twin, L2A a1–a6) on tracks left out of each fit, each effect where it \
         acts: a datum above the ALS ground (ALS frame), a ground detection and the noise above GEDI's own ground \
         (RH frame), the others in both."
            .into(),
    );
    // What a trial changed, in the unit it is judged in.
    let gap = |t: &crate::kernels::diagnose::rank::Trial| match &t.held_out.spread {
        Some(s) => format!("held-out MSD above the noise floor {:.2} → {:.2} m²", s.excess()[0], s.excess()[1]),
        None => {
            format!("held-out gap {:.2} → {:.2} m", t.held_out.before.mean_abs_bias, t.held_out.after.mean_abs_bias)
        }
    };
    let verdict = &d.verdict;
    if d.ranking.unexplained {
        let best = d.ranking.effects.first();
        lines.push(match best {
            Some(t) => format!(
                "Which: unexplained — the best candidate, {} ({}), {}, is not enough to name it{}.",
                t.effect.name(),
                gap(t),
                shrink_text(&t.held_out),
                match &t.ground_test {
                    Some(g) if !g.passes() => format!(" ({})", ground_test_text(g)),
                    Some(_) => format!(
                        " (or its per-shot offsets are under {} m)",
                        crate::kernels::diagnose::rank::MIN_SHOT_SIGMA_M
                    ),
                    None => String::new(),
                }
            ),
            None => "Which: unexplained — no effect could be fitted.".into(),
        });
    } else if *verdict == Verdict::Unexplained {
        let t = &d.ranking.effects[0];
        let (k, n) = d
            .self_test
            .as_ref()
            .and_then(|s| s.planting(None))
            .map_or((0, 0), |p| (p.count(Some(t.effect.name())), p.named.len()));
        lines.push(format!(
            "Which: unexplained — {} ({}, {}) clears the intervals, but twins of these shots without any effect \
             name it first in {k} of {n}: on data like these it is what the chain finds when nothing is there.",
            t.effect.name(),
            gap(t),
            shrink_text(&t.held_out)
        ));
    } else {
        for (i, t) in d.ranking.ladder.iter().enumerate() {
            let params = params_text(&t.effect);
            let gap = gap(t);
            let caveat = match (t.at_bound(), t.equivalent()) {
                (_, Some(e)) => format!(" — equivalent to the simpler {}", e.name()),
                (Some(b), None) => format!(" — fit on the edge of its range ({b}): the effect may not be this one"),
                (None, None) => String::new(),
            };
            lines.push(format!(
                "{} {} ({params}): {gap}, {}{caveat}.",
                if i == 0 { "Which:" } else { "  then" },
                t.effect.name(),
                shrink_text(&t.held_out)
            ));
            match (verdict, &d.self_test) {
                (Verdict::Ambiguous(v), Some(test)) if i == 0 => {
                    let taken: Vec<String> = v[1..]
                        .iter()
                        .filter_map(|m| test.planting(Some(m)))
                        .map(|p| {
                            format!(
                                "{} planted is named {} in {} of {}",
                                p.label(),
                                v[0],
                                p.count(Some(&v[0])),
                                p.named.len()
                            )
                        })
                        .collect();
                    lines.push(format!("  ambiguous: in twins of these shots, {}.", taken.join("; ")));
                }
                (Verdict::Ambiguous(v), None) if i == 0 => lines.push(format!(
                    "  ambiguous: {} explain(s) the gap as well within noise (paired 95 % interval of the shrink \
                     difference contains 0).",
                    v[1..].join(", ")
                )),
                _ => {}
            }
        }
    }
    lines.extend(d.self_test.as_ref().map(|t| self_test_line(t, verdict)));
    lines
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_shrink_outside_its_interval_is_said_so() {
        let c = |shrink: f64, ci95: [f64; 2]| crate::kernels::diagnose::rank::Comparison {
            frame: crate::kernels::diagnose::gap::Frame::Both,
            before: Default::default(),
            after: Default::default(),
            shrink,
            ci95,
            gain_ci95: [0.0, 0.0],
            shrink_mean_abs_bias: 0.0,
            profile_chi2: [0.0, 0.0],
            spread: None,
        };
        assert_eq!(shrink_text(&c(0.62, [0.40, 0.80])), "shrink 62 % (95 % CI 40–80 %)");
        // As printed: 96.4 % with an interval ending at 96.3 % reads 96 within 42–96.
        assert_eq!(shrink_text(&c(0.964, [0.42, 0.963])), "shrink 96 % (95 % CI 42–96 %)");
        let outside = shrink_text(&c(0.97, [0.42, 0.96]));
        assert!(outside.starts_with("shrink 97 % (95 % CI 42–96 %, the estimate outside its interval"), "{outside}");
    }
}
