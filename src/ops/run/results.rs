//! Write: the study's filters applied, `results/<granule key>.parquet` per granule whose results are
//! not current.

use std::collections::HashMap;
use std::path::Path;

use super::plan::{GranulePlan, StudyInputs};
use super::{META_COUNTS, META_INPUT};
use crate::dataset::results::{results_batch, results_metadata, results_schema};
use crate::dataset::{self, read};
use crate::error::{Error, Result};
use crate::kernels::study::select::{
    als_window, select_rows, AlgorithmFacts, Filter, FilterCounts, SegmentFacts, ShotContext, ShotFacts, SimFacts,
    StudyRules, WEIGHTINGS,
};
use crate::ops::progress::{Progress, Step};

/// Apply the filters and write `results/<key>.parquet` for every granule whose results are not current.
pub(super) fn results(
    plans: &mut [GranulePlan],
    inputs: &StudyInputs,
    rules: &StudyRules,
    progress: &dyn Progress,
) -> Result<()> {
    let todo = plans.iter().filter(|p| p.needs_results).count();
    if todo == 0 {
        return Ok(());
    }
    progress.start(Step::Results, todo as u64);
    let r = plans.iter_mut().filter(|p| p.needs_results).try_for_each(|p| {
        granule_results(p, inputs, rules)?;
        progress.advance(1);
        Ok(())
    });
    progress.finish();
    r
}

pub(super) fn granule_results(p: &mut GranulePlan, inputs: &StudyInputs, rules: &StudyRules) -> Result<()> {
    let sims = if p.covered.is_empty() { HashMap::new() } else { read_sim_facts(&p.sim_path)? };
    let shots = read_shot_facts(&p.file.path, p.covered.iter().map(|c| c.row))?;
    let mut counts = FilterCounts::default();
    counts.remove_shots((p.run.shots - p.covered.len()) as u64, Filter::AlsCoverage);
    let mut rows = Vec::new();
    for (c, shot) in p.covered.iter().zip(&shots) {
        let segment =
            c.offset.as_ref().map(|o| SegmentFacts { dz: o.dz, r_after: inputs.r_after.get(&o.segment_id).copied() });
        let ctx = ShotContext {
            sim: sims.get(&shot.shot_number),
            window: als_window(&inputs.tiles, c.footprint.x, c.footprint.y),
            segment,
            forest_type: inputs.strata.get(&shot.shot_number).map(String::as_str),
        };
        select_rows(shot, &ctx, rules, &mut counts, &mut rows);
    }
    let batch = results_batch(&rows)?;
    let mut meta = results_metadata();
    meta.insert(META_INPUT.to_string(), p.results_input.clone());
    meta.insert(META_COUNTS.to_string(), counts.to_json().to_string());
    dataset::write_parquet(&p.results_path, results_schema(), &[batch], &meta)?;
    p.run.results_written = true;
    p.run.counts = counts;
    Ok(())
}

/// The facts of the `shots/` rows `rows` (ascending) of one file, in that order.
pub(super) fn read_shot_facts(path: &Path, rows: impl Iterator<Item = usize>) -> Result<Vec<ShotFacts>> {
    let rows: Vec<usize> = rows.collect();
    if rows.is_empty() {
        return Ok(Vec::new());
    }
    let mut names: Vec<String> = [
        "shot_number",
        "granule",
        "beam",
        "beam_type",
        "delta_time",
        "degrade_flag",
        "leaf_off_flag",
        "selected_algorithm",
        "geoid_offset_used",
        "quality_flag",
        "sensitivity",
        "elev_lowestmode",
        "rh",
    ]
    .map(String::from)
    .to_vec();
    for n in 1..=6 {
        names.extend([
            format!("quality_flag_a{n}"),
            format!("sensitivity_a{n}"),
            format!("elev_lowestmode_a{n}"),
            format!("rh_a{n}"),
        ]);
    }
    let names: Vec<&str> = names.iter().map(String::as_str).collect();
    let mut out = Vec::with_capacity(rows.len());
    read::for_each_batch(path, Some(&names), Some(&rows), |c| {
        for i in 0..c.num_rows() {
            let alg = |suffix: &str| -> Result<AlgorithmFacts> {
                Ok(AlgorithmFacts {
                    quality_flag: c.u8(&format!("quality_flag{suffix}"), i)?,
                    sensitivity: c.f64(&format!("sensitivity{suffix}"), i)?,
                    elev_lowestmode: c.f64(&format!("elev_lowestmode{suffix}"), i)?,
                    rh: c.f32_list(&format!("rh{suffix}"), i)?,
                })
            };
            let algorithms = [alg("")?, alg("_a1")?, alg("_a2")?, alg("_a3")?, alg("_a4")?, alg("_a5")?, alg("_a6")?];
            out.push(ShotFacts {
                shot_number: c.u64("shot_number", i)?.ok_or_else(|| Error::field(path, "shot_number", "null"))?,
                granule: c.string("granule", i)?.unwrap_or_default(),
                beam: c.string("beam", i)?.unwrap_or_default(),
                beam_type: c.string("beam_type", i)?.unwrap_or_default(),
                delta_time: c.f64("delta_time", i)?,
                degrade_flag: c.u8("degrade_flag", i)?,
                leaf_off_flag: c.u8("leaf_off_flag", i)?,
                selected_algorithm: c.u8("selected_algorithm", i)?,
                geoid_offset: c.f64("geoid_offset_used", i)?,
                algorithms,
            });
        }
        Ok(())
    })?;
    if out.len() != rows.len() {
        return Err(Error::table(path, format!("read {} shots for {} rows", out.len(), rows.len())));
    }
    Ok(out)
}

/// Shot → the three weightings' simulation facts of a `sim/` file.
pub(super) fn read_sim_facts(path: &Path) -> Result<HashMap<u64, [SimFacts; 3]>> {
    let columns = ["footprint_id", "weighting", "status", "als_ground", "slope_deg", "als_cover", "rh"];
    let mut out: HashMap<u64, [SimFacts; 3]> = HashMap::new();
    read::for_each_batch(path, Some(&columns), None, |c| {
        for i in 0..c.num_rows() {
            let id = c.string("footprint_id", i)?.unwrap_or_default();
            let sn: u64 =
                id.parse().map_err(|_| Error::field(path, "footprint_id", format!("`{id}` is not a shot number")))?;
            let w = c.string("weighting", i)?.unwrap_or_default();
            let Some(k) = WEIGHTINGS.iter().position(|x| *x == w) else {
                return Err(Error::field(path, "weighting", format!("`{w}` is not count, frac or int")));
            };
            out.entry(sn).or_default()[k] = SimFacts {
                ok: c.string("status", i)?.as_deref() == Some("ok"),
                als_ground: c.f64("als_ground", i)?,
                slope_deg: c.f64("slope_deg", i)?,
                als_cover: c.f64("als_cover", i)?,
                rh: c.f32_list("rh", i)?,
            };
        }
        Ok(())
    })?;
    Ok(out)
}
