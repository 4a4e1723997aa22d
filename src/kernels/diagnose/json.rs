//! `diagnosis.json` (docs/diagnosis.md): one set of serde types shared by its writer
//! (`ops::diagnose`) and its readers (the benchmarks). Non-finite numbers are written as null.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::case::{RECOLLOCATE_SHIFT_M, RECOLLOCATE_STEP_M, SHORT_SEGMENT_SHOTS, SITE_HALF, SITE_STEP_M};
use super::configuration::ConfigurationChoice;
use super::gap::{GapMetrics, N_PCT};
use super::geolocation::{GroundTest, MIN_BETA_LOWER};
use super::rank::{Comparison, Trial, BOOTSTRAP, MIN_GAIN_M, MIN_SHRINK_LOWER};
use super::Diagnosis;
use crate::scenario::effects::{Effect, ParamValue};
use crate::scenario::truth::PlantedEffect;

/// An effect's parameters by contract name.
pub type Params = BTreeMap<String, ParamValue>;

/// Parameters as `name = value, …` (numbers to 3 decimals), in the order given.
pub fn params_text<K: AsRef<str>>(params: &[(K, ParamValue)]) -> String {
    let text: Vec<String> = params
        .iter()
        .map(|(k, v)| match v {
            ParamValue::Number(x) => format!("{} = {x:.3}", k.as_ref()),
            other => format!("{} = {other}", k.as_ref()),
        })
        .collect();
    text.join(", ")
}

/// The whole file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DiagnosisJson {
    /// The sign of every bias in the file.
    pub signs: Signs,
    /// The verdict in a few lines, as `gedisim diagnose` prints it.
    #[serde(default)]
    pub summary: Vec<String>,
    /// The dataset diagnosed (its folder).
    #[serde(default)]
    pub dataset: Option<String>,
    /// Key of the inputs (`ops::diagnose`): a re-run on the same inputs reuses this diagnosis.
    #[serde(default)]
    pub inputs_key: Option<String>,
    /// The tables and figures written beside this file.
    #[serde(default)]
    pub files: Vec<String>,
    pub baseline: Baseline,
    /// The study's question first: every simulator configuration's gap, the one chosen, and the
    /// ground bias of each L2A algorithm under it.
    pub configuration: ConfigurationJson,
    /// The chosen configuration's held-out gap (every first effect's "before").
    pub nominal_chain: Gap,
    /// Every effect tried, best first.
    pub effects: Vec<TrialJson>,
    /// The greedy ladder of combined causes.
    pub ladder: Vec<TrialJson>,
    /// The verdict (`verdict.kind` is `unexplained`).
    pub unexplained: bool,
    /// The effects the first could be taken for (`verdict.kind` is `ambiguous`): in the self-test,
    /// twins with one of these planted are named as the first.
    pub ambiguous_with: Vec<String>,
    /// What the diagnosis concludes, and what decided it.
    pub verdict: VerdictJson,
    /// Twins of the shots with each leading candidate planted, and with none, ranked the same
    /// way (absent with `--twins 0`).
    pub self_test: Option<SelfTestJson>,
    #[serde(rename = "where")]
    pub where_: WhereJson,
    pub shots: ShotsJson,
    pub settings: Settings,
}

/// The verdict ([`super::selftest::verdict`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VerdictJson {
    /// `named`, `ambiguous` or `unexplained`.
    pub kind: String,
    /// The effect named, or those it is ambiguous between (the first first).
    pub effects: Vec<String>,
    /// The ranking's first effect explains the gap by its intervals (before the self-test).
    pub ranking_names: Option<String>,
    /// `self-test` or `intervals` (without a self-test).
    pub decided_by: String,
}

/// The self-test ([`super::selftest`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SelfTestJson {
    /// The configuration the twins were made and ranked with.
    pub configuration: String,
    /// Twin sets per planted hypothesis.
    pub twins: usize,
    /// Each hypothesis planted (the leading candidates, then `none`).
    pub plantings: Vec<PlantingJson>,
    /// For the effect the verdict names first: twins where it was planted that named it first,
    /// and twins without any effect that named it.
    pub named: Option<RecoveryJson>,
    /// Rates that decide the verdict.
    pub max_false_rate: f64,
    pub max_confusion_rate: f64,
}

/// One hypothesis planted in twins.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlantingJson {
    /// The effect planted, or `none`.
    pub planted: String,
    /// Its parameters (the magnitude fitted on the real shots).
    pub params: Option<Params>,
    /// What the twins named first, most often first (`unexplained`: nothing named).
    pub named_first: Vec<OutcomeJson>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OutcomeJson {
    pub name: String,
    pub twins: usize,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecoveryJson {
    pub effect: String,
    /// Twins with it planted that named it first, of `twins`.
    pub recovered: usize,
    /// Twins without any effect that named it first, of `twins`.
    pub named_without: usize,
    pub twins: usize,
}

impl VerdictJson {
    fn of(d: &Diagnosis) -> VerdictJson {
        use super::selftest::Verdict;
        let (kind, effects) = match &d.verdict {
            Verdict::Named(e) => ("named", vec![e.clone()]),
            Verdict::Ambiguous(v) => ("ambiguous", v.clone()),
            Verdict::Unexplained => ("unexplained", Vec::new()),
        };
        VerdictJson {
            kind: kind.to_string(),
            effects,
            ranking_names: d
                .ranking
                .effects
                .first()
                .filter(|_| !d.ranking.unexplained)
                .map(|t| t.effect.name().to_string()),
            decided_by: if d.self_test.is_some() { "self-test" } else { "intervals" }.to_string(),
        }
    }
}

impl SelfTestJson {
    fn of(t: &super::selftest::SelfTest, verdict: &super::selftest::Verdict) -> SelfTestJson {
        use super::selftest::{MAX_CONFUSION_RATE, MAX_FALSE_RATE};
        let named = t.subject(verdict);
        SelfTestJson {
            configuration: t.configuration.label(),
            twins: t.twins,
            plantings: t
                .plantings
                .iter()
                .map(|p| PlantingJson {
                    planted: p.label().to_string(),
                    params: p.effect.as_ref().map(params),
                    named_first: p
                        .outcomes()
                        .into_iter()
                        .map(|(n, k)| OutcomeJson { name: n.unwrap_or_else(|| "unexplained".into()), twins: k })
                        .collect(),
                })
                .collect(),
            named: named.and_then(|e| {
                Some(RecoveryJson {
                    effect: e.to_string(),
                    recovered: t.planting(Some(e))?.count(Some(e)),
                    named_without: t.planting(None)?.count(Some(e)),
                    twins: t.twins,
                })
            }),
            max_false_rate: MAX_FALSE_RATE,
            max_confusion_rate: MAX_CONFUSION_RATE,
        }
    }
}

/// The sign conventions (the study's, the same as the report's).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Signs {
    pub rh_bias: String,
    pub ground_bias: String,
    pub waveform_residual: String,
}

impl Default for Signs {
    fn default() -> Self {
        Signs {
            rh_bias: "simulated − GEDI RH (m); in the ALS frame, simulated − GEDI RH brought onto the ALS ground"
                .into(),
            ground_bias: "GEDI ground − ALS ground (m), GEDI's elev_lowestmode in the ALS datum through the geoid"
                .into(),
            waveform_residual: "simulated − real normalised waveform".into(),
        }
    }
}

/// The study's baseline gap.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Baseline {
    pub description: String,
    pub mean_abs_bias_rh1_99: Option<f64>,
    pub msd: Option<f64>,
    pub sb: Option<f64>,
    pub sdsd: Option<f64>,
    pub lcs: Option<f64>,
    pub mean_abs_bias_als_frame: Option<f64>,
    pub ground_bias_m: Option<f64>,
    pub n_shots: usize,
    pub n_tracks: usize,
}

/// The gap of a set of shots ([`GapMetrics`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Gap {
    pub mean_abs_bias_rh1_99: Option<f64>,
    pub mean_abs_bias_rh_frame: Option<f64>,
    pub mean_abs_bias_als_frame: Option<f64>,
    pub systematic_gap: Option<f64>,
    pub msd: Option<f64>,
    pub sb: Option<f64>,
    pub sdsd: Option<f64>,
    pub lcs: Option<f64>,
    pub ground_bias_m: Option<f64>,
    pub n_pairs: usize,
}

/// One effect tried: its fitted parameters and its held-out comparison.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrialJson {
    pub name: String,
    pub params: Params,
    pub held_out: HeldOut,
    /// Parameters fitted on each fold's calibration set.
    pub fold_params: Vec<Option<Params>>,
    /// The fitted parameter on a bound of its range (`name = value (… bound)`), if any.
    pub at_bound: Option<String>,
    /// The simpler effect the fitted one is equivalent to, if any.
    pub equivalent_to: Option<PlantedEffect>,
    /// For `geolocation`: the ground test it must pass to be named.
    #[serde(default)]
    pub ground_test: Option<GroundTestJson>,
}

fn equal() -> String {
    super::chain::Reflectance::Equal.name().to_string()
}

fn one() -> f64 {
    1.0
}

/// The configuration stage ([`ConfigurationChoice`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ConfigurationJson {
    /// The configuration chosen on all tracks, e.g. `int + recorded pulse`.
    pub chosen: String,
    pub weighting: String,
    /// `gaussian` (the study's 15 ns) or `recorded` (each shot's L1B transmit pulse).
    pub pulse: String,
    /// `equal` (ground and vegetation alike) or `reference` (the reference simulator's ρv 0.57,
    /// ρg 0.40).
    #[serde(default = "equal")]
    pub reflectance: String,
    /// ρg/ρv of those reflectances: a `weighting` effect's ratio multiplies it.
    #[serde(default = "one")]
    pub rho_ground_over_veg: f64,
    /// The vertical shift (m) of the real waveforms the configurations were compared at: the
    /// nominal configuration's best match, as a datum would shift them (docs/diagnosis.md).
    #[serde(default)]
    pub vertical_shift_m: Option<f64>,
    /// The configuration chosen on each fold's calibration set.
    pub fold_chosen: Vec<String>,
    /// The study's configuration (count + Gaussian 15 ns, before) against the cross-fitted
    /// choice (after), on held-out tracks.
    pub held_out: HeldOut,
    /// Every configuration's gap on every shot.
    pub configurations: Vec<ConfigurationRowJson>,
    /// GEDI ground − ALS ground of each algorithm under the chosen configuration.
    pub ground_by_algorithm: Vec<AlgorithmGroundJson>,
    /// The algorithm whose ground is least biased.
    pub least_biased_algorithm: Option<u8>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ConfigurationRowJson {
    pub configuration: String,
    pub weighting: String,
    pub pulse: String,
    #[serde(default = "equal")]
    pub reflectance: String,
    /// Mean over RH1..RH99 of the bias, simulated − GEDI (m), RH frame.
    pub mean_bias_rh_frame: Option<f64>,
    pub mean_abs_bias_rh1_99: Option<f64>,
    pub systematic_gap: Option<f64>,
    pub msd: Option<f64>,
    pub rh98_bias: Option<f64>,
    pub rh50_bias: Option<f64>,
    pub ground_bias_m: Option<f64>,
    /// Waveform-level gap against the study configuration's between-shot variance.
    pub waveform_chi2: Option<f64>,
    /// The same at the configuration's best ground/vegetation ratio, the real waveforms at their
    /// best vertical shift: what the choice of weighting and pulse is made by.
    pub waveform_chi2_profiled: Option<f64>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AlgorithmGroundJson {
    pub algorithm: u8,
    pub n_shots: usize,
    pub bias_m: Option<f64>,
    pub ci95: [Option<f64>; 2],
}

/// The ground test of per-shot geolocation ([`GroundTest`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GroundTestJson {
    pub n_shots: usize,
    pub n_moved: usize,
    pub rms_predicted_m: Option<f64>,
    pub beta: Option<f64>,
    pub ci95: [Option<f64>; 2],
    /// β's interval must start at this for per-shot geolocation to be named.
    pub min_beta_lower: f64,
    pub passes: bool,
}

/// The held-out comparison ([`Comparison`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HeldOut {
    /// The frame the systematic gap, shrink and intervals are measured in: `rh`, `als` or `both`
    /// (their mean), where the effect acts (docs/diagnosis.md).
    #[serde(default)]
    pub frame: String,
    pub mean_abs_bias_rh1_99_before: Option<f64>,
    pub mean_abs_bias_rh1_99_after: Option<f64>,
    pub shrink: Option<f64>,
    pub ci95: [Option<f64>; 2],
    pub systematic_gap_before: Option<f64>,
    pub systematic_gap_after: Option<f64>,
    pub gain_m_ci95: [Option<f64>; 2],
    pub shrink_mean_abs_bias: Option<f64>,
    pub msd_before: Option<f64>,
    pub msd_after: Option<f64>,
    pub waveform_chi2_before: Option<f64>,
    pub waveform_chi2_after: Option<f64>,
    pub waveform_shrink: Option<f64>,
    pub score: Option<f64>,
    pub before: Gap,
    pub after: Gap,
    /// `systematic_gap`, or `excess_msd` for an effect judged on spread.
    pub measure: String,
    pub spread: Option<SpreadJson>,
}

/// The spread gap of `geolocation` (m²).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SpreadJson {
    pub msd_segments_replaced: Option<f64>,
    pub msd_shots_replaced: Option<f64>,
    pub floor_msd_segments_replaced: Option<f64>,
    pub floor_msd_shots_replaced: Option<f64>,
    pub excess_msd_before: Option<f64>,
    pub excess_msd_after: Option<f64>,
}

/// Where the gap lies.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WhereJson {
    pub percentiles: Vec<PercentileJson>,
    pub strata: Vec<StratumJson>,
    pub waveform_residual: WaveformResidualJson,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PercentileJson {
    pub rh: usize,
    pub bias: Option<f64>,
    pub bias_als_frame: Option<f64>,
    pub rmse: Option<f64>,
    pub sb: Option<f64>,
    pub sdsd: Option<f64>,
    pub lcs: Option<f64>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StratumJson {
    pub kind: String,
    pub label: String,
    pub n_shots: usize,
    pub mean_abs_bias_rh1_99: Option<f64>,
    pub msd: Option<f64>,
    pub sb: Option<f64>,
    pub sdsd: Option<f64>,
    pub lcs: Option<f64>,
    pub ground_bias_m: Option<f64>,
    pub share_of_squared_error: Option<f64>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WaveformResidualJson {
    pub height_m: Vec<Option<f64>>,
    pub real: Vec<Option<f64>>,
    pub simulated: Vec<Option<f64>>,
    pub residual: Vec<Option<f64>>,
    pub n_shots: usize,
}

/// The shots read, used and dropped.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShotsJson {
    pub read: usize,
    /// Shots whose baseline gap (`where`) was measured.
    pub used: usize,
    /// Shots of the tracks drawn for the configuration, the effects and the self-test
    /// (`sample::ranked_tracks`), and those tracks.
    #[serde(default)]
    pub ranked: usize,
    #[serde(default)]
    pub ranked_tracks: usize,
    /// The limit the tracks were drawn to (`--ranked-shots`; 0: every shot).
    #[serde(default)]
    pub ranked_limit: usize,
    pub re_placed_per_hypothesis: usize,
    pub pairs_ground_mismatch: usize,
    pub dropped: Vec<DroppedJson>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DroppedJson {
    pub reason: String,
    pub n: usize,
}

/// The decision rules and the placement model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Settings {
    pub min_shrink_lower: f64,
    pub min_gain_m: f64,
    pub bootstrap: usize,
    pub folds: usize,
    pub split: String,
    pub placement: Placement,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Placement {
    pub short_segment_shots: usize,
    pub site_grid_step_m: f64,
    pub site_grid_half_width_m: f64,
    pub recollocation_shift_m: f64,
    pub recollocation_step_m: f64,
}

fn finite(x: f64) -> Option<f64> {
    x.is_finite().then_some(x)
}

fn finite_all(v: &[f64]) -> Vec<Option<f64>> {
    v.iter().map(|&x| finite(x)).collect()
}

/// An effect's parameters by contract name.
pub fn params(e: &Effect) -> Params {
    e.params().into_iter().map(|(k, v)| (k.to_string(), v)).collect()
}

impl Gap {
    pub fn of(m: &GapMetrics) -> Gap {
        Gap {
            mean_abs_bias_rh1_99: finite(m.mean_abs_bias),
            mean_abs_bias_rh_frame: finite(m.mean_abs_bias_rh),
            mean_abs_bias_als_frame: finite(m.mean_abs_bias_als),
            systematic_gap: finite(m.systematic),
            msd: finite(m.msd),
            sb: finite(m.sb),
            sdsd: finite(m.sdsd),
            lcs: finite(m.lcs),
            ground_bias_m: finite(m.ground_bias),
            n_pairs: m.n_pairs,
        }
    }
}

impl HeldOut {
    pub fn of(h: &Comparison) -> HeldOut {
        HeldOut {
            frame: h.frame.name().to_string(),
            mean_abs_bias_rh1_99_before: finite(h.before.mean_abs_bias),
            mean_abs_bias_rh1_99_after: finite(h.after.mean_abs_bias),
            shrink: finite(h.shrink),
            ci95: [finite(h.ci95[0]), finite(h.ci95[1])],
            systematic_gap_before: finite(h.before.systematic_in(h.frame)),
            systematic_gap_after: finite(h.after.systematic_in(h.frame)),
            gain_m_ci95: [finite(h.gain_ci95[0]), finite(h.gain_ci95[1])],
            shrink_mean_abs_bias: finite(h.shrink_mean_abs_bias),
            msd_before: finite(h.before.msd),
            msd_after: finite(h.after.msd),
            waveform_chi2_before: finite(h.profile_chi2[0]),
            waveform_chi2_after: finite(h.profile_chi2[1]),
            waveform_shrink: h.profile_shrink().and_then(finite),
            score: finite(h.score()),
            before: Gap::of(&h.before),
            after: Gap::of(&h.after),
            measure: if h.spread.is_some() { "excess_msd" } else { "systematic_gap" }.to_string(),
            spread: h.spread.as_ref().map(|s| SpreadJson {
                msd_segments_replaced: finite(s.msd[0]),
                msd_shots_replaced: finite(s.msd[1]),
                floor_msd_segments_replaced: finite(s.floor[0]),
                floor_msd_shots_replaced: finite(s.floor[1]),
                excess_msd_before: finite(s.excess()[0]),
                excess_msd_after: finite(s.excess()[1]),
            }),
        }
    }
}

impl TrialJson {
    pub fn of(t: &Trial) -> TrialJson {
        TrialJson {
            name: t.effect.name().to_string(),
            params: params(&t.effect),
            held_out: HeldOut::of(&t.held_out),
            fold_params: t.fold_effects.iter().map(|e| e.as_ref().map(params)).collect(),
            at_bound: t.at_bound(),
            equivalent_to: t.equivalent().as_ref().map(PlantedEffect::of),
            ground_test: t.ground_test.as_ref().map(GroundTestJson::of),
        }
    }
}

impl GroundTestJson {
    pub fn of(g: &GroundTest) -> GroundTestJson {
        GroundTestJson {
            n_shots: g.n_shots,
            n_moved: g.n_moved,
            rms_predicted_m: finite(g.rms_predicted_m),
            beta: finite(g.beta),
            ci95: [finite(g.ci95[0]), finite(g.ci95[1])],
            min_beta_lower: MIN_BETA_LOWER,
            passes: g.passes(),
        }
    }
}

impl ConfigurationJson {
    pub fn of(c: &ConfigurationChoice) -> ConfigurationJson {
        let pulse = |p| match p {
            super::chain::PulseChoice::Gaussian => "gaussian",
            super::chain::PulseChoice::Recorded => "recorded",
        };
        ConfigurationJson {
            chosen: c.chosen.label(),
            weighting: c.chosen.weighting.name().to_string(),
            pulse: pulse(c.chosen.pulse).to_string(),
            reflectance: c.chosen.reflectance.name().to_string(),
            rho_ground_over_veg: c.chosen.reflectance.rho_ground_over_veg(),
            vertical_shift_m: c.vertical_shift_m.and_then(finite),
            fold_chosen: c.fold_chosen.iter().map(|k| k.label()).collect(),
            held_out: HeldOut::of(&c.held_out),
            configurations: c
                .trials
                .iter()
                .map(|t| {
                    let m = &t.metrics;
                    ConfigurationRowJson {
                        configuration: t.config.label(),
                        weighting: t.config.weighting.name().to_string(),
                        pulse: pulse(t.config.pulse).to_string(),
                        reflectance: t.config.reflectance.name().to_string(),
                        mean_bias_rh_frame: finite(m.bias_rh.iter().sum::<f64>() / N_PCT as f64),
                        mean_abs_bias_rh1_99: finite(m.mean_abs_bias),
                        systematic_gap: finite(m.systematic),
                        msd: finite(m.msd),
                        rh98_bias: finite(m.bias_rh[97]),
                        rh50_bias: finite(m.bias_rh[49]),
                        ground_bias_m: finite(m.ground_bias),
                        waveform_chi2: finite(t.waveform_chi2),
                        waveform_chi2_profiled: finite(t.waveform_chi2_profiled),
                    }
                })
                .collect(),
            ground_by_algorithm: c
                .ground
                .iter()
                .map(|g| AlgorithmGroundJson {
                    algorithm: g.algorithm,
                    n_shots: g.n,
                    bias_m: finite(g.bias_m),
                    ci95: [finite(g.ci95[0]), finite(g.ci95[1])],
                })
                .collect(),
            least_biased_algorithm: c.least_biased_algorithm().map(|g| g.algorithm),
        }
    }
}

impl DiagnosisJson {
    /// The file of diagnosis `d` of `shots_read` shots, `dropped` (reason, count) before it, its
    /// effects ranked on tracks drawn up to `ranked_limit` shots.
    pub fn of(d: &Diagnosis, shots_read: usize, dropped: &[(String, usize)], ranked_limit: usize) -> DiagnosisJson {
        let w = &d.where_;
        let mean = |f: fn(&super::locate::PercentileGap) -> f64| {
            finite(w.percentiles.iter().map(f).sum::<f64>() / N_PCT as f64)
        };
        DiagnosisJson {
            signs: Signs::default(),
            summary: Vec::new(),
            dataset: None,
            inputs_key: None,
            files: Vec::new(),
            baseline: Baseline {
                description: "study baseline: real RH of the selected algorithm as stored vs noise-free simulated RH \
                              (count, 15 ns, σf 5.5 m) from the ALS ground, per-beam collocated, nominal geoid"
                    .to_string(),
                mean_abs_bias_rh1_99: finite(w.overall.mean_abs_bias_rh),
                msd: mean(|p| p.sb + p.sdsd + p.lcs),
                sb: mean(|p| p.sb),
                sdsd: mean(|p| p.sdsd),
                lcs: mean(|p| p.lcs),
                mean_abs_bias_als_frame: finite(w.overall.mean_abs_bias_als),
                ground_bias_m: finite(w.overall.ground_bias),
                n_shots: d.n_located,
                n_tracks: d.n_located_tracks,
            },
            configuration: ConfigurationJson::of(&d.configuration),
            nominal_chain: Gap::of(&d.nominal),
            effects: d.ranking.effects.iter().map(TrialJson::of).collect(),
            // A ladder stands on its first effect: none when the verdict names nothing.
            ladder: match d.verdict {
                super::selftest::Verdict::Unexplained => Vec::new(),
                _ => d.ranking.ladder.iter().map(TrialJson::of).collect(),
            },
            unexplained: d.verdict == super::selftest::Verdict::Unexplained,
            ambiguous_with: match &d.verdict {
                super::selftest::Verdict::Ambiguous(v) => v[1..].to_vec(),
                _ => Vec::new(),
            },
            verdict: VerdictJson::of(d),
            self_test: d.self_test.as_ref().map(|t| SelfTestJson::of(t, &d.verdict)),
            where_: WhereJson {
                percentiles: w
                    .percentiles
                    .iter()
                    .map(|p| PercentileJson {
                        rh: p.k,
                        bias: finite(p.bias),
                        bias_als_frame: finite(p.bias_als_frame),
                        rmse: finite(p.rmse),
                        sb: finite(p.sb),
                        sdsd: finite(p.sdsd),
                        lcs: finite(p.lcs),
                    })
                    .collect(),
                strata: w
                    .strata
                    .iter()
                    .map(|s| StratumJson {
                        kind: s.kind.clone(),
                        label: s.label.clone(),
                        n_shots: s.n_shots,
                        mean_abs_bias_rh1_99: finite(s.metrics.mean_abs_bias_rh),
                        msd: finite(s.metrics.msd),
                        sb: finite(s.metrics.sb),
                        sdsd: finite(s.metrics.sdsd),
                        lcs: finite(s.metrics.lcs),
                        ground_bias_m: finite(s.metrics.ground_bias),
                        share_of_squared_error: finite(s.share_of_squared_error),
                    })
                    .collect(),
                waveform_residual: WaveformResidualJson {
                    height_m: finite_all(&w.waveform.height),
                    real: finite_all(&w.waveform.real),
                    simulated: finite_all(&w.waveform.simulated),
                    residual: finite_all(&w.waveform.residual),
                    n_shots: w.waveform.n_shots,
                },
            },
            shots: ShotsJson {
                read: shots_read,
                used: d.n_located,
                ranked: d.n_shots,
                ranked_tracks: d.n_tracks,
                ranked_limit,
                re_placed_per_hypothesis: d.n_replaceable,
                pairs_ground_mismatch: d.mismatched,
                dropped: dropped.iter().map(|(reason, n)| DroppedJson { reason: reason.clone(), n: *n }).collect(),
            },
            settings: Settings {
                min_shrink_lower: MIN_SHRINK_LOWER,
                min_gain_m: MIN_GAIN_M,
                bootstrap: BOOTSTRAP,
                folds: 2,
                split: "by track (one beam of one granule)".to_string(),
                placement: Placement {
                    short_segment_shots: SHORT_SEGMENT_SHOTS,
                    site_grid_step_m: SITE_STEP_M,
                    site_grid_half_width_m: f64::from(SITE_HALF) * SITE_STEP_M,
                    recollocation_shift_m: RECOLLOCATE_SHIFT_M,
                    recollocation_step_m: RECOLLOCATE_STEP_M,
                },
            },
        }
    }
}
