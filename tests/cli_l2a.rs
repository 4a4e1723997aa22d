//! `gedisim l2a` (the CLI contract) on the real V1 L1B file, checked against NASA's L2A values
//! as ingested in the `shots` table.

mod common;

use std::collections::HashMap;
use std::fs::File;

use arrow::array::{Array, AsArray};
use arrow::datatypes::{Float32Type, Float64Type, UInt64Type, UInt8Type};
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;

use common::{data, gedisim};

fn read(path: &std::path::Path) -> Vec<arrow::record_batch::RecordBatch> {
    ParquetRecordBatchReaderBuilder::try_new(File::open(path).unwrap())
        .unwrap()
        .build()
        .unwrap()
        .map(|b| b.unwrap())
        .collect()
}

#[test]
fn l2a_cli_rows_agree_with_nasa() {
    let tmp = tempfile::tempdir().unwrap();
    let l1b = data("gedi/GEDI01_B_2019108080338_O01964_T05337_02_003_01_sub.h5");
    let l2a = data("gedi/GEDI02_A_2019108080338_O01964_T05337_02_001_01_sub.h5");
    let out = tmp.path().join("l2a.parquet");
    let (ok, _, err) = gedisim(&["l2a", "--l1b", l1b.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert!(ok, "{err}");
    let (ok, _, err) =
        gedisim(&["l2a", "--l1b", l1b.to_str().unwrap(), "--out", out.to_str().unwrap(), "--algorithms", "7"]);
    assert!(!ok && err.contains("--algorithms"), "{err}");

    // NASA's values per (shot, algorithm), through our own ingest.
    let (batches, _) = gedisim::ops::ingest_gedi::read_gedi(&[l1b], &[l2a], &Default::default()).unwrap();
    let mut nasa: HashMap<(u64, u8), (f64, Vec<f32>)> = HashMap::new();
    for b in &batches {
        let sn = b.column_by_name("shot_number").unwrap().as_primitive::<UInt64Type>();
        for a in 1..=6u8 {
            let elev = b.column_by_name(&format!("elev_lowestmode_a{a}")).unwrap().as_primitive::<Float64Type>();
            let rh = b.column_by_name(&format!("rh_a{a}")).unwrap().as_list::<i32>();
            for i in 0..b.num_rows() {
                if !rh.is_null(i) && !elev.is_null(i) {
                    let r = rh.value(i);
                    nasa.insert((sn.value(i), a), (elev.value(i), r.as_primitive::<Float32Type>().values().to_vec()));
                }
            }
        }
    }

    let rows = read(&out);
    let n: usize = rows.iter().map(|b| b.num_rows()).sum();
    assert_eq!(n, 300 * 6, "one row per L1B shot × algorithm");
    let (mut rh_ok, mut rh_all, mut elev_ok, mut compared) = (0usize, 0usize, 0usize, 0usize);
    for b in &rows {
        let sn = b.column_by_name("shot_number").unwrap().as_primitive::<UInt64Type>();
        let alg = b.column_by_name("algorithm").unwrap().as_primitive::<UInt8Type>();
        let elev = b.column_by_name("elev_lowestmode").unwrap().as_primitive::<Float64Type>();
        let rh = b.column_by_name("rh").unwrap().as_list::<i32>();
        for i in 0..b.num_rows() {
            let Some((nasa_elev, nasa_rh)) = nasa.get(&(sn.value(i), alg.value(i))) else { continue };
            assert!(!rh.is_null(i), "every real shot has an L2A result");
            compared += 1;
            let ours = rh.value(i);
            for (a, b) in ours.as_primitive::<Float32Type>().values().iter().zip(nasa_rh) {
                rh_all += 1;
                rh_ok += ((a - b).abs() <= 0.15) as usize;
            }
            elev_ok += ((elev.value(i) - nasa_elev).abs() <= 0.5 * 0.1499) as usize;
        }
    }
    let (rh_rate, elev_rate) = (rh_ok as f64 / rh_all as f64, elev_ok as f64 / compared as f64);
    println!(
        "gedisim l2a vs NASA: {compared} shot-algorithms, RH within 0.15 m {:.1} %, ground within ½ sample {:.1} %",
        100.0 * rh_rate,
        100.0 * elev_rate
    );
    assert_eq!(compared, 1800);
    assert!(rh_rate >= 0.99 && elev_rate >= 0.99, "{rh_rate} {elev_rate}");
}

/// Bad waveforms in an L1B granule (a V2 file written here): each gives rows with a
/// `no_result: <reason>` status and null values, never a failed run or a panic.
#[test]
fn l2a_cli_reports_bad_waveforms_as_no_result_rows() {
    use gedisim::io::granule::{write_l1b_v2, Beam, GranuleMeta};
    use gedisim::kernels::gedi::v2_file_name;
    use gedisim::kernels::gedi::L1bShot;
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join(v2_file_name("01_B", "2023100120000", 1, 1, 1));
    let signal: Vec<f32> =
        (0..600).map(|i| 220.0 + 400.0 * (-0.5 * ((i as f32 - 300.0) / 6.0).powi(2)).exp()).collect();
    let shot = |k: u64, wave: Vec<f32>, sd: f64| L1bShot {
        shot_number: 29_320_600_200_465_601 + k,
        rx_waveform: wave.clone(),
        tx_waveform: vec![0.0; 128],
        latitude_bin0: 46.5,
        longitude_bin0: 3.0,
        latitude_lastbin: 46.5,
        longitude_lastbin: 3.0,
        elevation_bin0: 400.0,
        elevation_lastbin: 400.0 - 0.15 * wave.len().saturating_sub(1) as f64,
        noise_mean_corrected: 220.0,
        noise_stddev_corrected: sd,
        ..Default::default()
    };
    let mut nan = signal.clone();
    nan[42] = f32::NAN;
    // All noise: the L2A algorithms do not run on it (NASA's rx_algrunflag = 0).
    let noise: Vec<f32> = (0..600).map(|i| 220.0 + 2.0 * ((i * 7919) % 13) as f32 / 13.0 - 1.0).collect();
    let shots = vec![
        shot(0, signal.clone(), 3.0),
        shot(1, vec![], 3.0),
        shot(2, nan, 3.0),
        shot(3, signal, 0.0),
        shot(4, noise, 3.0),
    ];
    write_l1b_v2(&path, &[Beam::new("BEAM0101", shots)], &GranuleMeta::default()).unwrap();
    let out = tmp.path().join("l2a.parquet");
    let (ok, _, err) = gedisim(&["l2a", "--l1b", path.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert!(ok, "{err}");
    assert!(err.contains("BEAM0101/rxwaveform: 1 shot(s) with NaN"), "the NaN shot is reported: {err}");
    let mut status: HashMap<(u64, u8), (String, bool)> = HashMap::new();
    for b in read(&out) {
        let sn = b.column_by_name("shot_number").unwrap().as_primitive::<UInt64Type>();
        let alg = b.column_by_name("algorithm").unwrap().as_primitive::<UInt8Type>();
        let st = b.column_by_name("status").unwrap().as_string::<i32>();
        let rh = b.column_by_name("rh").unwrap().as_list::<i32>();
        for i in 0..b.num_rows() {
            status
                .insert((sn.value(i) - 29_320_600_200_465_601, alg.value(i)), (st.value(i).to_string(), rh.is_null(i)));
        }
    }
    assert_eq!(status.len(), 5 * 6, "every shot keeps one row per algorithm");
    for a in 1..=6u8 {
        assert_eq!(status[&(0, a)], ("ok".to_string(), false), "a{a}");
        // Ingest nulls an empty record and one with a NaN sample (issue 20), with a warning.
        let nulled = "no_result: no usable waveform (empty, or NaN or infinite samples at ingest)".to_string();
        assert_eq!(status[&(1, a)], (nulled.clone(), true), "a{a}");
        assert_eq!(status[&(2, a)], (nulled, true), "a{a}");
        assert_eq!(
            status[&(3, a)],
            ("no_result: invalid noise statistics (mean not finite or stddev not > 0)".to_string(), true),
            "a{a}"
        );
        assert_eq!(status[&(4, a)], ("no_result: no signal above the thresholds".to_string(), true), "a{a}");
    }
}
