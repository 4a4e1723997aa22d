//! The `l2a` table: one row per shot × algorithm (the `gedisim l2a` contract, docs/contracts.md), from
//! the L1B waveforms of the `shots` schema through the L2A kernel, and the columns of one L2A
//! outcome that the CLI table and the `gedi_l2a` SQL struct share.

use std::sync::Arc;

use arrow::array::{
    Array, ArrayRef, AsArray, Float32Array, Float32Builder, Float64Array, ListBuilder, RecordBatch, StringArray,
    UInt64Array, UInt8Array,
};
use arrow::datatypes::{DataType, Field, Fields, Float32Type, Float64Type, Schema, SchemaRef, UInt64Type};
use rayon::prelude::*;

use super::{list_f32, list_f32_builder};
use crate::error::{Error, Result};
use crate::kernels::waveform::l2a::{
    AlgorithmSettings, L2aOutcome, L2aProcessor, NoResult, Noise, WaveformGeolocation,
};

/// Schema of the `l2a` table.
pub fn l2a_schema() -> SchemaRef {
    let f = |n: &str, t: DataType, null: bool| Field::new(n, t, null);
    Arc::new(Schema::new(vec![
        f("shot_number", DataType::UInt64, false),
        f("beam", DataType::Utf8, false),
        f("algorithm", DataType::UInt8, false),
        f("status", DataType::Utf8, false),
        f("toploc", DataType::Float64, true),
        f("botloc", DataType::Float64, true),
        f("zcross", DataType::Float64, true),
        f("elev_lowestmode", DataType::Float64, true),
        f("elev_highestreturn", DataType::Float64, true),
        f("lat_lowestmode", DataType::Float64, true),
        f("lon_lowestmode", DataType::Float64, true),
        f("rh", list_f32(), true),
        f("sensitivity", DataType::Float32, true),
        f("energy_total", DataType::Float32, true),
        f("num_modes", DataType::UInt8, true),
    ]))
}

/// Fields of the struct returned by the `gedi_l2a` SQL function, in order. Types are those of the
/// same columns of the `l2a` table, so that both give identical values.
pub fn l2a_struct_fields() -> Fields {
    let f = |n: &str, t: DataType| Field::new(n, t, true);
    Fields::from(vec![
        f("toploc", DataType::Float64),
        f("botloc", DataType::Float64),
        f("zcross", DataType::Float64),
        f("elev_lowestmode", DataType::Float64),
        f("rh", list_f32()),
        f("sensitivity", DataType::Float32),
        f("energy_total", DataType::Float32),
        f("num_modes", DataType::UInt8),
        f("no_result_reason", DataType::Utf8),
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

/// Run the L2A kernel with `settings` on every shot of a `shots` batch that has L1B columns (rows
/// without are skipped), shots in parallel. A shot the kernel cannot process, or whose waveform
/// ingest nulled, keeps its rows with `status` = `no_result: <reason>` and null values.
pub fn l2a_batch(shots: &RecordBatch, settings: &[AlgorithmSettings], source: &std::path::Path) -> Result<RecordBatch> {
    let col = |n: &str| shots.column_by_name(n).ok_or_else(|| Error::field(source, n, "column missing"));
    let sn = col("shot_number")?.as_primitive::<UInt64Type>().clone();
    let beam = col("beam")?.as_string::<i32>().clone();
    let waves = col("rx_waveform")?.as_list::<i32>().clone();
    let f64c = |n: &str| -> Result<Float64Array> { Ok(col(n)?.as_primitive::<Float64Type>().clone()) };
    let (mean, sd) = (f64c("noise_mean_corrected")?, f64c("noise_stddev_corrected")?);
    let (z0, zn) = (f64c("elevation_bin0")?, f64c("elevation_lastbin")?);
    let (la0, lan) = (f64c("lat_bin0")?, f64c("lat_lastbin")?);
    let (lo0, lon) = (f64c("lon_bin0")?, f64c("lon_lastbin")?);
    let l1b_rows: Vec<usize> = (0..shots.num_rows()).filter(|&i| !z0.is_null(i)).collect();
    let outcomes: Vec<(usize, Vec<L2aOutcome>, WaveformGeolocation)> = l1b_rows
        .par_iter()
        .map_init(L2aProcessor::new, |proc, &i| {
            let w = if waves.is_null(i) { None } else { Some(waves.value(i)) };
            let w = w.as_ref().map(|w| w.as_primitive::<Float32Type>());
            let geo = WaveformGeolocation {
                sample_count: w.map_or(0, |w| w.len()),
                elevation_bin0: z0.value(i),
                elevation_lastbin: zn.value(i),
                latitude_bin0: la0.value(i),
                latitude_lastbin: lan.value(i),
                longitude_bin0: lo0.value(i),
                longitude_lastbin: lon.value(i),
            };
            let noise = Noise { mean: mean.value(i), stddev: sd.value(i) };
            let mut out = Vec::with_capacity(settings.len());
            match w {
                Some(w) => proc.process_all(w.values(), noise, &geo, settings, &mut out),
                None => out.extend(settings.iter().map(|_| Err(NoResult::NoWaveform))),
            }
            (i, out, geo)
        })
        .collect();
    let n = outcomes.len() * settings.len();
    let (mut o_sn, mut o_beam, mut o_alg, mut o_status) =
        (Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n));
    let mut c = L2aColumns::with_capacity(n);
    for (i, outs, geo) in &outcomes {
        for (s, o) in settings.iter().zip(outs) {
            o_sn.push(sn.value(*i));
            o_beam.push(beam.value(*i).to_string());
            o_alg.push(s.id);
            o_status.push(status_text(o));
            c.append(o, geo, true);
        }
    }
    let cols: Vec<ArrayRef> = vec![
        Arc::new(UInt64Array::from(o_sn)),
        Arc::new(StringArray::from(o_beam)),
        Arc::new(UInt8Array::from(o_alg)),
        Arc::new(StringArray::from(o_status)),
        Arc::new(Float64Array::from(c.toploc)),
        Arc::new(Float64Array::from(c.botloc)),
        Arc::new(Float64Array::from(c.zcross)),
        Arc::new(Float64Array::from(c.elev_lowestmode)),
        Arc::new(Float64Array::from(c.elev_highestreturn)),
        Arc::new(Float64Array::from(c.lat_lowestmode)),
        Arc::new(Float64Array::from(c.lon_lowestmode)),
        Arc::new(c.rh.finish()),
        Arc::new(Float32Array::from(c.sensitivity)),
        Arc::new(Float32Array::from(c.energy_total)),
        Arc::new(UInt8Array::from(c.num_modes)),
    ];
    RecordBatch::try_new(l2a_schema(), cols).map_err(|e| Error::table(source, e))
}
