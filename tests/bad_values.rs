//! Bad values met through the binary (issue "Nothing silently wrong, round two"): each is refused
//! in one line naming the flag, file or field, or bounded with a warning — never accepted
//! silently (docs/robustness.md, "Bad values").

mod common;
#[path = "common/study.rs"]
mod study;

use std::path::{Path, PathBuf};

use common::{data, gedisim, s};

const L1B: &str = "gedi/GEDI01_B_2019108080338_O01964_T05337_02_003_01_sub.h5";
const TILE: &str = "als/pdal-ign-plugin_mnx_input_crop_2.laz";

/// The first line of stderr names every one of `needles`, and the run failed.
fn refused(ok: bool, err: &str, needles: &[&str]) {
    assert!(!ok, "the run should fail: {err}");
    let first = err.lines().find(|l| !l.trim().is_empty()).unwrap_or_default();
    for n in needles {
        assert!(first.contains(n), "{n:?} in the first line of: {err}");
    }
}

#[test]
fn nonsensical_widths_and_geoid_offsets_are_refused_naming_the_flag() {
    for (flag, value) in
        [("--fsigma", "0"), ("--fsigma", "-1"), ("--fsigma", "NaN"), ("--psigma", "-1"), ("--psigma", "NaN")]
    {
        let (ok, _, err) = gedisim(&["simulate", flag, value]);
        refused(ok, &err, &[flag, value]);
    }
    for value in ["NaN", "1e300", "-inf"] {
        for cmd in [&["run", "--dataset", "ds"][..], &["ingest", "gedi", "--out", "ds"][..]] {
            let (ok, _, err) = gedisim(&[cmd, &["--geoid-offset", value]].concat());
            refused(ok, &err, &["--geoid-offset", value]);
        }
    }
    // Sense still passes the parser (and fails later for want of inputs, not of the value).
    let (ok, _, err) = gedisim(&["simulate", "--fsigma", "7.5", "--psigma", "0.8"]);
    assert!(!ok && !err.contains("--fsigma") && !err.contains("--psigma"), "{err}");
}

#[test]
fn thread_counts_beyond_a_few_per_core_are_capped_with_a_warning() {
    let (ok, out, err) = gedisim(&["--threads", "100000", "completions", "bash"]);
    assert!(ok, "{err}");
    assert!(out.contains("gedisim"), "the completions are still written");
    let warning = err.lines().find(|l| l.contains("--threads 100000")).unwrap_or_else(|| panic!("a warning: {err}"));
    assert!(warning.contains("per core") && warning.contains("using"), "{warning}");
    let (ok, _, err) = gedisim(&["--threads", "1", "completions", "bash"]);
    assert!(ok && !err.contains("--threads"), "{err}");
}

/// Simulate the footprints of `csv` (text) over the small tile into `dir`.
fn simulate_csv(dir: &Path, csv: &str) -> (bool, String, PathBuf) {
    let path = dir.join("plots.csv");
    std::fs::write(&path, csv).unwrap();
    let out = dir.join("out.parquet");
    let (ok, _, err) = gedisim(&["simulate", "--als", s(&data(TILE)), "--footprints", s(&path), "--out", s(&out)]);
    (ok, err, path)
}

#[test]
fn a_repeated_csv_column_is_refused_and_a_huge_field_is_not_echoed() {
    let tmp = tempfile::tempdir().unwrap();
    let (ok, err, csv) = simulate_csv(tmp.path(), "id,x,y,X\np1,1,2,3\n");
    refused(ok, &err, &[s(&csv), "`X` twice", "columns 2 and 4"]);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    // A 20 MB field where a number belongs: the error line names the file and the column, and shows
    // the field by its start and length.
    let field = "9".repeat(20_000_000) + "x";
    let (ok, err, csv) = simulate_csv(tmp.path(), &format!("id,x,y\np1,{field},2\n"));
    refused(ok, &err, &[s(&csv)]);
    assert!(err.len() < 2_000, "{} bytes of error: {}…", err.len(), &err[..200]);
    assert!(err.contains("…(2000000") && err.contains(" bytes)"), "{err}");
    assert!(!tmp.path().join("out.parquet").exists());
}

/// A copy of the test L1B whose first BEAM0001 shot has `elevation_lastbin` = `lastbin`.
fn l1b_with_lastbin(dir: &Path, lastbin: Option<f64>) -> PathBuf {
    let path = dir.join("GEDI01_B_2019108080338_O01964_T05337_02_003_01_sub.h5");
    std::fs::copy(data(L1B), &path).unwrap();
    let f = gedisim::io::gedi::without_locks().open_rw(&path).unwrap();
    let geo = f.group("BEAM0001/geolocation").unwrap();
    let top: Vec<f64> = geo.dataset("elevation_bin0").unwrap().read_raw().unwrap();
    let last = geo.dataset("elevation_lastbin").unwrap();
    let mut v: Vec<f64> = last.read_raw().unwrap();
    // Above the first sample (inverted), or equal to it.
    v[0] = lastbin.unwrap_or(top[0]);
    last.write_raw(&v).unwrap();
    path
}

/// `status` of every row of an l2a output for the first BEAM0001 shot, and the count of other
/// rows that are `ok`.
fn first_shot_statuses(out: &Path) -> (Vec<String>, usize) {
    use arrow::array::{AsArray, RecordBatchReader};
    use arrow::datatypes::UInt64Type;
    let file = std::fs::File::open(out).unwrap();
    let reader = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file).unwrap().build().unwrap();
    let _ = reader.schema();
    let (mut first, mut others_ok) = (Vec::new(), 0);
    for b in reader {
        let b = b.unwrap();
        let sn = b.column_by_name("shot_number").unwrap().as_primitive::<UInt64Type>().clone();
        let beam = b.column_by_name("beam").unwrap().as_string::<i32>().clone();
        let status = b.column_by_name("status").unwrap().as_string::<i32>().clone();
        for i in 0..b.num_rows() {
            if beam.value(i) == "BEAM0001" && sn.value(i) == 19640119100108615 {
                first.push(status.value(i).to_string());
            } else if status.value(i) == "ok" {
                others_ok += 1;
            }
        }
    }
    (first, others_ok)
}

#[test]
fn l2a_refuses_repeated_algorithms_and_standard_output_and_flags_upside_down_waveforms() {
    let tmp = tempfile::tempdir().unwrap();
    let l1b = data(L1B);
    let out = tmp.path().join("l2a.parquet");
    let (ok, _, err) = gedisim(&["l2a", "--l1b", s(&l1b), "--out", s(&out), "--algorithms", "1,1,1"]);
    refused(ok, &err, &["--algorithms", "1 given twice"]);
    let (ok, _, err) = gedisim(&["l2a", "--l1b", s(&l1b), "--out", "-", "--algorithms", "1"]);
    refused(ok, &err, &["--out -", "standard output"]);
    assert!(!out.exists() && !Path::new("-").exists());
    // A first sample below the last, or at the same height: no result, said in the status (as `run`
    // skips the shot as bad_waveform_geometry), where every row used to be `ok` with RH98 −25 m.
    for (name, lastbin) in [("inverted", Some(900.0)), ("flat", None)] {
        let dir = tmp.path().join(name);
        std::fs::create_dir(&dir).unwrap();
        let edited = l1b_with_lastbin(&dir, lastbin);
        let out = dir.join("l2a.parquet");
        let (ok, _, err) = gedisim(&["l2a", "--l1b", s(&edited), "--out", s(&out), "--algorithms", "1,3"]);
        assert!(ok, "{err}");
        let (first, others_ok) = first_shot_statuses(&out);
        assert_eq!(first.len(), 2, "{name}");
        for st in &first {
            assert!(st.starts_with("no_result: bad waveform geometry"), "{name}: {st}");
        }
        assert!(others_ok > 100, "{name}: the other shots are processed ({others_ok} ok rows)");
    }
}

/// A LAS 1.4 file (point format 6, Lambert-93 coordinates at 1 cm) of `points` whose only CRS
/// record is the WKT `wkt`.
fn write_las(path: &Path, wkt: &str, points: impl IntoIterator<Item = las::Point>) {
    let mut b = las::Builder::from((1, 4));
    b.point_format = las::point::Format::new(6).unwrap();
    b.has_wkt_crs = true;
    let t = |offset| las::Transform { scale: 0.01, offset };
    b.transforms = las::Vector { x: t(700_000.0), y: t(6_600_000.0), z: t(0.0) };
    b.vlrs.push(las::Vlr {
        user_id: "LASF_Projection".into(),
        record_id: 2112,
        description: String::new(),
        data: wkt.as_bytes().to_vec(),
    });
    let mut w = las::Writer::from_path(path, b.into_header().unwrap()).unwrap();
    for p in points {
        w.write_point(p).unwrap();
    }
    w.close().unwrap();
}

/// A LAS 1.4 file of a few points whose only CRS record is the WKT `wkt`.
fn las_with_wkt(path: &Path, wkt: &str) {
    let points = (0..10).map(|i| las::Point {
        x: 700_000.0 + f64::from(i),
        y: 6_600_000.0,
        z: 100.0,
        gps_time: Some(1.0e8 + f64::from(i)),
        ..Default::default()
    });
    write_las(path, wkt, points);
}

#[test]
fn a_tile_with_a_vertical_crs_only_is_refused_at_ingest_naming_the_tile() {
    let tmp = tempfile::tempdir().unwrap();
    let tile = tmp.path().join("heights_only.las");
    let wkt = concat!(
        r#"VERT_CS["NGF-IGN69 height",VERT_DATUM["Nivellement General de la France - IGN69",2005,"#,
        r#"AUTHORITY["EPSG","5119"]],UNIT["metre",1],AXIS["Gravity-related height",UP],AUTHORITY["EPSG","5720"]]"#
    );
    las_with_wkt(&tile, wkt);
    let ds = tmp.path().join("ds");
    let (ok, _, err) = gedisim(&["ingest", "als", "--out", s(&ds), s(&tile)]);
    refused(ok, &err, &[s(&tile), "CRS", "vertical only (EPSG:5720)", "--epsg"]);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    // With the horizontal CRS given, the tile is ingested.
    let (ok, _, err) = gedisim(&["ingest", "als", "--out", s(&ds), "--epsg", "2154", s(&tile)]);
    assert!(ok, "{err}");
}

/// A dataset `<dir>/ds` holding the bundled tile.
fn tile_dataset(dir: &Path) -> PathBuf {
    let ds = dir.join("ds");
    let (ok, _, err) = gedisim(&["ingest", "als", "--out", s(&ds), s(&data(TILE))]);
    assert!(ok, "{err}");
    ds
}

#[test]
fn query_and_simulation_outputs_never_land_in_a_dataset_table() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = tile_dataset(tmp.path());
    let count = || gedisim(&["sql", "--dataset", s(&ds), "--format", "csv", "select count(*) as n from tiles"]).1;
    let before = count();
    // `sql --out` into a table folder used to add its rows to the table.
    let dup = ds.join("tiles/dup.parquet");
    let (ok, _, err) = gedisim(&["sql", "--dataset", s(&ds), "--out", s(&dup), "select * from tiles"]);
    refused(ok, &err, &["--out", "`tiles` table", "write elsewhere"]);
    assert!(!dup.exists());
    // Also a table folder the dataset does not have yet (`results/` before the first run): it used
    // to fail on the temporary file's name.
    let early = ds.join("results/dup.parquet");
    let (ok, _, err) = gedisim(&["sql", "--dataset", s(&ds), "--out", s(&early), "select * from tiles"]);
    refused(ok, &err, &["results/dup.parquet: --out", "`results` table", "write elsewhere"]);
    assert_eq!(count(), before);
    // Likewise a simulation's output, and a relative path from inside the folder.
    let csv = tmp.path().join("plots.csv");
    std::fs::write(&csv, "id,x,y\np1,1,2\n").unwrap();
    let (ok, _, err) = common::gedisim_in(
        &ds.join("als"),
        &[],
        &["simulate", "--als", s(&data(TILE)), "--footprints", s(&csv), "--out", "x.parquet"],
    );
    refused(ok, &err, &["`als` table"]);
    // Outside the tables (the dataset's report/ folder, or elsewhere) is fine.
    let fine = ds.join("report/n.csv");
    std::fs::create_dir_all(fine.parent().unwrap()).unwrap();
    let (ok, _, err) = gedisim(&["sql", "--dataset", s(&ds), "--out", s(&fine), "select count(*) as n from tiles"]);
    assert!(ok && fine.exists(), "{err}");
}

#[test]
fn a_granule_repeating_a_shot_number_in_two_beams_is_refused_and_the_dataset_takes_the_good_one() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("edited");
    std::fs::create_dir(&dir).unwrap();
    let l1b = dir.join("GEDI01_B_2019108080338_O01964_T05337_02_003_01_sub.h5");
    std::fs::copy(data(L1B), &l1b).unwrap();
    {
        let f = gedisim::io::gedi::without_locks().open_rw(&l1b).unwrap();
        let first: Vec<u64> = f.dataset("BEAM0001/shot_number").unwrap().read_raw().unwrap();
        let ds = f.dataset("BEAM0010/shot_number").unwrap();
        let mut v: Vec<u64> = ds.read_raw().unwrap();
        v[0] = first[0];
        ds.write_raw(&v).unwrap();
    }
    let ds = tmp.path().join("ds");
    let (ok, _, err) = gedisim(&["ingest", "gedi", "--out", s(&ds), "--l1b", s(&l1b)]);
    refused(ok, &err, &[s(&l1b), "shot_number", "19640119100108615", "BEAM0001", "BEAM0010"]);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(common::files_with_suffix(&ds, ".parquet").is_empty(), "nothing of the granule is kept");
    // The dataset takes the good granule afterwards.
    let (ok, _, err) = gedisim(&["ingest", "gedi", "--out", s(&ds), "--l1b", s(&data(L1B))]);
    assert!(ok, "{err}");
}

/// A LAS 1.4 tile of a 40 m × 40 m grid of returns every 0.5 m (Lambert-93), every return numbered
/// `return_number` of `number_of_returns`, the ground class on even rows.
fn grid_tile(path: &Path, return_number: u8, number_of_returns: u8) {
    let points = (0..80).flat_map(|i| {
        (0..80).map(move |j| las::Point {
            x: 700_000.0 + 0.5 * f64::from(i),
            y: 6_600_000.0 + 0.5 * f64::from(j),
            z: if j % 2 == 0 { 100.0 } else { 112.0 },
            return_number,
            number_of_returns,
            classification: if j % 2 == 0 {
                las::point::Classification::Ground
            } else {
                las::point::Classification::HighVegetation
            },
            gps_time: Some(1.0e8 + f64::from(i * 80 + j)),
            ..Default::default()
        })
    });
    write_las(path, r#"PROJCS["RGF93 v1 / Lambert-93",AUTHORITY["EPSG","2154"]]"#, points);
}

#[test]
fn returns_numbered_beyond_their_pulse_are_warned_of_and_still_cover_the_footprint() {
    let tmp = tempfile::tempdir().unwrap();
    let csv = tmp.path().join("plot.csv");
    std::fs::write(&csv, "id,x,y\np1,700020,6600020\n").unwrap();
    // Status and RH98 of the `count` row.
    let status = |tile: &Path| {
        use arrow::array::AsArray;
        let out = tmp.path().join("out.parquet");
        let args = ["simulate", "--als", s(tile), "--footprints", s(&csv), "--out", s(&out)];
        let (ok, _, err) = gedisim(&args);
        assert!(ok, "{err}");
        let file = std::fs::File::open(&out).unwrap();
        let reader =
            parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file).unwrap().build().unwrap();
        let mut rows = Vec::new();
        for b in reader {
            let b = b.unwrap();
            let weighting = b.column_by_name("weighting").unwrap().as_string::<i32>().clone();
            let st = b.column_by_name("status").unwrap().as_string::<i32>().clone();
            for i in (0..b.num_rows()).filter(|&i| weighting.value(i) == "count") {
                rows.push(st.value(i).to_string());
            }
        }
        rows.join(";")
    };
    let good = tmp.path().join("good.las");
    grid_tile(&good, 1, 1);
    let odd = tmp.path().join("odd.las");
    grid_tile(&odd, 3, 1);
    let (good, odd) = (status(&good), status(&odd));
    assert_eq!(good, "ok");
    assert_eq!(odd, "ok", "a return numbered 3 of 1 counts as its pulse's last, as 1 of 1 does");
    // Ingest says how many points are odd, naming the tile and the field.
    let (ok, _, err) = gedisim(&["ingest", "als", "--out", s(&tmp.path().join("ds")), s(&tmp.path().join("odd.las"))]);
    assert!(ok, "{err}");
    let warning = err.lines().find(|l| l.contains("return_number")).unwrap_or_else(|| panic!("a warning: {err}"));
    assert!(warning.contains("odd") && warning.contains("6400 points"), "{warning}");
}

#[test]
fn a_stray_file_in_a_table_folder_is_named() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = tile_dataset(tmp.path());
    let junk = ds.join("tiles/junk.parquet");
    std::fs::write(&junk, b"PAR1\n").unwrap();
    let (ok, _, err) = gedisim(&["sql", "--dataset", s(&ds), "select count(*) from tiles"]);
    refused(ok, &err, &[s(&junk), "not a Parquet file gedisim can read", "move it out"]);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    // `report` reads `results/`: a stray file there is named too.
    std::fs::remove_file(&junk).unwrap();
    let junk = ds.join("results/junk.parquet");
    std::fs::create_dir_all(junk.parent().unwrap()).unwrap();
    std::fs::write(&junk, b"PAR1\n").unwrap();
    let (ok, _, err) = gedisim(&["report", "--dataset", s(&ds)]);
    refused(ok, &err, &[s(&junk), "not a Parquet file gedisim can read"]);
    // `export` reads `shots/`: it used to name its own output as the file it could not read.
    let study = gedisim::dataset::Dataset::create(&tmp.path().join("study")).unwrap();
    study::write_results(&study, &study::synthetic_results(12));
    study::write_shots_and_sim(&study, 12);
    let junk = study.root().join("shots/junk.parquet");
    std::fs::write(&junk, b"hello").unwrap();
    let out = tmp.path().join("shots.geo.parquet");
    let (ok, _, err) =
        gedisim(&["export", "geoparquet", "--dataset", s(study.root()), "--table", "shots", "--out", s(&out)]);
    refused(ok, &err, &[s(&junk), "not a Parquet file gedisim can read", "move it out"]);
    assert!(!out.exists());
}

#[test]
fn dataset_paths_with_glob_or_control_characters() {
    let tmp = tempfile::tempdir().unwrap();
    // `?` (a glob character to the SQL engine's path parser): ingested and queried.
    let ds = tmp.path().join("plots?2024[a]").join("ds");
    let (ok, _, err) = gedisim(&["ingest", "als", "--out", s(&ds), s(&data(TILE))]);
    assert!(ok, "{err}");
    let (ok, out, err) = gedisim(&["sql", "--dataset", s(&ds), "--format", "csv", "select count(*) as n from tiles"]);
    assert!(ok && out.contains("\n1"), "{out} {err}");
    // A newline, which the engine's object store cannot address: refused before anything is written.
    let ds = tmp.path().join("two\nlines").join("ds");
    let (ok, _, err) = gedisim(&["ingest", "als", "--out", s(&ds), s(&data(TILE))]);
    refused(ok, &err, &["control character", "'\\n'", "rename it"]);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(!ds.exists());
}

#[test]
fn simulate_on_a_dataset_never_writes_into_runs_sim_table() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = tile_dataset(tmp.path());
    // Named like a granule's `sim/` file, as a user may name a plot list: it used to replace that file.
    let csv = tmp.path().join("GEDI02_A_2019108080338_O01964_T05337_02_001_01_sub.csv");
    std::fs::write(&csv, "id,x,y\np1,1,2\n").unwrap();
    let (ok, _, err) = gedisim(&["simulate", "--dataset", s(&ds), "--footprints", s(&csv)]);
    assert!(ok, "{err}");
    assert!(!ds.join("sim").exists(), "sim/ is run's alone");
    let written = ds.join("simulated/GEDI02_A_2019108080338_O01964_T05337_02_001_01_sub.parquet");
    assert!(written.exists());
    let (ok, out, err) = gedisim(&[
        "sql",
        "--dataset",
        s(&ds),
        "--format",
        "csv",
        "select count(distinct footprint_id) as n from simulated",
    ]);
    assert!(ok && out.contains("\n1"), "{out} {err}");
}

#[test]
fn a_granule_repeating_the_shot_numbers_of_another_granule_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    // Another granule name, other content (one waveform sample changed), the same shot numbers.
    let copy = tmp.path().join("GEDI01_B_2019109080338_O01980_T05337_02_003_01_sub.h5");
    std::fs::copy(data(L1B), &copy).unwrap();
    {
        let f = gedisim::io::gedi::without_locks().open_rw(&copy).unwrap();
        let ds = f.dataset("BEAM0001/rxwaveform").unwrap();
        let mut v: Vec<f32> = ds.read_raw().unwrap();
        v[0] += 1.0;
        ds.write_raw(&v).unwrap();
    }
    let ds = tmp.path().join("ds");
    let (ok, _, err) = gedisim(&["ingest", "gedi", "--out", s(&ds), "--l1b", s(&data(L1B))]);
    assert!(ok, "{err}");
    let rows = |ds: &Path| common::files_with_suffix(&ds.join("shots"), ".parquet").len();
    let (ok, _, err) = gedisim(&["ingest", "gedi", "--out", s(&ds), "--l1b", s(&copy)]);
    refused(ok, &err, &[s(&copy), "shot_number", "granule 2019108080338_O01964", "unique across GEDI"]);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert_eq!(rows(&ds), 1, "the dataset keeps only the first granule");
    // Both in one call, into a new dataset: the second to be written is refused.
    let both = tmp.path().join("both");
    let (ok, _, err) = gedisim(&["ingest", "gedi", "--out", s(&both), "--l1b", s(&data(L1B)), s(&copy)]);
    refused(ok, &err, &["shot_number", "unique across GEDI"]);
    // Re-ingesting the first granule itself (unchanged, or changed) is not a conflict with itself.
    let (ok, _, err) = gedisim(&["ingest", "gedi", "--out", s(&ds), "--l1b", s(&data(L1B))]);
    assert!(ok, "{err}");
}

#[test]
fn a_las_whose_header_bounds_miss_its_points_is_said_in_direct_mode() {
    let tmp = tempfile::tempdir().unwrap();
    let tile = tmp.path().join("moved.las");
    grid_tile(&tile, 1, 1);
    // The header's x bounds 10 km east of the points (700 000–700 040 m): max X at byte 179, min X at 187.
    let mut bytes = std::fs::read(&tile).unwrap();
    for at in [179, 187] {
        let v = f64::from_le_bytes(bytes[at..at + 8].try_into().unwrap()) + 10_000.0;
        bytes[at..at + 8].copy_from_slice(&v.to_le_bytes());
    }
    std::fs::write(&tile, bytes).unwrap();
    let simulate = |x: f64| {
        let csv = tmp.path().join("plots.csv");
        std::fs::write(&csv, format!("id,x,y\np,{x},6600020\n")).unwrap();
        let out = tmp.path().join("out.parquet");
        gedisim(&["simulate", "--als", s(&tile), "--footprints", s(&csv), "--out", s(&out)])
    };
    // Where the points are: outside the header, said (it was a silent no_points).
    let (ok, _, err) = simulate(700_020.0);
    assert!(ok, "{err}");
    assert!(err.contains("warning") && err.contains("outside every --als file's header bounds"), "{err}");
    // Where the header says: the file is read, and its points found beyond its header.
    let (ok, _, err) = simulate(710_020.0);
    assert!(ok, "{err}");
    assert!(err.contains(s(&tile)) && err.contains("beyond the header's bounds"), "{err}");
    assert!(!err.contains("outside every"), "{err}");
}

/// The peak resident memory (VmHWM, bytes) of the running process `pid`; None once it has ended.
fn peak_memory_of(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let kb = status.lines().find_map(|l| l.strip_prefix("VmHWM:"))?;
    Some(kb.trim().trim_end_matches("kB").trim().parse::<u64>().ok()? * 1024)
}

/// The binary started with `args`, its stdout and stderr as given.
fn spawn(args: &[&str], stdout: std::process::Stdio, stderr: std::process::Stdio) -> std::process::Child {
    std::process::Command::new(env!("CARGO_BIN_EXE_gedisim"))
        .args(args)
        .stdout(stdout)
        .stderr(stderr)
        .spawn()
        .expect("run gedisim")
}

/// Run the binary with `args` to its end, its peak resident memory sampled every 20 ms (the last
/// sample before it ended): (success, stderr, peak bytes).
fn run_with_peak_memory(args: &[&str]) -> (bool, String, u64) {
    use std::io::Read;
    let mut child = spawn(args, std::process::Stdio::null(), std::process::Stdio::piped());
    let mut stderr = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut text = String::new();
        let _ = stderr.read_to_string(&mut text);
        text
    });
    let mut peak = 0;
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        peak = peak_memory_of(child.id()).unwrap_or(0).max(peak);
        std::thread::sleep(std::time::Duration::from_millis(20));
    };
    (status.success(), reader.join().unwrap(), peak)
}

/// Run the binary with `args` until `enough` is true of the stdout lines read so far, then its peak
/// resident memory (VmHWM, bytes) while still running; the process is killed afterwards. None if
/// its output ended first. The reading is bounded by a guard (a build that gathers instead of
/// streaming prints nothing until the end), which is no timing assertion: 10 minutes.
fn peak_memory_while_streaming(args: &[&str], mut enough: impl FnMut(&[String]) -> bool) -> Option<u64> {
    use std::io::BufRead;
    let mut child = spawn(args, std::process::Stdio::piped(), std::process::Stdio::null());
    let stdout = child.stdout.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in std::io::BufReader::new(stdout).lines() {
            if tx.send(line.unwrap_or_default()).is_err() {
                break;
            }
        }
    });
    let mut lines = Vec::new();
    let mut peak = None;
    while let Ok(line) = rx.recv_timeout(std::time::Duration::from_secs(600)) {
        lines.push(line);
        if enough(&lines) {
            peak = peak_memory_of(child.id());
            break;
        }
    }
    let _ = child.kill();
    let _ = child.wait();
    peak
}

#[test]
fn sql_results_come_row_by_row_and_a_printed_table_is_bounded_by_the_memory_limit() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = tile_dataset(tmp.path());
    let cross = "select a.x, b.y from als a cross join als b";
    // A table is printed only whole: past half of --memory-limit it is refused in one line (the
    // result used to be gathered without bound, past 5 GB under a 1 GB limit).
    let (ok, out, err) = gedisim(&["sql", "--dataset", s(&ds), "--memory-limit", "64M", cross]);
    refused(ok, &err, &["Resources exhausted", "--memory-limit", "--format csv"]);
    assert!(out.is_empty(), "{out}");
    // CSV comes row by row: a million rows of a result of billions are out while the process holds
    // little memory.
    let peak = peak_memory_while_streaming(
        &["sql", "--dataset", s(&ds), "--memory-limit", "64M", "--format", "csv", cross],
        |lines| lines.len() > 1_000_000,
    )
    .expect("rows as they come");
    assert!(peak < 400 << 20, "peak {} MB", peak >> 20);
    // --out writes the one result as it comes; a second result is refused and nothing is left.
    let csv = tmp.path().join("two.csv");
    let (ok, _, err) = gedisim(&["sql", "--dataset", s(&ds), "--out", s(&csv), "select 1 as a; select 2 as b"]);
    refused(ok, &err, &["two.csv", "a second statement gives a result"]);
    assert!(std::fs::read_dir(tmp.path()).unwrap().all(|e| !e.unwrap().file_name().to_string_lossy().contains("two")));
    let parquet = tmp.path().join("pairs.parquet");
    let (ok, _, err) = gedisim(&["sql", "--dataset", s(&ds), "--out", s(&parquet), &format!("{cross} limit 3000000")]);
    assert!(ok, "{err}");
    use parquet::file::reader::FileReader;
    let reader = parquet::file::reader::SerializedFileReader::new(std::fs::File::open(&parquet).unwrap()).unwrap();
    assert_eq!(reader.metadata().file_metadata().num_rows(), 3_000_000);
}

#[test]
fn sql_refuses_an_expression_too_deep_to_plan_and_parses_statements_one_at_a_time() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = tile_dataset(tmp.path());
    let file = tmp.path().join("q.sql");
    let run = |text: String| {
        std::fs::write(&file, text).unwrap();
        gedisim(&["sql", "--dataset", s(&ds), "--format", "csv", "-f", s(&file)])
    };
    // 400 KB of `1+1+…` and 10,000 OR terms used to abort the process with a stack overflow.
    let terms = |n: usize, term: &str, op: &str| vec![term; n].join(op);
    let (ok, out, err) = run(format!("select {};", terms(200_000, "1", "+")));
    refused(ok, &err, &["statement 1", "nests deeper than 256", "x IN (…)"]);
    assert!(out.is_empty(), "{out}");
    let (ok, _, err) =
        run(format!("select 1 as a; select count(*) from als where {};", terms(10_000, "x = 0", " or ")));
    refused(ok, &err, &["statement 2", "nests deeper than 256"]);
    // The deepest allowed still runs.
    let (ok, out, err) = run(format!("select {} as s;", terms(256, "1", "+")));
    assert!(ok && out.lines().nth(1) == Some("256"), "{out} {err}");
    // Statements are parsed one at a time and dropped once run: 30,000 of them (they used to be
    // parsed all at once, ≈ 14 KB each).
    std::fs::write(&file, "select 1 as one;\n".repeat(30_000)).unwrap();
    let peak = peak_memory_while_streaming(&["sql", "--dataset", s(&ds), "--format", "csv", "-f", s(&file)], |lines| {
        lines.len() > 25_000 * 2 // a header and a row each
    })
    .expect("every result printed");
    assert!(peak < 300 << 20, "peak {} MB", peak >> 20);
}

#[test]
fn simulate_writes_its_rows_as_they_come_in_both_modes() {
    // 15,000 footprints over one bundled tile: every result used to be held until the end (direct
    // mode 1.38 GB, dataset mode 0.71 GB here; 7.1 and 3.4 GB at 10⁵); now a chunk or block of
    // at most 1,024 footprints is (≈ 0.3 GB at 10⁵).
    let tmp = tempfile::tempdir().unwrap();
    let tile = data("als/lidarforfuel_1_42.laz");
    let csv = tmp.path().join("plots.csv");
    let mut text = String::from("id,x,y\n");
    for i in 0..15_000 {
        let (u, v) = ((i * 7919 % 15_000) as f64 / 15_000.0, (i * 104_729 % 15_000) as f64 / 15_000.0);
        text += &format!("p{i},{:.2},{:.2}\n", 817_582.0 + 80.0 * u, 6_460_777.0 + 80.0 * v);
    }
    std::fs::write(&csv, text).unwrap();
    let out = tmp.path().join("plots.parquet");
    let (ok, err, peak) =
        run_with_peak_memory(&["simulate", "--als", s(&tile), "--footprints", s(&csv), "--out", s(&out)]);
    assert!(ok, "{err}");
    assert!(peak < 500 << 20, "direct mode peak {} MB", peak >> 20);
    let ds = tmp.path().join("ds");
    let (ok, _, err) = gedisim(&["ingest", "als", "--out", s(&ds), s(&tile)]);
    assert!(ok, "{err}");
    let (ok, err, peak) = run_with_peak_memory(&["simulate", "--dataset", s(&ds), "--footprints", s(&csv)]);
    assert!(ok, "{err}");
    assert!(peak < 500 << 20, "dataset mode peak {} MB", peak >> 20);
    // Every footprint's three rows, either way.
    use parquet::file::reader::FileReader;
    let rows = |p: &Path| {
        parquet::file::reader::SerializedFileReader::new(std::fs::File::open(p).unwrap())
            .unwrap()
            .metadata()
            .file_metadata()
            .num_rows()
    };
    assert_eq!(rows(&out), 45_000);
    assert_eq!(rows(&ds.join("simulated/plots.parquet")), 45_000);
}

/// Write a small Parquet file of `columns` (each `(name, int64 or utf8 values)`) as another tool would.
fn foreign_parquet(path: &Path, columns: &[(&str, bool)]) {
    use std::sync::Arc;
    let fields: Vec<arrow::datatypes::Field> = columns
        .iter()
        .map(|(n, text)| {
            let t = if *text { arrow::datatypes::DataType::Utf8 } else { arrow::datatypes::DataType::Int64 };
            arrow::datatypes::Field::new(*n, t, true)
        })
        .collect();
    let arrays: Vec<arrow::array::ArrayRef> = columns
        .iter()
        .map(|(_, text)| -> arrow::array::ArrayRef {
            match text {
                true => Arc::new(arrow::array::StringArray::from(vec!["a", "b", "c"])),
                false => Arc::new(arrow::array::Int64Array::from(vec![1, 2, 3])),
            }
        })
        .collect();
    let batch =
        arrow::record_batch::RecordBatch::try_new(Arc::new(arrow::datatypes::Schema::new(fields)), arrays).unwrap();
    let mut w =
        parquet::arrow::ArrowWriter::try_new(std::fs::File::create(path).unwrap(), batch.schema(), None).unwrap();
    w.write(&batch).unwrap();
    w.close().unwrap();
}

#[test]
fn a_readable_parquet_file_of_another_tool_in_a_table_folder_is_refused_by_name() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = tile_dataset(tmp.path());
    let count = || gedisim(&["sql", "--dataset", s(&ds), "--format", "csv", "select count(*) as n from tiles"]);
    let before = count();
    assert!(before.0 && before.1.contains("\n1"), "{before:?}");
    // A user's own table (its rows used to be counted among the tiles, its columns added to the table's).
    let mine = ds.join("tiles/plots.parquet");
    foreign_parquet(&mine, &[("plot_id", true), ("tile", true), ("agb", false)]);
    let (ok, _, err) = count();
    refused(ok, &err, &["plots.parquet: plot_id: no such column in the `tiles` table", "move it out"]);
    // A file holding the table's columns, one with another type.
    std::fs::remove_file(&mine).unwrap();
    let typed = [("tile", true), ("path", true), ("content_hash", true), ("las_version", true), ("n_points", true)];
    foreign_parquet(&mine, &typed);
    let (ok, _, err) = count();
    refused(ok, &err, &["plots.parquet", "n_points: Utf8 where the `tiles` table has UInt64"]);
    std::fs::remove_file(&mine).unwrap();
    assert_eq!(count(), before);
    // The report meets one in `results/` the same way.
    let study = gedisim::dataset::Dataset::create(&tmp.path().join("study")).unwrap();
    study::write_results(&study, &study::synthetic_results(12));
    study::write_shots_and_sim(&study, 12);
    study::write_tiles(&study);
    foreign_parquet(&study.root().join("results/mine.parquet"), &[("shot_number", false), ("rh98", false)]);
    let (ok, _, err) = gedisim(&["report", "--dataset", s(study.root())]);
    refused(ok, &err, &["results/mine.parquet", "`results` table", "move it out"]);
}
