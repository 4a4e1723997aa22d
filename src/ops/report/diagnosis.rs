//! The diagnosis in `report.html` (`gedisim report --diagnosis <dir>`, and `gedisim demo`): the
//! verdict as `gedisim diagnose` printed it, the effects tried and the ladder, and the before/after
//! figures, read from a `gedisim diagnose --out <dir>` folder (docs/diagnosis.md).

use std::fmt::Write;
use std::path::Path;

use super::html::{base64, escape};
use crate::error::{Error, Result};
use crate::kernels::diagnose::json::{params_text, ConfigurationJson, DiagnosisJson, SelfTestJson, TrialJson};
use crate::kernels::scenario::effects::ParamValue;

/// The figures of a diagnosis shown in the page, with their captions.
const FIGURES: [(&str, &str); 2] = [
    (
        "bias_profile_before_after",
        "Held-out RH bias (simulated − GEDI) per percentile: the study's baseline, the chosen configuration and \
         each step of the ladder, above each side's own ground and above the ALS ground.",
    ),
    (
        "waveform_residual",
        "Mean normalised real and simulated waveforms by height above the ALS ground, and their difference \
         (simulated − real).",
    ),
];

/// The section's HTML, from the diagnosis folder `dir` of the dataset at `dataset`.
pub fn section(dir: &Path, dataset: &Path) -> Result<String> {
    let path = dir.join("diagnosis.json");
    let text = std::fs::read_to_string(&path).map_err(|e| Error::file(&path, format!("cannot read: {e}")))?;
    let d: DiagnosisJson = serde_json::from_str(&text)
        .map_err(|e| Error::file(&path, format!("not a diagnosis.json of this gedisim version: {e}")))?;
    let here = dataset.canonicalize().unwrap_or_else(|_| dataset.to_path_buf()).display().to_string();
    if let Some(other) = d.dataset.as_ref().filter(|d| **d != here) {
        return Err(Error::field(&path, "dataset", format!("a diagnosis of {other}, not of this dataset ({here})")));
    }
    let mut s = String::from("<h2 id=\"diagnosis\">Diagnosis</h2>\n");
    let _ = writeln!(
        s,
        "<p class=\"note\">From <code>{}</code> (<code>gedisim diagnose</code>: which unmodelled effect explains \
         the gap, judged on held-out tracks). Signs: RH bias = {}; ground bias = {}.</p>",
        escape(&dir.display().to_string()),
        escape(&d.signs.rh_bias),
        escape(&d.signs.ground_bias)
    );
    let v = &d.verdict;
    let verdict = match v.kind.as_str() {
        "unexplained" if v.ranking_names.is_some() => format!(
            "unexplained: {} clears the intervals, but the self-test names it as often without any effect",
            v.ranking_names.as_deref().unwrap_or_default()
        ),
        "unexplained" => "unexplained: no effect shrinks the held-out gap enough to be named".to_string(),
        "ambiguous" => format!("ambiguous between {}", v.effects.join(" and ")),
        _ => {
            let names: Vec<&str> = d.ladder.iter().map(|t| t.name.as_str()).collect();
            format!("explained by {}", names.join(" + "))
        }
    };
    let _ = writeln!(s, "<p><strong>Verdict: {}.</strong></p>", escape(&verdict));
    if !d.summary.is_empty() {
        s.push_str("<ul>\n");
        for line in &d.summary {
            let _ = writeln!(s, "<li>{}</li>", escape(line.trim()));
        }
        s.push_str("</ul>\n");
    }
    s.push_str(&configuration_tables(&d.configuration));
    if let Some(t) = &d.self_test {
        s.push_str(&self_test_table(t));
    }
    for (title, trials) in
        [("Ladder (effects added in order)", &d.ladder), ("Every effect tried, best first", &d.effects)]
    {
        if trials.is_empty() {
            continue;
        }
        let _ = writeln!(s, "<h3>{}</h3>", escape(title));
        s.push_str(&trial_table(trials));
    }
    for (name, caption) in FIGURES {
        let png = dir.join(format!("{name}.png"));
        let bytes = std::fs::read(&png).map_err(|e| Error::file(&png, format!("cannot read: {e}")))?;
        let _ = writeln!(
            s,
            "<figure><img alt=\"{}\" src=\"data:image/png;base64,{}\">\n<figcaption>{}</figcaption></figure>",
            escape(name),
            base64(&bytes),
            escape(caption)
        );
    }
    Ok(s)
}

/// The self-test: per planted hypothesis, what its twins were named first.
fn self_test_table(t: &SelfTestJson) -> String {
    let mut s = format!(
        "<h3>Self-test</h3>\n<p>{} twin sets of these shots per hypothesis, made from {} with each leading candidate \
         planted at its fitted magnitude (and with nothing), ranked the same way. The verdict is unexplained when \
         twins without any effect name the first effect in ≥ {:.0} % of them, ambiguous when twins with another \
         candidate planted do.</p>\n<table>\n<thead><tr><th>planted</th><th>parameters</th>\
         <th>named first (twin sets)</th></tr></thead>\n<tbody>\n",
        t.twins,
        escape(&t.configuration),
        100.0 * t.max_false_rate
    );
    for p in &t.plantings {
        let params: Vec<(&String, ParamValue)> = p.params.iter().flatten().map(|(k, v)| (k, v.clone())).collect();
        let named: Vec<String> = p.named_first.iter().map(|o| format!("{} {}", o.name, o.twins)).collect();
        let _ = writeln!(
            s,
            "<tr><td>{}</td><td>{}</td><td>{}</td></tr>",
            escape(&p.planted),
            escape(&params_text(&params)),
            escape(&named.join(", "))
        );
    }
    s.push_str("</tbody>\n</table>\n");
    s
}

/// The configuration stage: every configuration's gap (the chosen one marked), and the ground
/// bias per L2A algorithm under it.
fn configuration_tables(c: &ConfigurationJson) -> String {
    let num = |v: Option<f64>| v.map_or("–".to_string(), |x| format!("{x:.2}"));
    let signed = |v: Option<f64>| v.map_or("–".to_string(), |x| format!("{x:+.2}"));
    let mut s = format!(
        "<h3>Configuration (weighting × pulse × reflectances)</h3>\n<p>Chosen: <strong>{}</strong>, on calibration \
         tracks by the waveforms at each one's best ground/vegetation ratio ρ, then equal reflectances or the \
         reference simulator's (ρg/ρv 0.40/0.57) by the waveforms; effects (a ratio ρ among them, relative to the \
         chosen reflectances) are ranked on top of it.</p>\n<table>\n<thead><tr><th>configuration</th>\
         <th>mean |RH bias| RH1–99 (m)</th><th>MSD (m²)</th><th>RH98 bias (m)</th><th>RH50 bias (m)</th>\
         <th>ground bias (m)</th><th>waveform χ²</th><th>at the best ρ</th></tr></thead>\n<tbody>\n",
        escape(&c.chosen)
    );
    for r in &c.configurations {
        let mark = if r.configuration == c.chosen { " (chosen)" } else { "" };
        let _ = writeln!(
            s,
            "<tr><td>{}{mark}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td>\
             <td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td></tr>",
            escape(&r.configuration),
            num(r.mean_abs_bias_rh1_99),
            num(r.msd),
            signed(r.rh98_bias),
            signed(r.rh50_bias),
            signed(r.ground_bias_m),
            r.waveform_chi2.map_or("–".to_string(), |x| format!("{x:.0}")),
            r.waveform_chi2_profiled.map_or("–".to_string(), |x| format!("{x:.0}"))
        );
    }
    s.push_str(
        "</tbody>\n</table>\n<table>\n<thead><tr><th>L2A algorithm</th><th>shots</th>\
         <th>ground bias, GEDI − ALS (m)</th><th>95 % CI (m)</th></tr></thead>\n<tbody>\n",
    );
    for g in &c.ground_by_algorithm {
        let mark = if c.least_biased_algorithm == Some(g.algorithm) { " (least biased)" } else { "" };
        let _ = writeln!(
            s,
            "<tr><td>a{}{mark}</td><td class=\"num\">{}</td><td class=\"num\">{}</td>\
             <td class=\"num\">{} to {}</td></tr>",
            g.algorithm,
            g.n_shots,
            signed(g.bias_m),
            signed(g.ci95[0]),
            signed(g.ci95[1])
        );
    }
    s.push_str("</tbody>\n</table>\n");
    s
}

/// Effects with their parameters and held-out figures (units in the headers).
fn trial_table(trials: &[TrialJson]) -> String {
    let mut s = String::from(
        "<table>\n<thead><tr><th>effect</th><th>parameters</th><th>held-out gap before (m)</th>\
         <th>after (m)</th><th>shrink (%)</th><th>95 % CI (%)</th><th>note</th></tr></thead>\n<tbody>\n",
    );
    let num = |v: Option<f64>, scale: f64| v.map_or("–".to_string(), |x| format!("{:.2}", x * scale));
    let pct = |v: Option<f64>| v.map_or("–".to_string(), |x| format!("{:.0}", 100.0 * x));
    for t in trials {
        let params: Vec<(&String, ParamValue)> = t.params.iter().map(|(k, v)| (k, v.clone())).collect();
        let params = params_text(&params);
        let h = &t.held_out;
        let note = match (&t.at_bound, &t.equivalent_to) {
            (_, Some(e)) => format!("equivalent to the simpler {}", e.name),
            (Some(b), None) => format!("fit on the edge of its range ({b})"),
            (None, None) => String::new(),
        };
        let _ = writeln!(
            s,
            "<tr><td>{}</td><td>{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td><td class=\"num\">{}</td>\
             <td class=\"num\">{} to {}</td><td>{}</td></tr>",
            escape(&t.name),
            escape(&params),
            num(h.mean_abs_bias_rh1_99_before, 1.0),
            num(h.mean_abs_bias_rh1_99_after, 1.0),
            pct(h.shrink),
            pct(h.ci95[0]),
            pct(h.ci95[1]),
            escape(&note)
        );
    }
    s.push_str("</tbody>\n</table>\n");
    s
}
