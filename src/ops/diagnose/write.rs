//! Write: the diagnosis's tables (Parquet + CSV) and figures (PNG + SVG) in its folder.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow::array::{Array, Float64Array, RecordBatch, StringArray};
use arrow::datatypes::{Field, Schema};

use crate::error::{Error, Result};
use crate::kernels::diagnose::gap::N_PCT;
use crate::kernels::diagnose::json::params;
use crate::kernels::diagnose::Diagnosis;
use crate::ops::report::figures::{self, LinePanels};

fn batch(fields: Vec<(&str, Arc<dyn Array>)>) -> Result<RecordBatch> {
    let schema =
        Schema::new(fields.iter().map(|(n, a)| Field::new(*n, a.data_type().clone(), true)).collect::<Vec<_>>());
    RecordBatch::try_new(Arc::new(schema), fields.into_iter().map(|(_, a)| a).collect())
        .map_err(|e| Error::table("diagnosis", e))
}

fn floats(v: impl IntoIterator<Item = f64>) -> Arc<dyn Array> {
    Arc::new(Float64Array::from_iter_values(v))
}

fn texts<S: AsRef<str>>(v: impl IntoIterator<Item = S>) -> Arc<dyn Array> {
    Arc::new(StringArray::from_iter_values(v))
}

pub(super) fn write_tables(d: &Diagnosis, out: &Path) -> Result<Vec<PathBuf>> {
    let w = &d.where_;
    let mut files = Vec::new();
    let p = &w.percentiles;
    files.extend(crate::ops::report::write_named_table(
        out,
        "where_percentiles",
        &batch(vec![
            ("rh", floats(p.iter().map(|p| p.k as f64))),
            ("bias", floats(p.iter().map(|p| p.bias))),
            ("bias_als_frame", floats(p.iter().map(|p| p.bias_als_frame))),
            ("rmse", floats(p.iter().map(|p| p.rmse))),
            ("sb", floats(p.iter().map(|p| p.sb))),
            ("sdsd", floats(p.iter().map(|p| p.sdsd))),
            ("lcs", floats(p.iter().map(|p| p.lcs))),
        ])?,
    )?);
    let s = &w.strata;
    files.extend(crate::ops::report::write_named_table(
        out,
        "where_strata",
        &batch(vec![
            ("kind", texts(s.iter().map(|s| s.kind.as_str()))),
            ("label", texts(s.iter().map(|s| s.label.as_str()))),
            ("n_shots", floats(s.iter().map(|s| s.n_shots as f64))),
            ("mean_abs_bias_rh1_99", floats(s.iter().map(|s| s.metrics.mean_abs_bias_rh))),
            ("msd", floats(s.iter().map(|s| s.metrics.msd))),
            ("sb", floats(s.iter().map(|s| s.metrics.sb))),
            ("sdsd", floats(s.iter().map(|s| s.metrics.sdsd))),
            ("lcs", floats(s.iter().map(|s| s.metrics.lcs))),
            ("ground_bias_m", floats(s.iter().map(|s| s.metrics.ground_bias))),
            ("share_of_squared_error", floats(s.iter().map(|s| s.share_of_squared_error))),
        ])?,
    )?);
    let r = &w.waveform;
    files.extend(crate::ops::report::write_named_table(
        out,
        "waveform_residual",
        &batch(vec![
            ("height_m", floats(r.height.iter().copied())),
            ("real", floats(r.real.iter().copied())),
            ("simulated", floats(r.simulated.iter().copied())),
            ("residual", floats(r.residual.iter().copied())),
        ])?,
    )?);
    let c = &d.configuration;
    let t = &c.trials;
    files.extend(crate::ops::report::write_named_table(
        out,
        "configurations",
        &batch(vec![
            ("configuration", texts(t.iter().map(|t| t.config.label()))),
            ("weighting", texts(t.iter().map(|t| t.config.weighting.name()))),
            ("reflectance", texts(t.iter().map(|t| t.config.reflectance.name()))),
            (
                "chosen",
                Arc::new(arrow::array::BooleanArray::from(t.iter().map(|t| t.config == c.chosen).collect::<Vec<_>>())),
            ),
            ("mean_abs_bias_rh1_99", floats(t.iter().map(|t| t.metrics.mean_abs_bias))),
            ("systematic_gap", floats(t.iter().map(|t| t.metrics.systematic))),
            ("msd", floats(t.iter().map(|t| t.metrics.msd))),
            ("rh98_bias", floats(t.iter().map(|t| t.metrics.bias_rh[97]))),
            ("rh50_bias", floats(t.iter().map(|t| t.metrics.bias_rh[49]))),
            ("ground_bias_m", floats(t.iter().map(|t| t.metrics.ground_bias))),
            ("waveform_chi2", floats(t.iter().map(|t| t.waveform_chi2))),
            ("waveform_chi2_profiled", floats(t.iter().map(|t| t.waveform_chi2_profiled))),
        ])?,
    )?);
    let g = &c.ground;
    files.extend(crate::ops::report::write_named_table(
        out,
        "ground_by_algorithm",
        &batch(vec![
            ("algorithm", floats(g.iter().map(|g| f64::from(g.algorithm)))),
            ("n_shots", floats(g.iter().map(|g| g.n as f64))),
            ("ground_bias_m", floats(g.iter().map(|g| g.bias_m))),
            ("ci95_lo", floats(g.iter().map(|g| g.ci95[0]))),
            ("ci95_hi", floats(g.iter().map(|g| g.ci95[1]))),
        ])?,
    )?);
    for (name, trials) in [("effects", &d.ranking.effects), ("ladder", &d.ranking.ladder)] {
        files.extend(crate::ops::report::write_named_table(
            out,
            name,
            &batch(vec![
                ("step", floats((0..trials.len()).map(|i| i as f64 + 1.0))),
                ("effect", texts(trials.iter().map(|t| t.effect.name()))),
                ("params", texts(trials.iter().map(|t| serde_json::to_string(&params(&t.effect)).unwrap_or_default()))),
                ("frame", texts(trials.iter().map(|t| t.held_out.frame.name()))),
                ("mean_abs_bias_before", floats(trials.iter().map(|t| t.held_out.before.mean_abs_bias))),
                ("mean_abs_bias_after", floats(trials.iter().map(|t| t.held_out.after.mean_abs_bias))),
                ("shrink", floats(trials.iter().map(|t| t.held_out.shrink))),
                ("shrink_ci95_lo", floats(trials.iter().map(|t| t.held_out.ci95[0]))),
                ("shrink_ci95_hi", floats(trials.iter().map(|t| t.held_out.ci95[1]))),
                ("msd_before", floats(trials.iter().map(|t| t.held_out.before.msd))),
                ("msd_after", floats(trials.iter().map(|t| t.held_out.after.msd))),
                (
                    "waveform_shrink",
                    Arc::new(Float64Array::from(
                        trials.iter().map(|t| t.held_out.profile_shrink()).collect::<Vec<_>>(),
                    )),
                ),
                ("score", floats(trials.iter().map(|t| t.held_out.score()))),
            ])?,
        )?);
    }
    Ok(files)
}

pub(super) fn write_figures(d: &Diagnosis, out: &Path) -> Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    let profile = |label: &str, b: &[f64; N_PCT]| {
        (label.to_string(), (0..N_PCT).map(|k| ((k + 1) as f64, b[k])).collect::<Vec<_>>())
    };
    let mut rh = vec![
        profile("baseline (noise-free)", &d.where_.overall.bias_rh),
        profile("chosen configuration", &d.nominal.bias_rh),
    ];
    let mut als = vec![
        profile("baseline (noise-free)", &d.where_.overall.bias_als),
        profile("chosen configuration", &d.nominal.bias_als),
    ];
    let mut names = Vec::new();
    for t in &d.ranking.ladder {
        names.push(t.effect.name());
        let label = format!("+ {}", names.join(" + "));
        rh.push(profile(&label, &t.held_out.after.bias_rh));
        als.push(profile(&label, &t.held_out.after.bias_als));
    }
    if d.ranking.ladder.is_empty() {
        if let Some(t) = d.ranking.effects.first() {
            let label = format!("+ {} (not significant)", t.effect.name());
            rh.push(profile(&label, &t.held_out.after.bias_rh));
            als.push(profile(&label, &t.held_out.after.bias_als));
        }
    }
    let fig = LinePanels {
        title: "Held-out RH bias (simulated − GEDI) before and after the diagnosed effects".into(),
        x_desc: "RH percentile".into(),
        y_desc: "bias, simulated − GEDI (m)".into(),
        panels: vec![("RH frame (own grounds)".into(), rh), ("ALS frame (heights above the ALS ground)".into(), als)],
        zero_line: true,
        legend_lower: false,
        own_y: false,
    };
    files.extend(figures::render(&fig, out, "bias_profile_before_after")?);
    let r = &d.where_.waveform;
    // In % of the waveform energy, so that the residual's ticks stay readable.
    let series = |label: &str, v: &[f64]| {
        (label.to_string(), r.height.iter().zip(v).map(|(&h, &y)| (h, 100.0 * y)).collect::<Vec<_>>())
    };
    let fig = LinePanels {
        title: format!("Mean normalised waveform by height above the ALS ground ({} shots)", r.n_shots),
        x_desc: "height above ALS ground (m)".into(),
        y_desc: "% of the waveform energy per 0.5 m".into(),
        panels: vec![
            ("real and simulated (baseline)".into(), vec![series("real", &r.real), series("simulated", &r.simulated)]),
            ("residual simulated − real".into(), vec![series("residual", &r.residual)]),
        ],
        zero_line: true,
        legend_lower: false,
        own_y: true,
    };
    files.extend(figures::render(&fig, out, "waveform_residual")?);
    Ok(files)
}
