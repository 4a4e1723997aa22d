//! `gedisim l2a`: GEDI L2A (algorithms a1–a6) re-run on every waveform of an L1B granule, one row
//! per shot × algorithm written to a Parquet file (docs/l2a.md).

use std::path::Path;
use std::sync::Arc;

use arrow::array::{Array, ArrayRef, AsArray, Float64Array, RecordBatch, StringArray, UInt64Array, UInt8Array};
use arrow::datatypes::{Float32Type, Float64Type, UInt64Type};
use rayon::prelude::*;

use crate::dataset::l2a::{l2a_schema, status_text, L2aColumns};
use crate::dataset::shots::col;
use crate::dataset::{writer_properties, AtomicParquet};
use crate::error::{Error, Result};
use crate::kernels::waveform::l2a::{
    AlgorithmSettings, L2aOutcome, L2aProcessor, NoResult, Noise, WaveformGeolocation,
};
use crate::ops::ingest_gedi::{ingest_gedi, GediOptions};

/// What `gedisim l2a` wrote.
#[derive(Debug, Clone)]
pub struct L2aReport {
    pub shots: usize,
    pub rows: usize,
    /// What reading the L1B found wrong (one line each, naming file, beam and count).
    pub warnings: Vec<String>,
}

/// Run the GEDI `algorithms` (1..6) on every waveform of `l1b` into `out` (atomically).
pub fn l2a(l1b: &Path, algorithms: &[u8], out: &Path) -> Result<L2aReport> {
    if let Some(n) = algorithms.iter().enumerate().find_map(|(i, n)| algorithms[..i].contains(n).then_some(n)) {
        return Err(Error::Usage(format!("--algorithms: {n} given twice (each algorithm's rows once)")));
    }
    let settings = algorithms
        .iter()
        .map(|&n| {
            AlgorithmSettings::gedi(n)
                .ok_or_else(|| Error::Usage(format!("--algorithms: {n} is not a GEDI algorithm (1..6)")))
        })
        .collect::<Result<Vec<_>>>()?;
    let mut writer = AtomicParquet::create(out, l2a_schema(), writer_properties(&Default::default(), 1 << 16))?;
    let mut rows = 0;
    let report = ingest_gedi(std::slice::from_ref(&l1b.to_path_buf()), &[], &GediOptions::default(), |shots| {
        let batch = l2a_batch(&shots, &settings, l1b)?;
        rows += batch.num_rows();
        writer.write(&batch)
    })?;
    writer.finish()?;
    Ok(L2aReport { shots: report.rows(), rows, warnings: report.warnings() })
}

/// Run the L2A kernel with `settings` on every shot of a `shots` batch that has L1B columns (rows
/// without are skipped), shots in parallel. A shot the kernel cannot process, or whose waveform
/// ingest nulled, keeps its rows with `status` = `no_result: <reason>` and null values.
fn l2a_batch(shots: &RecordBatch, settings: &[AlgorithmSettings], source: &Path) -> Result<RecordBatch> {
    let col = |n: &str| shots.column_by_name(n).ok_or_else(|| Error::field(source, n, "column missing"));
    let sn = col(col::SHOT_NUMBER)?.as_primitive::<UInt64Type>().clone();
    let beam = col(col::BEAM)?.as_string::<i32>().clone();
    let waves = col(col::RX_WAVEFORM)?.as_list::<i32>().clone();
    let f64c = |n: &str| -> Result<Float64Array> { Ok(col(n)?.as_primitive::<Float64Type>().clone()) };
    let (mean, sd) = (f64c(col::NOISE_MEAN_CORRECTED)?, f64c(col::NOISE_STDDEV_CORRECTED)?);
    let (z0, zn) = (f64c(col::ELEVATION_BIN0)?, f64c(col::ELEVATION_LASTBIN)?);
    let (la0, lan) = (f64c(col::LAT_BIN0)?, f64c(col::LAT_LASTBIN)?);
    let (lo0, lon) = (f64c(col::LON_BIN0)?, f64c(col::LON_LASTBIN)?);
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
    let mut cols: Vec<ArrayRef> = vec![
        Arc::new(UInt64Array::from(o_sn)),
        Arc::new(StringArray::from(o_beam)),
        Arc::new(UInt8Array::from(o_alg)),
        Arc::new(StringArray::from(o_status)),
    ];
    cols.extend(c.finish_table_columns());
    RecordBatch::try_new(l2a_schema(), cols).map_err(|e| Error::table(source, e))
}
