//! The `results` table: one row per shot × weighting × algorithm, the input of every study
//! query (`queries/*.sql`, `gedisim report`). `gedisim run` fills it with [`results_batch`]
//! from [`ResultInput`] rows; every derived column (classes, GEDI ground in the ALS datum,
//! aligned RH) is computed here by the `study` kernels, so no writer can get them differently.

use std::collections::HashMap;
use std::sync::Arc;

use arrow::array::{ArrayRef, Float32Builder, Float64Array, ListBuilder, StringArray, UInt64Array, UInt8Array};
use arrow::datatypes::{DataType, Field, Schema, SchemaRef};
use arrow::record_batch::RecordBatch;

use super::list_f32;
use crate::error::{Error, Result};
use crate::kernels::gedi::RH_LEN;
use crate::kernels::study::align::align_rh;
use crate::kernels::study::classes;
use crate::kernels::study::select::{ResultInput, StudyAlgorithm};

/// Schema of the results table (docs/schemas.md, `results/`).
pub fn results_schema() -> SchemaRef {
    let f = |n: &str, t: DataType, null: bool| Field::new(n, t, null);
    Arc::new(Schema::new(vec![
        f("shot_number", DataType::UInt64, false),
        f("granule", DataType::Utf8, false),
        f("beam", DataType::Utf8, false),
        f("beam_type", DataType::Utf8, false),
        f("forest_type", DataType::Utf8, false),
        f("phenology", DataType::Utf8, false),
        f("selected_algorithm", DataType::UInt8, true),
        f("sensitivity", DataType::Float32, false),
        f("sensitivity_group", DataType::Utf8, false),
        f("slope_deg", DataType::Float64, true),
        f("slope_class", DataType::Utf8, false),
        f("als_cover", DataType::Float64, true),
        f("cover_class", DataType::Utf8, false),
        f("weighting", DataType::Utf8, false),
        f("algorithm", DataType::Utf8, false),
        f("als_ground", DataType::Float64, false),
        f("gedi_ground", DataType::Float64, false),
        f("vertical_reference", DataType::Utf8, false),
        f("rh_sim", list_f32(), false),
        f("rh_gedi", list_f32(), false),
        f("rh_aligned", list_f32(), false),
        f("r_collocation", DataType::Float64, true),
    ]))
}

/// Key-value metadata of a results file.
pub fn results_metadata() -> HashMap<String, String> {
    HashMap::from([
        ("gedisim:table".to_string(), "results".to_string()),
        (
            "gedisim:rh_aligned".to_string(),
            "rh_gedi + (gedi_ground - als_ground), both grounds in the ALS vertical datum".to_string(),
        ),
    ])
}

/// Build a results batch. Errors (naming the shot and the field) on RH lists that are not 101
/// long, a sensitivity below the study's 0.90 (filter before), an unknown weighting or algorithm.
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
        for (name, rh) in [("rh_sim", &r.rh_sim), ("rh_gedi", &r.rh_gedi)] {
            if rh.len() != RH_LEN {
                return Err(bad(r, name, format!("{} values, expected {RH_LEN}", rh.len())));
            }
        }
        if !["count", "frac", "int"].contains(&r.weighting.as_str()) {
            return Err(bad(r, "weighting", format!("`{}` is not count, frac or int", r.weighting)));
        }
        if let StudyAlgorithm::A(k) = r.algorithm {
            if !(1..=6).contains(&k) {
                return Err(bad(r, "algorithm", format!("a{k} is not a GEDI algorithm (1..6)")));
            }
        }
        let group = classes::sensitivity_group(r.sensitivity).ok_or_else(|| {
            bad(r, "sensitivity", format!("{} is below the study's 0.90 (apply the filter first)", r.sensitivity))
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

/// Shots of the results table (`dataset`'s `results/`) by `vertical_reference`: how GEDI's ground
/// was brought into the ALS datum, counted once per shot (rows of the `count` weighting and the
/// `default` algorithm).
pub fn vertical_references(dataset: &super::Dataset) -> Result<std::collections::BTreeMap<String, usize>> {
    let mut counts = std::collections::BTreeMap::new();
    let files = dataset.visible_files("results").map_err(|e| Error::file(dataset.root(), e))?;
    for path in files {
        let columns = ["weighting", "algorithm", "vertical_reference"];
        super::read::for_each_batch(&path, Some(&columns), None, |c| {
            let (w, a, v) = (c.strings("weighting")?, c.strings("algorithm")?, c.strings("vertical_reference")?);
            for i in (0..c.num_rows()).filter(|&i| w.value(i) == "count" && a.value(i) == "default") {
                *counts.entry(v.value(i).to_string()).or_insert(0) += 1;
            }
            Ok(())
        })?;
    }
    Ok(counts)
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
