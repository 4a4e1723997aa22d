//! `gedisim l2a`: GEDI L2A (algorithms a1–a6) re-run on every waveform of an L1B granule, one row
//! per shot × algorithm written to a Parquet file (docs/l2a.md); or on a table of shots (the
//! Python API's `gedisim.l2a(table)`), the same rows returned.

use std::path::Path;
use std::sync::Arc;

use arrow::array::{Array, ArrayRef, AsArray, RecordBatch, StringArray, UInt64Array, UInt8Array};
use arrow::datatypes::{DataType, Float32Type};
use rayon::prelude::*;

use crate::dataset::l2a::{l2a_schema, status_text, L2aColumns};
use crate::dataset::read::{cast_columns, Columns};
use crate::dataset::shots::{col, shots_schema};
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
    let settings = algorithm_settings(algorithms)?;
    let mut writer = l2a_writer(out)?;
    let mut rows = 0;
    let report = ingest_gedi(std::slice::from_ref(&l1b.to_path_buf()), &[], &GediOptions::default(), |shots| {
        let batch = l2a_batch(&shots, &settings, l1b)?;
        rows += batch.num_rows();
        writer.write(&batch)
    })?;
    writer.finish()?;
    Ok(L2aReport { shots: report.rows(), rows, warnings: report.warnings() })
}

/// The `l2a` rows of the `algorithms` (1..6) on the waveforms of `shots`, a table with the L1B
/// columns of `shots/` (docs/schemas.md: shot_number, beam, rx_waveform, the corrected noise
/// statistics, the elevations and positions of the first and last samples), cast to their types;
/// `source` names it in errors. Rows without `elevation_bin0` (no L1B) are skipped, as in [`l2a`].
/// With `out`, the rows are also written there as [`l2a`] writes them (atomically).
pub fn l2a_of_shots(
    shots: &[RecordBatch],
    algorithms: &[u8],
    source: &Path,
    out: Option<&Path>,
) -> Result<Vec<RecordBatch>> {
    let settings = algorithm_settings(algorithms)?;
    // The columns' types (the EPSG code only names the CRS of x, y in the schema's metadata).
    let schema = shots_schema(0);
    let rows = shots
        .iter()
        .map(|b| l2a_batch(&cast_columns(source, b, &schema, &L1B_COLUMNS, &[])?, &settings, source))
        .collect::<Result<Vec<_>>>()?;
    if let Some(out) = out {
        let mut writer = l2a_writer(out)?;
        rows.iter().try_for_each(|b| writer.write(b))?;
        writer.finish()?;
    }
    Ok(rows)
}

/// The `l2a` file `out`, written under a temporary name until it is finished.
fn l2a_writer(out: &Path) -> Result<AtomicParquet> {
    AtomicParquet::create(out, l2a_schema(), writer_properties(&Default::default(), 1 << 16))
}

/// The `--algorithms`' settings, each algorithm once.
fn algorithm_settings(algorithms: &[u8]) -> Result<Vec<AlgorithmSettings>> {
    if let Some(n) = algorithms.iter().enumerate().find_map(|(i, n)| algorithms[..i].contains(n).then_some(n)) {
        return Err(Error::Usage(format!("--algorithms: {n} given twice (each algorithm's rows once)")));
    }
    algorithms
        .iter()
        .map(|&n| {
            AlgorithmSettings::gedi(n)
                .ok_or_else(|| Error::Usage(format!("--algorithms: {n} is not a GEDI algorithm (1..6)")))
        })
        .collect()
}

/// The columns of `shots/` that the L2A of a waveform reads.
const L1B_COLUMNS: [&str; 11] = [
    col::SHOT_NUMBER,
    col::BEAM,
    col::RX_WAVEFORM,
    col::NOISE_MEAN_CORRECTED,
    col::NOISE_STDDEV_CORRECTED,
    col::ELEVATION_BIN0,
    col::ELEVATION_LASTBIN,
    col::LAT_BIN0,
    col::LAT_LASTBIN,
    col::LON_BIN0,
    col::LON_LASTBIN,
];

/// Run the L2A kernel with `settings` on every shot of a `shots` batch that has L1B columns (rows
/// without are skipped), shots in parallel. A shot the kernel cannot process, or whose waveform
/// ingest nulled, keeps its rows with `status` = `no_result: <reason>` and null values.
fn l2a_batch(shots: &RecordBatch, settings: &[AlgorithmSettings], source: &Path) -> Result<RecordBatch> {
    let c = Columns::new(source, shots);
    let (sn, beam, waves) = (c.u64s(col::SHOT_NUMBER)?, c.strings(col::BEAM)?, c.lists(col::RX_WAVEFORM)?);
    let (mean, sd) = (c.f64s(col::NOISE_MEAN_CORRECTED)?, c.f64s(col::NOISE_STDDEV_CORRECTED)?);
    let (z0, zn) = (c.f64s(col::ELEVATION_BIN0)?, c.f64s(col::ELEVATION_LASTBIN)?);
    let (la0, lan) = (c.f64s(col::LAT_BIN0)?, c.f64s(col::LAT_LASTBIN)?);
    let (lo0, lon) = (c.f64s(col::LON_BIN0)?, c.f64s(col::LON_LASTBIN)?);
    if waves.value_type() != DataType::Float32 {
        return Err(Error::field(source, col::RX_WAVEFORM, format!("a list of {}, not float32", waves.value_type())));
    }
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
