//! The `l2a` table: one row per shot × algorithm (the `gedisim l2a` contract, docs/contracts.md), and
//! the columns of one L2A outcome that the table (`crate::ops::l2a` runs the kernel) and the
//! `gedi_l2a` SQL struct share.

use std::sync::Arc;

use arrow::array::{ArrayRef, Float32Array, Float32Builder, Float64Array, ListBuilder, StringArray, UInt8Array};
use arrow::datatypes::{DataType, Field, Fields, Schema, SchemaRef};

use super::{list_f32, list_f32_builder};
use crate::error::Result;
use crate::kernels::waveform::l2a::{L2aOutcome, WaveformGeolocation};

/// The names of the `l2a` table's columns (docs/schemas.md), one constant each.
pub mod col {
    pub const SHOT_NUMBER: &str = "shot_number";
    pub const BEAM: &str = "beam";
    pub const ALGORITHM: &str = "algorithm";
    pub const STATUS: &str = "status";
    pub const TOPLOC: &str = "toploc";
    pub const BOTLOC: &str = "botloc";
    pub const ZCROSS: &str = "zcross";
    pub const ELEV_LOWESTMODE: &str = "elev_lowestmode";
    pub const ELEV_HIGHESTRETURN: &str = "elev_highestreturn";
    pub const LAT_LOWESTMODE: &str = "lat_lowestmode";
    pub const LON_LOWESTMODE: &str = "lon_lowestmode";
    pub const RH: &str = "rh";
    pub const SENSITIVITY: &str = "sensitivity";
    pub const ENERGY_TOTAL: &str = "energy_total";
    pub const NUM_MODES: &str = "num_modes";
}

/// Schema of the `l2a` table.
pub fn l2a_schema() -> SchemaRef {
    let f = |n: &str, t: DataType, null: bool| Field::new(n, t, null);
    Arc::new(Schema::new(vec![
        f(col::SHOT_NUMBER, DataType::UInt64, false),
        f(col::BEAM, DataType::Utf8, false),
        f(col::ALGORITHM, DataType::UInt8, false),
        f(col::STATUS, DataType::Utf8, false),
        f(col::TOPLOC, DataType::Float64, true),
        f(col::BOTLOC, DataType::Float64, true),
        f(col::ZCROSS, DataType::Float64, true),
        f(col::ELEV_LOWESTMODE, DataType::Float64, true),
        f(col::ELEV_HIGHESTRETURN, DataType::Float64, true),
        f(col::LAT_LOWESTMODE, DataType::Float64, true),
        f(col::LON_LOWESTMODE, DataType::Float64, true),
        f(col::RH, list_f32(), true),
        f(col::SENSITIVITY, DataType::Float32, true),
        f(col::ENERGY_TOTAL, DataType::Float32, true),
        f(col::NUM_MODES, DataType::UInt8, true),
    ]))
}

/// The struct field of `gedi_l2a` that says why a waveform gave no result (the table's `status`).
pub const NO_RESULT_REASON: &str = "no_result_reason";

/// Fields of the struct returned by the `gedi_l2a` SQL function, in order. Types are those of the
/// same columns of the `l2a` table, so that both give identical values.
pub fn l2a_struct_fields() -> Fields {
    let f = |n: &str, t: DataType| Field::new(n, t, true);
    Fields::from(vec![
        f(col::TOPLOC, DataType::Float64),
        f(col::BOTLOC, DataType::Float64),
        f(col::ZCROSS, DataType::Float64),
        f(col::ELEV_LOWESTMODE, DataType::Float64),
        f(col::RH, list_f32()),
        f(col::SENSITIVITY, DataType::Float32),
        f(col::ENERGY_TOTAL, DataType::Float32),
        f(col::NUM_MODES, DataType::UInt8),
        f(NO_RESULT_REASON, DataType::Utf8),
    ])
}

/// The text of an outcome's `status` (`l2a` table): `ok` or `no_result: <reason>`.
pub fn status_text(outcome: &L2aOutcome) -> String {
    match outcome {
        Ok(_) => "ok".to_string(),
        Err(reason) => format!("no_result: {reason}"),
    }
}

/// Column builders for L2A outcomes: one row per outcome; every value is null for a row without
/// a result (and for a null input row).
pub struct L2aColumns {
    toploc: Vec<Option<f64>>,
    botloc: Vec<Option<f64>>,
    zcross: Vec<Option<f64>>,
    elev_lowestmode: Vec<Option<f64>>,
    elev_highestreturn: Vec<Option<f64>>,
    lat_lowestmode: Vec<Option<f64>>,
    lon_lowestmode: Vec<Option<f64>>,
    rh: ListBuilder<Float32Builder>,
    sensitivity: Vec<Option<f32>>,
    energy_total: Vec<Option<f32>>,
    num_modes: Vec<Option<u8>>,
    reason: Vec<Option<String>>,
    valid: Vec<bool>,
}

impl L2aColumns {
    /// Empty builders with room for `capacity` rows.
    pub fn with_capacity(capacity: usize) -> Self {
        let v = || Vec::with_capacity(capacity);
        Self {
            toploc: v(),
            botloc: v(),
            zcross: v(),
            elev_lowestmode: v(),
            elev_highestreturn: v(),
            lat_lowestmode: v(),
            lon_lowestmode: v(),
            rh: list_f32_builder(capacity),
            sensitivity: Vec::with_capacity(capacity),
            energy_total: Vec::with_capacity(capacity),
            num_modes: Vec::with_capacity(capacity),
            reason: Vec::with_capacity(capacity),
            valid: Vec::with_capacity(capacity),
        }
    }

    /// One row for `outcome` on a waveform geolocated by `geo`. `absolute` says whether `geo`
    /// carries real elevations (otherwise elevations are null; RH only needs the spacing).
    pub fn append(&mut self, outcome: &L2aOutcome, geo: &WaveformGeolocation, absolute: bool) {
        self.valid.push(true);
        match outcome {
            Ok(r) => {
                let known = |v: f64| (absolute && v.is_finite()).then_some(v);
                self.toploc.push(Some(r.toploc));
                self.botloc.push(Some(r.botloc));
                self.zcross.push(Some(r.zcross));
                self.elev_lowestmode.push(known(r.elev_lowestmode));
                self.elev_highestreturn.push(known(r.elev_highestreturn));
                self.lat_lowestmode.push(known(geo.latitude_at(r.zcross)));
                self.lon_lowestmode.push(known(geo.longitude_at(r.zcross)));
                self.rh.append_value(r.rh.iter().map(|&v| Some(v as f32)));
                self.sensitivity.push(Some(r.sensitivity as f32));
                self.energy_total.push(Some(r.energy_total as f32));
                self.num_modes.push(Some(r.num_modes as u8));
                self.reason.push(None);
            }
            Err(reason) => {
                self.push_nulls();
                self.reason.push(Some(reason.to_string()));
            }
        }
    }

    /// A null row (null input).
    pub fn append_null(&mut self) {
        self.valid.push(false);
        self.push_nulls();
        self.reason.push(None);
    }

    fn push_nulls(&mut self) {
        for v in [
            &mut self.toploc,
            &mut self.botloc,
            &mut self.zcross,
            &mut self.elev_lowestmode,
            &mut self.elev_highestreturn,
            &mut self.lat_lowestmode,
            &mut self.lon_lowestmode,
        ] {
            v.push(None);
        }
        self.rh.append_null();
        self.sensitivity.push(None);
        self.energy_total.push(None);
        self.num_modes.push(None);
    }

    /// The columns of the `l2a` table after its keys and `status` ([`l2a_schema`]).
    pub fn finish_table_columns(mut self) -> Vec<ArrayRef> {
        vec![
            Arc::new(Float64Array::from(self.toploc)),
            Arc::new(Float64Array::from(self.botloc)),
            Arc::new(Float64Array::from(self.zcross)),
            Arc::new(Float64Array::from(self.elev_lowestmode)),
            Arc::new(Float64Array::from(self.elev_highestreturn)),
            Arc::new(Float64Array::from(self.lat_lowestmode)),
            Arc::new(Float64Array::from(self.lon_lowestmode)),
            Arc::new(self.rh.finish()),
            Arc::new(Float32Array::from(self.sensitivity)),
            Arc::new(Float32Array::from(self.energy_total)),
            Arc::new(UInt8Array::from(self.num_modes)),
        ]
    }

    /// The `gedi_l2a` struct column ([`l2a_struct_fields`]); null rows are null structs.
    pub fn finish_struct(mut self) -> Result<arrow::array::StructArray, arrow::error::ArrowError> {
        let arrays: Vec<ArrayRef> = vec![
            Arc::new(Float64Array::from(self.toploc)),
            Arc::new(Float64Array::from(self.botloc)),
            Arc::new(Float64Array::from(self.zcross)),
            Arc::new(Float64Array::from(self.elev_lowestmode)),
            Arc::new(self.rh.finish()),
            Arc::new(Float32Array::from(self.sensitivity)),
            Arc::new(Float32Array::from(self.energy_total)),
            Arc::new(UInt8Array::from(self.num_modes)),
            Arc::new(StringArray::from(self.reason)),
        ];
        let nulls = self.valid.iter().any(|v| !v).then(|| self.valid.into());
        arrow::array::StructArray::try_new(l2a_struct_fields(), arrays, nulls)
    }
}
