//! Write: the study's filters applied, `results/<granule key>.parquet` per granule whose results are
//! not current.

use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

use arrow::array::{ArrayRef, Float32Builder, Float64Array, ListBuilder, StringArray, UInt64Array, UInt8Array};
use arrow::record_batch::RecordBatch;

use super::plan::{GranulePlan, StudyInputs};
use super::{META_COUNTS, META_INPUT};
use crate::dataset::results::col;
use crate::dataset::results::{results_metadata, results_schema};
use crate::dataset::shots::{col as shot_col, AlgorithmColumns, ShotColumns, ALGORITHMS, SELECTED};
use crate::dataset::sim::{col as sim_col, STATUS_OK};
use crate::dataset::{self, read};
use crate::error::{Error, Result};
use crate::kernels::gedi::{N_ALGORITHMS, RH_LEN};
use crate::kernels::study::align::align_rh;
use crate::kernels::study::classes;
use crate::kernels::study::select::{
    als_window, select_rows, AlgorithmFacts, Filter, FilterCounts, ResultInput, SegmentFacts, ShotContext, ShotFacts,
    SimFacts, StudyAlgorithm, StudyRules, WEIGHTINGS,
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
    let mut names = vec![
        shot_col::SHOT_NUMBER,
        shot_col::GRANULE,
        shot_col::BEAM,
        shot_col::BEAM_TYPE,
        shot_col::DELTA_TIME,
        shot_col::DEGRADE_FLAG,
        shot_col::LEAF_OFF_FLAG,
        shot_col::SELECTED_ALGORITHM,
    ];
    names.extend(ShotColumns::GEOID_COLUMNS);
    for a in std::iter::once(&SELECTED).chain(ALGORITHMS.iter().map(|(a, _)| a)) {
        names.extend([a.quality_flag, a.sensitivity, a.elev_lowestmode, a.rh]);
    }
    let mut out = Vec::with_capacity(rows.len());
    read::for_each_batch(path, Some(&names), Some(&rows), |c| {
        let shots = ShotColumns(c);
        for i in 0..c.num_rows() {
            let alg = |a: &AlgorithmColumns| -> Result<AlgorithmFacts> {
                Ok(AlgorithmFacts {
                    quality_flag: c.u8(a.quality_flag, i)?,
                    sensitivity: c.f64(a.sensitivity, i)?,
                    elev_lowestmode: c.f64(a.elev_lowestmode, i)?,
                    rh: c.f32_list(a.rh, i)?,
                })
            };
            let mut algorithms = vec![alg(&SELECTED)?];
            for (a, _) in &ALGORITHMS {
                algorithms.push(alg(a)?);
            }
            out.push(ShotFacts {
                shot_number: c
                    .u64(shot_col::SHOT_NUMBER, i)?
                    .ok_or_else(|| Error::field(path, shot_col::SHOT_NUMBER, "null"))?,
                granule: c.string(shot_col::GRANULE, i)?.unwrap_or_default(),
                beam: c.string(shot_col::BEAM, i)?.unwrap_or_default(),
                beam_type: shots.beam_type(i)?.map(|b| b.as_str().to_string()).unwrap_or_default(),
                delta_time: c.f64(shot_col::DELTA_TIME, i)?,
                degrade_flag: c.u8(shot_col::DEGRADE_FLAG, i)?,
                leaf_off_flag: c.u8(shot_col::LEAF_OFF_FLAG, i)?,
                selected_algorithm: c.u8(shot_col::SELECTED_ALGORITHM, i)?,
                geoid_offset: shots.geoid_offset(i)?,
                algorithms: algorithms.try_into().expect("the selected algorithm and a1…a6"),
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
    let columns = [
        sim_col::FOOTPRINT_ID,
        sim_col::WEIGHTING,
        sim_col::STATUS,
        sim_col::ALS_GROUND,
        sim_col::SLOPE_DEG,
        sim_col::ALS_COVER,
        sim_col::RH,
    ];
    let mut out: HashMap<u64, [SimFacts; 3]> = HashMap::new();
    read::for_each_batch(path, Some(&columns), None, |c| {
        for i in 0..c.num_rows() {
            let id = c.string(sim_col::FOOTPRINT_ID, i)?.unwrap_or_default();
            let sn: u64 = id
                .parse()
                .map_err(|_| Error::field(path, sim_col::FOOTPRINT_ID, format!("`{id}` is not a shot number")))?;
            let w = c.string(sim_col::WEIGHTING, i)?.unwrap_or_default();
            let Some(k) = WEIGHTINGS.iter().position(|x| *x == w) else {
                return Err(Error::field(path, sim_col::WEIGHTING, format!("`{w}` is not count, frac or int")));
            };
            out.entry(sn).or_default()[k] = SimFacts {
                ok: c.string(sim_col::STATUS, i)?.as_deref() == Some(STATUS_OK),
                als_ground: c.f64(sim_col::ALS_GROUND, i)?,
                slope_deg: c.f64(sim_col::SLOPE_DEG, i)?,
                als_cover: c.f64(sim_col::ALS_COVER, i)?,
                rh: c.f32_list(sim_col::RH, i)?,
            };
        }
        Ok(())
    })?;
    Ok(out)
}

/// Build a results batch: every derived column (classes, GEDI ground in the ALS datum, aligned RH)
/// is computed here by the `study` kernels, so no writer can get them differently. Errors (naming
/// the shot and the field) on RH lists that are not 101 long, a sensitivity below the study's 0.90
/// (filter before), an unknown weighting or algorithm.
pub fn results_batch(rows: &[ResultInput]) -> Result<RecordBatch> {
    let n = rows.len();
    let bad = |r: &ResultInput, field: &str, msg: String| {
        Error::field("results", format!("shot {} {field}", r.shot_number), msg)
    };
    let mut rh_sim = ListBuilder::with_capacity(Float32Builder::with_capacity(n * RH_LEN), n);
    let mut rh_gedi = ListBuilder::with_capacity(Float32Builder::with_capacity(n * RH_LEN), n);
    let mut rh_aligned = ListBuilder::with_capacity(Float32Builder::with_capacity(n * RH_LEN), n);
    let mut groups = Vec::with_capacity(n);
    let mut gedi_ground = Vec::with_capacity(n);
    for r in rows {
        for (name, rh) in [(col::RH_SIM, &r.rh_sim), (col::RH_GEDI, &r.rh_gedi)] {
            if rh.len() != RH_LEN {
                return Err(bad(r, name, format!("{} values, expected {RH_LEN}", rh.len())));
            }
        }
        if !WEIGHTINGS.contains(&r.weighting.as_str()) {
            return Err(bad(r, col::WEIGHTING, format!("`{}` is not count, frac or int", r.weighting)));
        }
        if let StudyAlgorithm::A(k) = r.algorithm {
            if !(1..=N_ALGORITHMS as u8).contains(&k) {
                return Err(bad(r, col::ALGORITHM, format!("a{k} is not a GEDI algorithm (1..{N_ALGORITHMS})")));
            }
        }
        let group = classes::sensitivity_group(r.sensitivity).ok_or_else(|| {
            bad(r, col::SENSITIVITY, format!("{} is below the study's 0.90 (apply the filter first)", r.sensitivity))
        })?;
        groups.push(group);
        let ground = r.vertical_reference.to_als_datum(r.elev_lowestmode);
        gedi_ground.push(ground);
        rh_sim.append_value(r.rh_sim.iter().map(|&v| Some(v)));
        rh_gedi.append_value(r.rh_gedi.iter().map(|&v| Some(v)));
        rh_aligned.append_value(align_rh(&r.rh_gedi, ground, r.als_ground).into_iter().map(Some));
    }
    let strings = |f: &dyn Fn(&ResultInput) -> String| -> ArrayRef {
        Arc::new(rows.iter().map(f).map(Some).collect::<StringArray>())
    };
    let columns: Vec<ArrayRef> = vec![
        Arc::new(rows.iter().map(|r| r.shot_number).collect::<UInt64Array>()),
        strings(&|r| r.granule.clone()),
        strings(&|r| r.beam.clone()),
        strings(&|r| r.beam_type.clone()),
        strings(&|r| {
            r.forest_type.as_deref().and_then(classes::parse_forest_type).unwrap_or(classes::UNKNOWN).to_string()
        }),
        strings(&|r| classes::phenology(r.leaf_off_flag).to_string()),
        Arc::new(rows.iter().map(|r| r.selected_algorithm).collect::<UInt8Array>()),
        Arc::new(rows.iter().map(|r| r.sensitivity as f32).collect::<arrow::array::Float32Array>()),
        Arc::new(groups.iter().map(|g| Some(*g)).collect::<StringArray>()),
        Arc::new(rows.iter().map(|r| r.slope_deg).collect::<Float64Array>()),
        strings(&|r| classes::slope_class(r.slope_deg).to_string()),
        Arc::new(rows.iter().map(|r| r.als_cover).collect::<Float64Array>()),
        strings(&|r| classes::cover_class(r.als_cover).to_string()),
        strings(&|r| r.weighting.clone()),
        strings(&|r| r.algorithm.label()),
        Arc::new(rows.iter().map(|r| r.als_ground).collect::<Float64Array>()),
        Arc::new(Float64Array::from(gedi_ground)),
        strings(&|r| r.vertical_reference.label().to_string()),
        Arc::new(rh_sim.finish()),
        Arc::new(rh_gedi.finish()),
        Arc::new(rh_aligned.finish()),
        Arc::new(rows.iter().map(|r| r.r_collocation).collect::<Float64Array>()),
    ];
    RecordBatch::try_new(results_schema(), columns).map_err(|e| Error::table("results", e))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernels::study::align::VerticalReference;
    use arrow::array::{Array, AsArray};
    use arrow::datatypes::Float32Type;

    fn row() -> ResultInput {
        ResultInput {
            shot_number: 19640513500108370,
            granule: "g".into(),
            beam: "BEAM0101".into(),
            beam_type: "full_power".into(),
            forest_type: Some("coniferous".into()),
            leaf_off_flag: None,
            selected_algorithm: Some(1),
            sensitivity: 0.97,
            slope_deg: Some(12.0),
            als_cover: Some(0.8),
            weighting: "count".into(),
            algorithm: StudyAlgorithm::Default,
            als_ground: 100.0,
            elev_lowestmode: 149.0,
            vertical_reference: VerticalReference::Geoid { geoid_offset: 50.0 },
            rh_sim: vec![1.0; 101],
            rh_gedi: (0..=100).map(|k| 21.0 * k as f32 / 100.0).collect(),
            r_collocation: None,
        }
    }

    #[test]
    fn derived_columns_come_from_the_kernels() {
        let b = results_batch(&[row()]).unwrap();
        let s = |name: &str| b.column_by_name(name).unwrap().as_string::<i32>().value(0).to_string();
        assert_eq!(s("phenology"), "unknown");
        assert_eq!(s("sensitivity_group"), "high");
        assert_eq!(s("slope_class"), "[10,20)");
        assert_eq!(s("cover_class"), "[0.75,1]");
        assert_eq!(s("forest_type"), "coniferous");
        assert_eq!(s("vertical_reference"), "geoid");
        assert_eq!(s("algorithm"), "default");
        let ground = b.column_by_name("gedi_ground").unwrap().as_primitive::<arrow::datatypes::Float64Type>().value(0);
        assert_eq!(ground, 99.0);
        // GEDI ground 1 m below the ALS ground: aligned RH 1 m below GEDI's RH.
        let aligned = b.column_by_name("rh_aligned").unwrap().as_list::<i32>().value(0);
        let aligned = aligned.as_primitive::<Float32Type>();
        assert!((aligned.value(100) - 20.0).abs() < 1e-5);
        assert!(b.column_by_name("r_collocation").unwrap().is_null(0));
        assert_eq!(b.schema(), results_schema());
    }

    #[test]
    fn contract_violations_name_shot_and_field() {
        let mut r = row();
        r.rh_gedi.pop();
        let e = results_batch(&[r]).unwrap_err().to_string();
        assert!(e.contains("rh_gedi") && e.contains("100 values") && e.contains("19640513500108370"), "{e}");
        let mut r = row();
        r.sensitivity = 0.5;
        assert!(results_batch(&[r]).unwrap_err().to_string().contains("sensitivity"));
        let mut r = row();
        r.weighting = "intensity".into();
        assert!(results_batch(&[r]).unwrap_err().to_string().contains("weighting"));
        let mut r = row();
        r.algorithm = StudyAlgorithm::A(7);
        assert!(results_batch(&[r]).unwrap_err().to_string().contains("algorithm"));
    }

    #[test]
    fn unknown_forest_label_becomes_unknown() {
        let mut r = row();
        r.forest_type = Some("pine".into());
        r.leaf_off_flag = Some(1);
        let b = results_batch(&[r]).unwrap();
        assert_eq!(b.column_by_name("forest_type").unwrap().as_string::<i32>().value(0), "unknown");
        assert_eq!(b.column_by_name("phenology").unwrap().as_string::<i32>().value(0), "leaf_off");
    }
}
