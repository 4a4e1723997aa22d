//! The `sim` table: one row per footprint × weighting (the `simulate` contract, docs/contracts.md),
//! with the collocation offset applied to the shot, if any.

use std::collections::HashMap;
use std::sync::Arc;

use arrow::array::{ArrayRef, Float32Array, Float64Array, StringArray, UInt32Array};
use arrow::datatypes::{DataType, Field, Schema, SchemaRef};
use arrow::record_batch::RecordBatch;

use super::offsets::AppliedOffset;
use super::{list_f32, list_f32_builder};
use crate::error::{Error, Result};
use crate::kernels::sim::{Footprint, Profile, SimulatedFootprint, SkipReason, Weighting};

/// The names of the `sim/` (and `simulated/`) columns (docs/schemas.md), one constant each.
pub mod col {
    pub const FOOTPRINT_ID: &str = "footprint_id";
    pub const X: &str = "x";
    pub const Y: &str = "y";
    pub const WEIGHTING: &str = "weighting";
    pub const STATUS: &str = "status";
    pub const Z0: &str = "z0";
    pub const DZ: &str = "dz";
    pub const WAVE: &str = "wave";
    pub const GROUND_WAVE: &str = "ground_wave";
    pub const CANOPY_WAVE: &str = "canopy_wave";
    pub const ALS_GROUND: &str = "als_ground";
    pub const TRUE_TOP: &str = "true_top";
    pub const SLOPE_DEG: &str = "slope_deg";
    pub const ALS_COVER: &str = "als_cover";
    pub const N_POINTS: &str = "n_points";
    pub const POINT_DENSITY: &str = "point_density";
    pub const PULSE_DENSITY: &str = "pulse_density";
    pub const MEAN_SCAN_ANGLE_DEG: &str = "mean_scan_angle_deg";
    pub const COVERED_FRACTION: &str = "covered_fraction";
    pub const RH: &str = "rh";
    pub const OFFSET_SEGMENT_ID: &str = "offset_segment_id";
    pub const OFFSET_DX: &str = "offset_dx";
    pub const OFFSET_DY: &str = "offset_dy";
    pub const OFFSET_DZ: &str = "offset_dz";
}

/// Schema of the simulated-waveform table.
pub fn sim_schema() -> SchemaRef {
    let f = |n: &str, t: DataType, null: bool| Field::new(n, t, null);
    Arc::new(Schema::new(vec![
        f(col::FOOTPRINT_ID, DataType::Utf8, false),
        f(col::X, DataType::Float64, false),
        f(col::Y, DataType::Float64, false),
        f(col::WEIGHTING, DataType::Utf8, false),
        f(col::STATUS, DataType::Utf8, false),
        f(col::Z0, DataType::Float64, true),
        f(col::DZ, DataType::Float64, true),
        f(col::WAVE, list_f32(), true),
        f(col::GROUND_WAVE, list_f32(), true),
        f(col::CANOPY_WAVE, list_f32(), true),
        f(col::ALS_GROUND, DataType::Float64, true),
        f(col::TRUE_TOP, DataType::Float64, true),
        f(col::SLOPE_DEG, DataType::Float64, true),
        f(col::ALS_COVER, DataType::Float64, true),
        f(col::N_POINTS, DataType::UInt32, true),
        f(col::POINT_DENSITY, DataType::Float32, true),
        f(col::PULSE_DENSITY, DataType::Float32, true),
        f(col::MEAN_SCAN_ANGLE_DEG, DataType::Float32, true),
        f(col::COVERED_FRACTION, DataType::Float32, true),
        f(col::RH, list_f32(), true),
        f(col::OFFSET_SEGMENT_ID, DataType::Utf8, true),
        f(col::OFFSET_DX, DataType::Float64, true),
        f(col::OFFSET_DY, DataType::Float64, true),
        f(col::OFFSET_DZ, DataType::Float64, true),
    ]))
}

/// Parquet key-value metadata of a `sim` file: profile and bin-label convention.
pub fn sim_metadata(profile: Profile) -> HashMap<String, String> {
    let label = match profile {
        Profile::Gedirat => "top_edge",
        Profile::Default => "centre",
    };
    HashMap::from([
        ("gedisim:profile".to_string(), profile.name().to_string()),
        ("gedisim:bin_label".to_string(), label.to_string()),
    ])
}

/// The `status` of a simulated footprint; a skipped one's names why.
pub const STATUS_OK: &str = "ok";

/// Text of a skip reason in the `status` column (`ok` for a simulated footprint).
pub fn status(r: &std::result::Result<SimulatedFootprint, SkipReason>) -> String {
    match r {
        Ok(_) => STATUS_OK.to_string(),
        Err(SkipReason::NoPoints) => "no_points".to_string(),
        Err(SkipReason::NoSignal) => "no_signal".to_string(),
        Err(SkipReason::PartlyCovered { covered_fraction }) => format!("partly_covered:{covered_fraction:.3}"),
    }
}

/// Rows for `footprints` and their results (same order): one per footprint × weighting; a skipped
/// footprint keeps its rows with a `status` and null values. `applied` gives the collocation
/// offset already added to each footprint's position (empty: none).
pub fn sim_batch(
    footprints: &[Footprint],
    results: &[std::result::Result<SimulatedFootprint, SkipReason>],
    weightings: &[Weighting],
    applied: &[Option<AppliedOffset>],
) -> Result<RecordBatch> {
    let n = footprints.len() * weightings.len();
    let mut id = Vec::with_capacity(n);
    let (mut x, mut y) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let mut wname = Vec::with_capacity(n);
    let mut st = Vec::with_capacity(n);
    let (mut z0, mut dz) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let (mut wave, mut ground, mut canopy, mut rh) =
        (list_f32_builder(n), list_f32_builder(n), list_f32_builder(n), list_f32_builder(n));
    let (mut g, mut top, mut slope, mut cover) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut npts, mut pd, mut bd, mut scan, mut cov) = (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut off_id, mut off_dx, mut off_dy, mut off_dz) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (k, (fp, r)) in footprints.iter().zip(results).enumerate() {
        let off = applied.get(k).and_then(|o| o.as_ref());
        for &w in weightings {
            off_id.push(off.map(|o| o.segment_id.clone()));
            off_dx.push(off.map(|o| o.dx));
            off_dy.push(off.map(|o| o.dy));
            off_dz.push(off.map(|o| o.dz));
            id.push(fp.id.clone());
            x.push(fp.x);
            y.push(fp.y);
            wname.push(w.name());
            st.push(status(r));
            match r {
                Ok(s) => {
                    let ww = s.get(w);
                    z0.push(Some(s.z0));
                    dz.push(Some(s.dz));
                    wave.append_value(ww.wave.iter().map(|&v| Some(v)));
                    ground.append_value(ww.ground.iter().map(|&v| Some(v)));
                    canopy.append_value(ww.canopy.iter().map(|&v| Some(v)));
                    match &ww.rh {
                        Some(r) => rh.append_value(r.iter().map(|&v| Some(v))),
                        None => rh.append_null(),
                    }
                    g.push(ww.truth.als_ground);
                    top.push(ww.truth.true_top);
                    slope.push(ww.truth.slope_deg.map(f64::from));
                    cover.push((ww.truth.als_cover >= 0.0).then_some(ww.truth.als_cover as f64));
                    npts.push(Some(s.n_points));
                    pd.push(Some(s.densities.point));
                    bd.push(Some(s.densities.beam));
                    scan.push(Some(s.mean_scan_angle_deg));
                    cov.push(Some(s.covered_fraction));
                }
                Err(reason) => {
                    z0.push(None);
                    dz.push(None);
                    wave.append_null();
                    ground.append_null();
                    canopy.append_null();
                    rh.append_null();
                    g.push(None);
                    top.push(None);
                    slope.push(None);
                    cover.push(None);
                    npts.push(None);
                    pd.push(None);
                    bd.push(None);
                    scan.push(None);
                    cov.push(match reason {
                        SkipReason::PartlyCovered { covered_fraction } => Some(*covered_fraction),
                        _ => None,
                    });
                }
            }
        }
    }
    let cols: Vec<ArrayRef> = vec![
        Arc::new(StringArray::from(id)),
        Arc::new(Float64Array::from(x)),
        Arc::new(Float64Array::from(y)),
        Arc::new(StringArray::from(wname)),
        Arc::new(StringArray::from(st)),
        Arc::new(Float64Array::from(z0)),
        Arc::new(Float64Array::from(dz)),
        Arc::new(wave.finish()),
        Arc::new(ground.finish()),
        Arc::new(canopy.finish()),
        Arc::new(Float64Array::from(g)),
        Arc::new(Float64Array::from(top)),
        Arc::new(Float64Array::from(slope)),
        Arc::new(Float64Array::from(cover)),
        Arc::new(UInt32Array::from(npts)),
        Arc::new(Float32Array::from(pd)),
        Arc::new(Float32Array::from(bd)),
        Arc::new(Float32Array::from(scan)),
        Arc::new(Float32Array::from(cov)),
        Arc::new(rh.finish()),
        Arc::new(StringArray::from(off_id)),
        Arc::new(Float64Array::from(off_dx)),
        Arc::new(Float64Array::from(off_dy)),
        Arc::new(Float64Array::from(off_dz)),
    ];
    RecordBatch::try_new(sim_schema(), cols).map_err(|e| Error::Usage(format!("sim table: {e}")))
}
