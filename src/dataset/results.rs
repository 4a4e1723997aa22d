//! The `results` table: one row per shot × weighting × algorithm, the input of every study
//! query (`queries/*.sql`, `gedisim report`): its schema and metadata. `gedisim run` fills it
//! (`ops::run::results_batch`, where the derived columns are computed by the `study` kernels).

use std::collections::HashMap;
use std::sync::Arc;

use arrow::datatypes::{DataType, Field, Schema, SchemaRef};

use super::list_f32;
use crate::error::{Error, Result};

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
