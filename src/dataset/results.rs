//! The `results` table: one row per shot × weighting × algorithm, the input of every study
//! query (`queries/*.sql`, `gedisim report`): its schema and metadata. `gedisim run` fills it
//! (`ops::run::results_batch`, where the derived columns are computed by the `study` kernels).

use std::collections::HashMap;
use std::sync::Arc;

use arrow::datatypes::{DataType, Field, Schema, SchemaRef};

use super::list_f32;
use crate::error::{Error, Result};

/// The names of the `results/` columns (docs/schemas.md), one constant each.
pub mod col {
    pub const SHOT_NUMBER: &str = "shot_number";
    pub const GRANULE: &str = "granule";
    pub const BEAM: &str = "beam";
    pub const BEAM_TYPE: &str = "beam_type";
    pub const FOREST_TYPE: &str = "forest_type";
    pub const PHENOLOGY: &str = "phenology";
    pub const SELECTED_ALGORITHM: &str = "selected_algorithm";
    pub const SENSITIVITY: &str = "sensitivity";
    pub const SENSITIVITY_GROUP: &str = "sensitivity_group";
    pub const SLOPE_DEG: &str = "slope_deg";
    pub const SLOPE_CLASS: &str = "slope_class";
    pub const ALS_COVER: &str = "als_cover";
    pub const COVER_CLASS: &str = "cover_class";
    pub const WEIGHTING: &str = "weighting";
    pub const ALGORITHM: &str = "algorithm";
    pub const ALS_GROUND: &str = "als_ground";
    pub const GEDI_GROUND: &str = "gedi_ground";
    pub const VERTICAL_REFERENCE: &str = "vertical_reference";
    pub const RH_SIM: &str = "rh_sim";
    pub const RH_GEDI: &str = "rh_gedi";
    pub const RH_ALIGNED: &str = "rh_aligned";
    pub const R_COLLOCATION: &str = "r_collocation";
}

/// Schema of the results table (docs/schemas.md, `results/`).
pub fn results_schema() -> SchemaRef {
    let f = |n: &str, t: DataType, null: bool| Field::new(n, t, null);
    Arc::new(Schema::new(vec![
        f(col::SHOT_NUMBER, DataType::UInt64, false),
        f(col::GRANULE, DataType::Utf8, false),
        f(col::BEAM, DataType::Utf8, false),
        f(col::BEAM_TYPE, DataType::Utf8, false),
        f(col::FOREST_TYPE, DataType::Utf8, false),
        f(col::PHENOLOGY, DataType::Utf8, false),
        f(col::SELECTED_ALGORITHM, DataType::UInt8, true),
        f(col::SENSITIVITY, DataType::Float32, false),
        f(col::SENSITIVITY_GROUP, DataType::Utf8, false),
        f(col::SLOPE_DEG, DataType::Float64, true),
        f(col::SLOPE_CLASS, DataType::Utf8, false),
        f(col::ALS_COVER, DataType::Float64, true),
        f(col::COVER_CLASS, DataType::Utf8, false),
        f(col::WEIGHTING, DataType::Utf8, false),
        f(col::ALGORITHM, DataType::Utf8, false),
        f(col::ALS_GROUND, DataType::Float64, false),
        f(col::GEDI_GROUND, DataType::Float64, false),
        f(col::VERTICAL_REFERENCE, DataType::Utf8, false),
        f(col::RH_SIM, list_f32(), false),
        f(col::RH_GEDI, list_f32(), false),
        f(col::RH_ALIGNED, list_f32(), false),
        f(col::R_COLLOCATION, DataType::Float64, true),
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
    let files = dataset.visible_files(super::tables::RESULTS).map_err(|e| Error::file(dataset.root(), e))?;
    for path in files {
        let columns = [col::WEIGHTING, col::ALGORITHM, col::VERTICAL_REFERENCE];
        super::read::for_each_batch(&path, Some(&columns), None, |c| {
            let (w, a, v) =
                (c.strings(col::WEIGHTING)?, c.strings(col::ALGORITHM)?, c.strings(col::VERTICAL_REFERENCE)?);
            for i in (0..c.num_rows()).filter(|&i| w.value(i) == "count" && a.value(i) == "default") {
                *counts.entry(v.value(i).to_string()).or_insert(0) += 1;
            }
            Ok(())
        })?;
    }
    Ok(counts)
}
