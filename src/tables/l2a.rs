//! The `l2a` table: one row per shot × algorithm (the `gedisim l2a` contract, CONTRACTS.md), from
//! the L1B waveforms of the `shots` schema through the L2A kernel.

use std::sync::Arc;

use arrow::array::{Array, ArrayRef, AsArray, Float32Array, Float64Array, RecordBatch, StringArray, UInt64Array, UInt8Array};
use arrow::datatypes::{DataType, Field, Float32Type, Float64Type, Schema, SchemaRef, UInt64Type};
use rayon::prelude::*;

use super::{list_f32, list_f32_builder};
use crate::error::{Error, Result};
use crate::process::l2a::{AlgorithmSettings, L2aOutcome, L2aProcessor, Noise, WaveformGeolocation};

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

/// Run the L2A kernel with `settings` on every shot of a `shots` batch that has a waveform (rows
/// without L1B columns are skipped), shots in parallel. A shot the kernel cannot process keeps
/// its rows with `status` = `no_result: <reason>` and null values.
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
    let rows: Vec<usize> = (0..shots.num_rows()).filter(|&i| !waves.is_null(i)).collect();
    let outcomes: Vec<(usize, Vec<L2aOutcome>, WaveformGeolocation)> = rows
        .par_iter()
        .map_init(L2aProcessor::new, |proc, &i| {
            let w = waves.value(i);
            let w = w.as_primitive::<Float32Type>();
            let geo = WaveformGeolocation {
                sample_count: w.len(),
                elevation_bin0: z0.value(i),
                elevation_lastbin: zn.value(i),
                latitude_bin0: la0.value(i),
                latitude_lastbin: lan.value(i),
                longitude_bin0: lo0.value(i),
                longitude_lastbin: lon.value(i),
            };
            let noise = Noise { mean: mean.value(i), stddev: sd.value(i) };
            let mut out = Vec::with_capacity(settings.len());
            proc.process_all(w.values(), noise, &geo, settings, &mut out);
            (i, out, geo)
        })
        .collect();
    let n = outcomes.len() * settings.len();
    let (mut o_sn, mut o_beam, mut o_alg, mut o_status) = (Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n));
    let (mut top, mut bot, mut zc, mut elev, mut elev_top, mut lat, mut lon_) = (vec![], vec![], vec![], vec![], vec![], vec![], vec![]);
    let (mut sens, mut energy, mut modes) = (vec![], vec![], vec![]);
    let mut rh = list_f32_builder(n);
    for (i, outs, geo) in &outcomes {
        for (s, o) in settings.iter().zip(outs) {
            o_sn.push(sn.value(*i));
            o_beam.push(beam.value(*i).to_string());
            o_alg.push(s.id);
            match o {
                Ok(r) => {
                    o_status.push("ok".to_string());
                    top.push(Some(r.toploc));
                    bot.push(Some(r.botloc));
                    zc.push(Some(r.zcross));
                    elev.push(Some(r.elev_lowestmode));
                    elev_top.push(Some(r.elev_highestreturn));
                    lat.push(Some(geo.latitude_at(r.zcross)));
                    lon_.push(Some(geo.longitude_at(r.zcross)));
                    rh.append_value(r.rh.iter().map(|&v| Some(v as f32)));
                    sens.push(Some(r.sensitivity as f32));
                    energy.push(Some(r.energy_total as f32));
                    modes.push(Some(r.num_modes as u8));
                }
                Err(reason) => {
                    o_status.push(format!("no_result: {reason}"));
                    for v in [&mut top, &mut bot, &mut zc, &mut elev, &mut elev_top, &mut lat, &mut lon_] {
                        v.push(None);
                    }
                    rh.append_null();
                    sens.push(None);
                    energy.push(None);
                    modes.push(None);
                }
            }
        }
    }
    let cols: Vec<ArrayRef> = vec![
        Arc::new(UInt64Array::from(o_sn)),
        Arc::new(StringArray::from(o_beam)),
        Arc::new(UInt8Array::from(o_alg)),
        Arc::new(StringArray::from(o_status)),
        Arc::new(Float64Array::from(top)),
        Arc::new(Float64Array::from(bot)),
        Arc::new(Float64Array::from(zc)),
        Arc::new(Float64Array::from(elev)),
        Arc::new(Float64Array::from(elev_top)),
        Arc::new(Float64Array::from(lat)),
        Arc::new(Float64Array::from(lon_)),
        Arc::new(rh.finish()),
        Arc::new(Float32Array::from(sens)),
        Arc::new(Float32Array::from(energy)),
        Arc::new(UInt8Array::from(modes)),
    ];
    RecordBatch::try_new(l2a_schema(), cols).map_err(|e| Error::table(source, e))
}
