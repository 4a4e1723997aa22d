//! `gedi_l2a` in SQL: `queries/l2a_real.sql` run by `gedisim sql` on ingested real shots gives,
//! row for row, exactly what `gedisim l2a` writes for the same L1B file; and bad waveforms give a
//! struct with a reason, never an error or a panic.

mod common;

use std::collections::HashMap;
use std::fs::File;
use std::sync::Arc;

use arrow::array::{Array, AsArray, Float32Builder, Float64Array, ListBuilder, RecordBatch};
use arrow::datatypes::{DataType, Field, Float32Type, Float64Type, Schema, UInt64Type, UInt8Type};
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;

use common::{data, gedisim};
use gedisim::dataset::{self, Dataset};
use gedisim::ops::sql::SqlSession;
use gedisim::sql::Engine;

const L1B: &str = "gedi/GEDI01_B_2019108080338_O01964_T05337_02_003_01_sub.h5";
const L2A: &str = "gedi/GEDI02_A_2019108080338_O01964_T05337_02_001_01_sub.h5";

fn read(path: &std::path::Path) -> Vec<RecordBatch> {
    ParquetRecordBatchReaderBuilder::try_new(File::open(path).unwrap())
        .unwrap()
        .build()
        .unwrap()
        .map(|b| b.unwrap())
        .collect()
}

/// One L2A row as comparable values: status, toploc, botloc, zcross, elev_lowestmode, rh,
/// sensitivity, energy_total, num_modes (floats as bits: equality is exact).
type Row = (
    Option<String>,
    Option<u64>,
    Option<u64>,
    Option<u64>,
    Option<u64>,
    Option<Vec<u32>>,
    Option<u32>,
    Option<u32>,
    Option<u8>,
);

fn rows_by_key(batches: &[RecordBatch], reason_col: &str) -> HashMap<(u64, u8), Row> {
    let mut out = HashMap::new();
    for b in batches {
        let c = |n: &str| b.column_by_name(n).unwrap_or_else(|| panic!("column {n}"));
        let sn = c("shot_number").as_primitive::<UInt64Type>();
        let alg = c("algorithm").as_primitive::<UInt8Type>();
        let reason = c(reason_col).as_string::<i32>();
        let f64s = |n: &str| c(n).as_primitive::<Float64Type>().clone();
        let (top, bot, zc, elev) = (f64s("toploc"), f64s("botloc"), f64s("zcross"), f64s("elev_lowestmode"));
        let rh = c("rh").as_list::<i32>();
        let sens = c("sensitivity").as_primitive::<Float32Type>();
        let energy = c("energy_total").as_primitive::<Float32Type>();
        let modes = c("num_modes").as_primitive::<UInt8Type>();
        let f = |a: &Float64Array, i: usize| (!a.is_null(i)).then(|| a.value(i).to_bits());
        for i in 0..b.num_rows() {
            // The CLI says "ok" / "no_result: <reason>", the struct null / "<reason>".
            let status = (!reason.is_null(i)).then(|| reason.value(i).trim_start_matches("no_result: ").to_string());
            let status = status.filter(|s| s != "ok");
            let row: Row = (
                status,
                f(&top, i),
                f(&bot, i),
                f(&zc, i),
                f(&elev, i),
                (!rh.is_null(i))
                    .then(|| rh.value(i).as_primitive::<Float32Type>().values().iter().map(|v| v.to_bits()).collect()),
                (!sens.is_null(i)).then(|| sens.value(i).to_bits()),
                (!energy.is_null(i)).then(|| energy.value(i).to_bits()),
                (!modes.is_null(i)).then(|| modes.value(i)),
            );
            assert!(out.insert((sn.value(i), alg.value(i)), row).is_none(), "duplicate row");
        }
    }
    out
}

#[test]
fn l2a_real_sql_equals_the_cli_row_for_row() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = tmp.path().join("ds");
    let (l1b, l2a) = (data(L1B), data(L2A));
    let (ok, _, err) = gedisim(&[
        "ingest",
        "gedi",
        "--l1b",
        l1b.to_str().unwrap(),
        "--l2a",
        l2a.to_str().unwrap(),
        "--out",
        ds.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let query = concat!(env!("CARGO_MANIFEST_DIR"), "/queries/l2a_real.sql");
    let sql_out = tmp.path().join("sql.parquet");
    let (ok, _, err) =
        gedisim(&["sql", "--dataset", ds.to_str().unwrap(), "-f", query, "--out", sql_out.to_str().unwrap()]);
    assert!(ok, "{err}");
    let cli_out = tmp.path().join("cli.parquet");
    let (ok, _, err) = gedisim(&["l2a", "--l1b", l1b.to_str().unwrap(), "--out", cli_out.to_str().unwrap()]);
    assert!(ok, "{err}");

    let sql_batches = read(&sql_out);
    let sql = rows_by_key(&sql_batches, "no_result_reason");
    let cli = rows_by_key(&read(&cli_out), "status");
    assert_eq!(sql.len(), 300 * 6, "one row per shot with a waveform × algorithm");
    assert_eq!(cli.len(), sql.len());
    let mut ok_rows = 0;
    for (key, row) in &cli {
        let theirs = sql.get(key).unwrap_or_else(|| panic!("{key:?} missing from the SQL result"));
        assert_eq!(row, theirs, "shot {} a{}", key.0, key.1);
        ok_rows += usize::from(row.0.is_none());
    }
    assert_eq!(ok_rows, 1800, "every real shot is processed by every algorithm");

    // NASA's values sit beside ours: the query's comparison columns agree as validated elsewhere.
    let (mut rh_ok, mut rh_all) = (0usize, 0usize);
    for b in &sql_batches {
        let ours = b.column_by_name("rh").unwrap().as_list::<i32>();
        let nasa = b.column_by_name("nasa_rh").unwrap().as_list::<i32>();
        for i in 0..b.num_rows() {
            let (o, n) = (ours.value(i), nasa.value(i));
            let (o, n) = (o.as_primitive::<Float32Type>(), n.as_primitive::<Float32Type>());
            rh_all += o.len();
            rh_ok += o.values().iter().zip(n.values()).filter(|(a, b)| (*a - *b).abs() <= 0.15).count();
        }
    }
    let rate = rh_ok as f64 / rh_all as f64;
    println!("l2a_real.sql: 1800 rows equal to `gedisim l2a`; RH within 0.15 m of NASA: {:.2} %", 100.0 * rate);
    assert!(rate >= 0.99, "{rate}");
}

/// A session on a dataset holding one table `waves(id, wave, mean, sd)`.
fn session_with(waves: Vec<Option<Vec<Option<f32>>>>, noise: &[(f64, f64)]) -> (tempfile::TempDir, Dataset) {
    let tmp = tempfile::tempdir().unwrap();
    let ds = Dataset::create(tmp.path()).unwrap();
    let mut list = ListBuilder::new(Float32Builder::new());
    for w in &waves {
        list.append_option(w.clone());
    }
    let schema = Arc::new(Schema::new(vec![
        Field::new("id", DataType::Int64, false),
        Field::new("wave", gedisim::dataset::list_f32(), true),
        Field::new("mean", DataType::Float64, false),
        Field::new("sd", DataType::Float64, false),
    ]));
    let batch = RecordBatch::try_new(
        schema.clone(),
        vec![
            Arc::new(arrow::array::Int64Array::from((0..waves.len() as i64).collect::<Vec<_>>())),
            Arc::new(list.finish()),
            Arc::new(Float64Array::from(noise.iter().map(|n| n.0).collect::<Vec<_>>())),
            Arc::new(Float64Array::from(noise.iter().map(|n| n.1).collect::<Vec<_>>())),
        ],
    )
    .unwrap();
    dataset::write_parquet(&ds.table_file("waves", "test").unwrap(), schema, &[batch], &Default::default()).unwrap();
    (tmp, ds)
}

fn query(ds: &Dataset, sql: &str) -> Result<Vec<RecordBatch>, String> {
    let session = SqlSession::open(ds.root(), &Default::default(), &Engine::Local).map_err(|e| e.to_string())?;
    session.collect(sql).map_err(|e| e.to_string())
}

#[test]
fn bad_waveforms_give_a_reason_in_the_struct() {
    let signal: Vec<Option<f32>> =
        (0..400).map(|i| Some(200.0 + 300.0 * (-0.5 * ((i as f32 - 200.0) / 5.0).powi(2)).exp())).collect();
    let mut with_nan = signal.clone();
    with_nan[17] = Some(f32::NAN);
    let mut with_null = signal.clone();
    with_null[5] = None;
    // All noise: a constant record at the mean (nothing crosses any threshold).
    let all_noise = vec![Some(200.0f32); 400];
    let waves =
        vec![Some(signal.clone()), Some(vec![]), Some(with_nan), Some(with_null), Some(all_noise), Some(signal), None];
    let noise = [(200.0, 3.0), (200.0, 3.0), (200.0, 3.0), (200.0, 3.0), (200.0, 3.0), (200.0, 0.0), (200.0, 3.0)];
    let (_tmp, ds) = session_with(waves, &noise);
    let batches = query(
        &ds,
        "select id, gedi_l2a(wave, mean, sd, 1) as r, gedi_l2a(wave, mean, sd, 5, 100.0, 40.15)['elev_lowestmode'] \
        as e \
         from waves order by id",
    )
    .unwrap();
    let b = &batches[0];
    let r = b.column_by_name("r").unwrap().as_struct();
    let reason = r.column_by_name("no_result_reason").unwrap().as_string::<i32>();
    let rh = r.column_by_name("rh").unwrap().as_list::<i32>();
    let zcross = r.column_by_name("zcross").unwrap().as_primitive::<Float64Type>();
    let elev = b.column_by_name("e").unwrap().as_primitive::<Float64Type>();
    let reasons: Vec<Option<&str>> = (0..b.num_rows()).map(|i| (!reason.is_null(i)).then(|| reason.value(i))).collect();
    assert_eq!(
        reasons,
        vec![
            None,
            Some("empty waveform"),
            Some("non-finite sample at index 17"),
            Some("non-finite sample at index 5"),
            Some("no signal above the thresholds"),
            Some("invalid noise statistics (mean not finite or stddev not > 0)"),
            None,
        ]
    );
    // The good waveform: ground at sample 200, RH in metres on the 1 ns grid.
    assert!(!r.is_null(0) && (zcross.value(0) - 200.0).abs() <= 0.25);
    assert_eq!(rh.value(0).len(), 101);
    assert!(!elev.is_null(0) && (elev.value(0) - (100.0 - 200.0 * 0.15)).abs() < 0.1);
    // A no-result row is a struct with null values; a null waveform gives a null struct.
    assert!(!r.is_null(1) && zcross.is_null(1) && rh.is_null(1));
    assert!(r.is_null(6));

    // Elevations that are not finite: a reason, not an error.
    let b =
        &query(&ds, "select gedi_l2a(wave, mean, sd, 1, 'NaN'::double, 40.0) as r from waves order by id").unwrap()[0];
    let r = b.column_by_name("r").unwrap().as_struct();
    let reason = r.column_by_name("no_result_reason").unwrap().as_string::<i32>();
    assert_eq!(reason.value(0), "elevation of the first or last sample is not finite");

    // An algorithm outside 1..6 is a one-line query error naming the function.
    let err = query(&ds, "select gedi_l2a(wave, mean, sd, 7) from waves").unwrap_err();
    assert!(err.contains("gedi_l2a: algorithm must be 1..6, got 7") && !err.contains('\n'), "{err}");
    let err = query(&ds, "select gedi_l2a(wave, mean, sd) from waves").unwrap_err();
    assert!(err.contains("4 or 6 arguments"), "{err}");
}
