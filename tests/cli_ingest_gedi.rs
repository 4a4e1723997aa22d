//! `gedisim ingest gedi` through the CLI: dataset layout, idempotency, and the shots table in SQL.

mod common;

use common::{data, files_with_suffix, gedisim};

const L1B: &str = "gedi/GEDI01_B_2019108080338_O01964_T05337_02_003_01_sub.h5";
const L2A: &str = "gedi/GEDI02_A_2019108080338_O01964_T05337_02_001_01_sub.h5";

#[test]
fn ingest_gedi_writes_shots_once_and_sql_reads_them() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = tmp.path().join("ds");
    let (l1b, l2a) = (data(L1B), data(L2A));
    let args = [
        "ingest",
        "gedi",
        "--l1b",
        l1b.to_str().unwrap(),
        "--l2a",
        l2a.to_str().unwrap(),
        "--out",
        ds.to_str().unwrap(),
    ];
    let (ok, _, err) = gedisim(&args);
    assert!(ok, "{err}");
    assert!(err.contains("301 shots"), "{err}");
    assert!(err.contains("warning:") && err.contains("BEAM0011"), "the unpaired L2A shot is reported: {err}");
    // No CRS named by --epsg or by tiles: the default is said, never silent.
    assert!(err.contains("warning: shots projected to EPSG:2154") && err.contains("--epsg"), "{err}");
    let (ok, _, err) = gedisim(&args);
    assert!(ok && err.contains("already ingested"), "{err}");
    assert!(!err.contains("shots projected to"), "the dataset has its CRS now: {err}");
    let named = tmp.path().join("named");
    let mut with_epsg = args.to_vec();
    with_epsg[7] = named.to_str().unwrap();
    with_epsg.extend(["--epsg", "2154"]);
    let (ok, _, err) = gedisim(&with_epsg);
    assert!(ok && !err.contains("shots projected to"), "{err}");
    assert_eq!(files_with_suffix(&ds.join("shots"), ".parquet").len(), 1);
    let q = "select count(*) as n, count(rx_waveform) as with_l1b, count(rh) as with_l2a, min(shot_number) as first \
        from shots";
    let (ok, out, err) = gedisim(&["sql", "--dataset", ds.to_str().unwrap(), q]);
    assert!(ok, "{err}");
    let row = out.lines().nth(3).unwrap();
    let cells: Vec<&str> = row.split('|').map(str::trim).filter(|s| !s.is_empty()).collect();
    assert_eq!(&cells[..3], &["301", "300", "301"], "{out}");
    assert!(cells[3].starts_with("1964") && cells[3].len() == 17, "shot numbers stay exact u64: {out}");
}

#[test]
fn missing_input_file_is_a_one_line_error() {
    let tmp = tempfile::tempdir().unwrap();
    let (ok, _, err) =
        gedisim(&["ingest", "gedi", "--l1b", "/nonexistent/GEDI01_B_x.h5", "--out", tmp.path().to_str().unwrap()]);
    assert!(!ok);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("/nonexistent/GEDI01_B_x.h5"), "{err}");
}
