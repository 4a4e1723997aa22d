//! Bad inputs, faults and concurrency through the CLI: each case that once went wrong (a panic, a
//! silently wrong result, a stray file, a SQL statement reaching outside the dataset) ends with
//! one line and a non-zero exit, or with the right result, and never with a partial table.

mod common;

use std::path::{Path, PathBuf};

use common::{data, files_with_suffix, gedisim, s};

const L1B: &str = "gedi/GEDI01_B_2019108080338_O01964_T05337_02_003_01_sub.h5";
const L2A: &str = "gedi/GEDI02_A_2019108080338_O01964_T05337_02_001_01_sub.h5";
const SMALL_TILE: &str = "als/pdal-ign-plugin_mnx_input_crop_2.laz";

/// The error of a failed run: exactly one line on stderr, naming `needles`.
fn one_line_error(ok: bool, err: &str, needles: &[&str]) {
    assert!(!ok, "the run should fail: {err}");
    let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "one line: {err}");
    for n in needles {
        assert!(lines[0].contains(n), "{n:?} in {err}");
    }
}

/// A copy of the small LAZ tile with `patch` applied to its bytes.
fn patched_tile(dir: &Path, name: &str, patch: impl FnOnce(&mut Vec<u8>)) -> PathBuf {
    let mut bytes = std::fs::read(data(SMALL_TILE)).unwrap();
    patch(&mut bytes);
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

// LAS 1.4 header offsets.
const LEGACY_COUNT: usize = 107;
const X_SCALE: usize = 131;
const COUNT_64: usize = 247;

/// No table file may hold a temporary or be left without its registry row.
fn assert_no_partial_tables(ds: &Path) {
    assert!(files_with_suffix(ds, ".tmp").is_empty(), "temporary files left: {:?}", files_with_suffix(ds, ".tmp"));
    for f in files_with_suffix(&ds.join("als"), ".parquet") {
        assert!(ds.join("tiles").join(f.file_name().unwrap()).exists(), "{} has no tiles/ row", f.display());
    }
}

fn ingest_als(ds: &Path, files: &[&Path]) -> (bool, String, String) {
    let mut args = vec!["ingest", "als", "--out", s(ds)];
    args.extend(files.iter().map(|f| s(f)));
    gedisim(&args)
}

fn sql(ds: &Path, extra: &[&str], query: &str) -> (bool, String, String) {
    let mut args = vec!["sql", "--dataset", s(ds)];
    args.extend_from_slice(extra);
    args.push(query);
    gedisim(&args)
}

/// The single value of a one-cell query result.
fn scalar(ds: &Path, query: &str) -> String {
    let (ok, out, err) = sql(ds, &[], query);
    assert!(ok, "{err}");
    out.lines().nth(3).unwrap().trim_matches(|c: char| c == '|' || c.is_whitespace()).to_string()
}

#[test]
fn hostile_las_headers_are_rejected_before_the_las_crate_reads_them() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = tmp.path().join("ds");
    // 2^60 points: once `attempt to multiply with overflow` inside `las`, exit 101.
    let huge = patched_tile(tmp.path(), "huge.laz", |b| {
        b[COUNT_64..COUNT_64 + 8].copy_from_slice(&(1u64 << 60).to_le_bytes())
    });
    let (ok, _, err) = ingest_als(&ds, &[&huge]);
    one_line_error(ok, &err, &["huge.laz", "number_of_point_records"]);
    // Half the real count: once ingested only that many points, exit 0.
    let half = patched_tile(tmp.path(), "half.laz", |b| {
        let n = u64::from_le_bytes(b[COUNT_64..COUNT_64 + 8].try_into().unwrap()) / 2;
        b[COUNT_64..COUNT_64 + 8].copy_from_slice(&n.to_le_bytes());
        b[LEGACY_COUNT..LEGACY_COUNT + 4].copy_from_slice(&(n as u32).to_le_bytes());
    });
    let (ok, _, err) = ingest_als(&ds, &[&half]);
    one_line_error(ok, &err, &["half.laz", "number_of_point_records", "chunk table"]);
    // A zero scale factor: once every point at x = 0.
    let flat = patched_tile(tmp.path(), "flat.laz", |b| b[X_SCALE..X_SCALE + 8].copy_from_slice(&0f64.to_le_bytes()));
    let (ok, _, err) = ingest_als(&ds, &[&flat]);
    one_line_error(ok, &err, &["flat.laz", "x_scale_factor"]);
    // A truncated file.
    let cut = patched_tile(tmp.path(), "cut.laz", |b| b.truncate(b.len() / 3));
    let (ok, _, err) = ingest_als(&ds, &[&cut]);
    one_line_error(ok, &err, &["cut.laz"]);
    assert!(files_with_suffix(&ds, ".parquet").is_empty(), "no table from rejected files");
    assert_no_partial_tables(&ds);
}

#[test]
fn one_crs_per_call_and_per_dataset() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = tmp.path().join("ds");
    // The same tile with its WKT records saying EPSG:3949 (Lambert CC49) instead of 2154.
    let other = patched_tile(tmp.path(), "cc49.laz", |b| {
        while let Some(at) = b.windows(6).position(|w| w == b"\"2154\"") {
            b[at..at + 6].copy_from_slice(b"\"3949\"");
        }
    });
    let lambert = data("als/lidarforfuel_2_bas_lig.laz");
    let (ok, _, err) = ingest_als(&ds, &[&lambert, &other]);
    one_line_error(ok, &err, &["cc49.laz", "EPSG:3949", "EPSG:2154"]);
    assert!(files_with_suffix(&ds, ".parquet").is_empty(), "nothing written when the call mixes CRSs");
    let (ok, _, err) = ingest_als(&ds, &[&lambert]);
    assert!(ok, "{err}");
    let (ok, _, err) = ingest_als(&ds, &[&other]);
    one_line_error(ok, &err, &["cc49.laz", "EPSG:3949", "EPSG:2154"]);
    // GEDI onto a Lambert-93 dataset in UTM 31N: once accepted, then `no_als 300`.
    let (l1b, l2a) = (data(L1B), data(L2A));
    let (ok, _, err) =
        gedisim(&["ingest", "gedi", "--out", s(&ds), "--l1b", s(&l1b), "--l2a", s(&l2a), "--epsg", "32631"]);
    one_line_error(ok, &err, &["--epsg 32631", "EPSG:2154"]);
    assert!(!ds.join("shots").exists() || files_with_suffix(&ds.join("shots"), ".parquet").is_empty());
}

/// A copy of the test L1B whose BEAM0001 `rx_sample_count` is a signed dataset (first shot
/// `first_count`) and whose first shot's first sample is `first_sample`.
fn edited_l1b(dir: &Path, first_count: i32, first_sample: f32) -> PathBuf {
    let path = dir.join("GEDI01_B_2019108080338_O01964_T05337_02_003_01_sub.h5");
    std::fs::copy(data(L1B), &path).unwrap();
    let f = gedisim::io::gedi::without_locks().open_rw(&path).unwrap();
    let beam = f.group("BEAM0001").unwrap();
    let counts: Vec<u16> = beam.dataset("rx_sample_count").unwrap().read_raw().unwrap();
    let mut signed: Vec<i32> = counts.iter().map(|&c| i32::from(c)).collect();
    signed[0] = first_count;
    beam.unlink("rx_sample_count").unwrap();
    beam.new_dataset_builder().with_data(&signed).create("rx_sample_count").unwrap();
    let wave = beam.dataset("rxwaveform").unwrap();
    let mut samples: Vec<f32> = wave.read_raw().unwrap();
    samples[0] = first_sample;
    wave.write_raw(&samples).unwrap();
    path
}

#[test]
fn bad_gedi_sample_counts_and_samples() {
    let tmp = tempfile::tempdir().unwrap();
    let l2a = data(L2A);
    // A negative count: once an empty waveform, exit 0.
    let dir = tmp.path().join("negative");
    std::fs::create_dir(&dir).unwrap();
    let l1b = edited_l1b(&dir, -5, 1.0);
    let ds = tmp.path().join("ds1");
    let (ok, _, err) = gedisim(&["ingest", "gedi", "--out", s(&ds), "--l1b", s(&l1b), "--l2a", s(&l2a)]);
    one_line_error(ok, &err, &["BEAM0001/rx_sample_count", "negative count -5"]);
    assert!(files_with_suffix(&ds, ".parquet").is_empty());
    // A NaN sample: the shot's waveform null, one warning naming file, beam and count.
    let dir = tmp.path().join("nan");
    std::fs::create_dir(&dir).unwrap();
    let l1b = edited_l1b(&dir, 760, f32::NAN);
    let ds = tmp.path().join("ds2");
    let (ok, _, err) = gedisim(&["ingest", "gedi", "--out", s(&ds), "--l1b", s(&l1b), "--l2a", s(&l2a)]);
    assert!(ok, "{err}");
    let warning = err.lines().find(|l| l.contains("NaN")).unwrap_or_else(|| panic!("a NaN warning: {err}"));
    assert!(warning.contains(s(&l1b)) && warning.contains("BEAM0001") && warning.contains(" 1 shot(s)"), "{warning}");
    assert_eq!(scalar(&ds, "select count(*) - count(rx_waveform) from shots where beam = 'BEAM0001'"), "1");
}

#[test]
fn a_renamed_granule_is_not_ingested_twice() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = tmp.path().join("ds");
    let (l1b, l2a) = (data(L1B), data(L2A));
    let (ok, _, err) = gedisim(&["ingest", "gedi", "--out", s(&ds), "--l1b", s(&l1b), "--l2a", s(&l2a)]);
    assert!(ok, "{err}");
    // Copies under another granule's name (another track): the same content, skipped.
    let copy_b = tmp.path().join("GEDI01_B_2019108080338_O01964_T05338_02_003_01_sub.h5");
    let copy_a = tmp.path().join("GEDI02_A_2019108080338_O01964_T05338_02_001_01_sub.h5");
    std::fs::copy(&l1b, &copy_b).unwrap();
    std::fs::copy(&l2a, &copy_a).unwrap();
    let (ok, _, err) = gedisim(&["ingest", "gedi", "--out", s(&ds), "--l1b", s(&copy_b), "--l2a", s(&copy_a)]);
    assert!(ok && err.contains("already ingested"), "{err}");
    assert_eq!(scalar(&ds, "select count(*) from shots"), "301");
    // The L1B alone under a name of no convention: a copy too.
    let renamed = tmp.path().join("renamed.h5");
    std::fs::copy(&l1b, &renamed).unwrap();
    let (ok, _, err) = gedisim(&["ingest", "gedi", "--out", s(&ds), "--l1b", s(&renamed)]);
    assert!(ok && err.contains("already ingested"), "{err}");
    assert_eq!(scalar(&ds, "select count(*) from shots"), "301");
    // Paired with another L2A, the copy is refused: one line, nothing written.
    let other_a = tmp.path().join("GEDI02_A_2019108080338_O01964_T05338_02_001_01_sub.h5");
    let mut bytes = std::fs::read(&l2a).unwrap();
    bytes.extend_from_slice(b"another file");
    std::fs::write(&other_a, bytes).unwrap();
    let (ok, _, err) = gedisim(&["ingest", "gedi", "--out", s(&ds), "--l1b", s(&copy_b), "--l2a", s(&other_a)]);
    one_line_error(ok, &err, &["same content as granule 2019108080338_O01964_T05337_02"]);
    assert_eq!(scalar(&ds, "select count(*) from shots"), "301");
}

#[test]
fn one_side_of_a_granule_never_replaces_both() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = tmp.path().join("ds");
    let (l1b, l2a) = (data(L1B), data(L2A));
    let (ok, _, err) = gedisim(&["ingest", "gedi", "--out", s(&ds), "--l1b", s(&l1b), "--l2a", s(&l2a)]);
    assert!(ok, "{err}");
    let counts = "select count(rx_waveform) || ' ' || count(rh) from shots";
    assert_eq!(scalar(&ds, counts), "300 301");
    // The same L1B again, alone: nothing new, and the L2A columns stay.
    let (ok, _, err) = gedisim(&["ingest", "gedi", "--out", s(&ds), "--l1b", s(&l1b)]);
    assert!(ok && err.contains("already ingested"), "{err}");
    assert_eq!(scalar(&ds, counts), "300 301");
    // A changed L1B alone (same granule name): once rewrote the granule without its L2A.
    let dir = tmp.path().join("changed");
    std::fs::create_dir(&dir).unwrap();
    let changed = dir.join(l1b.file_name().unwrap());
    let mut bytes = std::fs::read(&l1b).unwrap();
    bytes.extend_from_slice(b"changed");
    std::fs::write(&changed, bytes).unwrap();
    let (ok, _, err) = gedisim(&["ingest", "gedi", "--out", s(&ds), "--l1b", s(&changed)]);
    one_line_error(ok, &err, &["give both files"]);
    assert_eq!(scalar(&ds, counts), "300 301");
}

#[test]
fn gedi_rh_is_null_where_rh_is_undefined() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = tmp.path().join("ds");
    std::fs::create_dir(&ds).unwrap();
    let f = |items: &str| format!("arrow_cast(make_array({items}), 'List(Float32)')");
    let q = format!(
        "select gedi_rh({}, 10.0, 0.15, 0.0) is null as nan, gedi_rh(arrow_cast(make_array(), 'List(Float32)'), 10.0, \
         0.15, 0.0) is null as empty, gedi_rh({}, 10.0, 0.15, 0.0) is null as zero, gedi_rh({}, 10.0, 0.15, 0.0) is \
         null as negative, gedi_rh({}, 10.0, 0.15, 0.0)[51] as rh50",
        f("'NaN', 1.0"),
        f("0.0, 0.0"),
        f("-1.0, -2.0"),
        f("0.0, 1.0"),
    );
    let (ok, out, err) = sql(&ds, &[], &q);
    assert!(ok, "{err}");
    let cells: Vec<&str> = out.lines().nth(3).unwrap().split('|').map(str::trim).filter(|c| !c.is_empty()).collect();
    assert_eq!(cells, ["true", "true", "true", "true", "9.85"], "{out}");
}

fn small_dataset(tmp: &Path) -> PathBuf {
    let ds = tmp.join("ds");
    let (ok, _, err) = ingest_als(&ds, &[&data(SMALL_TILE)]);
    assert!(ok, "{err}");
    ds
}

#[test]
fn sql_is_read_only_and_stays_inside_its_memory() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = small_dataset(tmp.path());
    let victim = tmp.path().join("victim.csv");
    std::fs::write(&victim, "precious\n").unwrap();
    let copy = format!("COPY (select 1 as a) TO '{}'", s(&victim));
    let (ok, _, err) = sql(&ds, &[], &copy);
    one_line_error(ok, &err, &["COPY", "--allow-writes"]);
    assert_eq!(std::fs::read_to_string(&victim).unwrap(), "precious\n");
    let external = "CREATE EXTERNAL TABLE e STORED AS CSV LOCATION '/etc/passwd'";
    let (ok, _, err) = sql(&ds, &[], external);
    one_line_error(ok, &err, &["DDL", "--allow-writes"]);
    // With --allow-writes: writes outside the dataset, never into its tables.
    let (ok, _, err) = sql(&ds, &["--allow-writes"], &copy);
    assert!(ok, "{err}");
    assert!(std::fs::read_to_string(&victim).unwrap().contains('1'));
    let (ok, _, err) = sql(&ds, &["--allow-writes"], "INSERT INTO tiles SELECT * FROM tiles");
    one_line_error(ok, &err, &["read-only"]);
    let inside = format!("COPY (select 1 as a) TO '{}/als/x.parquet'", s(&ds));
    let (ok, _, err) = sql(&ds, &["--allow-writes"], &inside);
    one_line_error(ok, &err, &["inside the dataset"]);
    assert_eq!(files_with_suffix(&ds.join("als"), ".parquet").len(), 1);
    assert_eq!(scalar(&ds, "select count(*) from tiles"), "1");
    // A self-join under a small memory limit fails cleanly instead of growing without bound.
    let join = "select a.cell, count(*) from als a join als b on a.cell = b.cell and a.z < b.z group by a.cell";
    let (ok, _, err) = sql(&ds, &["--memory-limit", "2M"], join);
    one_line_error(ok, &err, &["Resources exhausted"]);
    // A twin record of 2e9 samples is refused per row (its reason), not allocated.
    let twin = "select gedi_noise_twin(arrow_cast(make_array(0.0, 1.0, 0.0), 'List(Float32)'), 100.0, 0.15, 6900.0, \
                241.0, 2.5, 2000000000, 0, 1)['no_result_reason'] as reason";
    let (ok, out, err) = sql(&ds, &[], twin);
    assert!(ok, "{err}");
    assert!(out.contains("record longer than 100000 samples"), "{out}");
}

#[test]
fn sql_out_errors_leave_no_file() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = small_dataset(tmp.path());
    let outdir = tmp.path().join("outdir");
    std::fs::create_dir(&outdir).unwrap();
    let (ok, _, err) = sql(&ds, &["--out", s(&outdir)], "select 1 as a");
    one_line_error(ok, &err, &["outdir", "is a directory"]);
    // Never CSV into a `.json` file, nor a format guessed from a name that does not say it.
    let json = tmp.path().join("result.json");
    let (ok, _, err) = sql(&ds, &["--out", s(&json), "--format", "csv"], "select 1 as a");
    one_line_error(ok, &err, &["result.json", "--format csv"]);
    let txt = tmp.path().join("result.txt");
    let (ok, _, err) = sql(&ds, &["--out", s(&txt)], "select 1 as a");
    one_line_error(ok, &err, &["result.txt", "--format"]);
    let (ok, _, err) = sql(&ds, &["--format", "parquet"], "select 1 as a");
    one_line_error(ok, &err, &["--format parquet", "--out"]);
    let mut left: Vec<_> = std::fs::read_dir(tmp.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    left.sort();
    assert_eq!(left, ["ds", "outdir"], "nothing else written");
    assert!(std::fs::read_dir(&outdir).unwrap().next().is_none());
}

#[test]
fn sql_writes_csv_json_and_parquet_with_lists_as_json_arrays() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = small_dataset(tmp.path());
    let q = "select 'a,\"b\"' as name, make_array(1.5, 2.0) as rh, cast(null as double) as missing \
             union all select 'c', make_array(), 3.0";
    // By the file's extension, or by --format (printed).
    let csv = tmp.path().join("r.csv");
    let (ok, _, err) = sql(&ds, &["--out", s(&csv)], q);
    assert!(ok, "{err}");
    let (ok, printed, err) = sql(&ds, &["--format", "csv"], q);
    assert!(ok, "{err}");
    let written = std::fs::read_to_string(&csv).unwrap();
    // `union all` gives its rows in either order.
    let sorted = |t: &str| {
        let mut lines: Vec<String> = t.trim_end().lines().map(String::from).collect();
        lines[1..].sort();
        lines
    };
    assert_eq!(sorted(&written), sorted(&printed));
    let mut rows = csv::ReaderBuilder::new().from_reader(written.as_bytes());
    assert_eq!(rows.headers().unwrap(), vec!["name", "rh", "missing"]);
    let mut records: Vec<Vec<String>> = rows.records().map(|r| r.unwrap().iter().map(String::from).collect()).collect();
    records.sort();
    assert_eq!(records, [vec!["a,\"b\"", "[1.5,2.0]", ""], vec!["c", "[]", "3.0"]]);

    let json = tmp.path().join("r.json");
    let (ok, _, err) = sql(&ds, &["--out", s(&json)], q);
    assert!(ok, "{err}");
    let mut objects: Vec<serde_json::Value> = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    objects.sort_by_key(|o| o["name"].to_string());
    assert_eq!(
        objects,
        [
            serde_json::json!({"name": "a,\"b\"", "rh": [1.5, 2.0], "missing": null}),
            serde_json::json!({"name": "c", "rh": [], "missing": 3.0})
        ]
    );

    let parquet = tmp.path().join("r.out");
    let (ok, _, err) = sql(&ds, &["--out", s(&parquet), "--format", "parquet"], q);
    assert!(ok, "{err}");
    let file = std::fs::File::open(&parquet).unwrap();
    let reader = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file).unwrap().build().unwrap();
    assert_eq!(reader.map(|b| b.unwrap().num_rows()).sum::<usize>(), 2);
}

#[test]
fn one_writer_at_a_time() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = small_dataset(tmp.path());
    // This process holds the writer lock; a gedisim process must fail at once, one line.
    let (held, _) = gedisim::dataset::Dataset::writer(&ds).unwrap();
    let (ok, _, err) = ingest_als(&ds, &[&data("als/lidarforfuel_2_bas_lig.laz")]);
    one_line_error(ok, &err, &["another gedisim process", &format!("pid {}", std::process::id())]);
    drop(held);
    let (ok, _, err) = ingest_als(&ds, &[&data("als/lidarforfuel_2_bas_lig.laz")]);
    assert!(ok, "{err}");
}

#[test]
fn copies_of_one_file_in_one_call_are_ingested_once() {
    let tmp = tempfile::tempdir().unwrap();
    let copies: Vec<PathBuf> = (0..3)
        .map(|i| {
            let p = tmp.path().join(format!("copy{i}.laz"));
            std::fs::copy(data(SMALL_TILE), &p).unwrap();
            p
        })
        .collect();
    // Once racing on one spill name (failed 3 of 5 runs).
    for run in 0..5 {
        let ds = tmp.path().join(format!("ds{run}"));
        let refs: Vec<&Path> = copies.iter().map(PathBuf::as_path).collect();
        let (ok, _, err) = ingest_als(&ds, &refs);
        assert!(ok, "run {run}: {err}");
        assert_eq!(err.matches("already ingested").count(), 2, "{err}");
        assert_eq!(scalar(&ds, "select count(*) from als"), "221315");
        assert_no_partial_tables(&ds);
    }
}

#[test]
fn points_appear_with_their_tile_row_and_dead_writers_are_cleaned() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = small_dataset(tmp.path());
    let (ok, _, err) = ingest_als(&ds, &[&data("als/lidarforfuel_2_bas_lig.laz")]);
    assert!(ok, "{err}");
    let total = scalar(&ds, "select count(*) from als");
    // A writer that died between als/ and tiles/: its points are invisible…
    let tiles = files_with_suffix(&ds.join("tiles"), ".parquet");
    let gone = tiles.iter().find(|t| scalar_of_file(t) != "221315").unwrap().clone();
    std::fs::remove_file(&gone).unwrap();
    // …and a dead writer's temporary stays out of every read.
    let stale = ds.join("als").join(format!("{}.999999999-0.tmp", gone.file_name().unwrap().to_str().unwrap()));
    std::fs::write(&stale, b"half a file").unwrap();
    assert_eq!(scalar(&ds, "select count(*) from als"), "221315");
    assert_eq!(scalar(&ds, "select count(*) from tiles"), "1");
    // The next writer removes both and re-ingests the tile.
    let (ok, _, err) = ingest_als(&ds, &[&data("als/lidarforfuel_2_bas_lig.laz")]);
    assert!(ok, "{err}");
    assert!(err.contains("1 temporary file(s), 1 als/ file(s) without a tiles/ row"), "{err}");
    assert_eq!(scalar(&ds, "select count(*) from als"), total);
    assert_no_partial_tables(&ds);
}

/// The `n_points` of a one-row tiles/ file, as text.
fn scalar_of_file(tiles_file: &Path) -> String {
    let mut kept = String::new();
    gedisim::dataset::read::for_each_batch(tiles_file, Some(&["n_points"]), None, |c| {
        kept = c.u64("n_points", 0)?.unwrap().to_string();
        Ok(())
    })
    .unwrap();
    kept
}

#[test]
fn killed_ingests_leave_nothing_the_next_run_does_not_repair() {
    let tmp = tempfile::tempdir().unwrap();
    let tiles: Vec<PathBuf> = common::TILES.iter().map(|t| data(&format!("als/{t}.laz"))).collect();
    let clean = tmp.path().join("clean");
    let refs: Vec<&Path> = tiles.iter().map(PathBuf::as_path).collect();
    let (ok, _, err) = ingest_als(&clean, &refs);
    assert!(ok, "{err}");
    let expected = table_digest(&clean);
    // Kill at five points of a run: while reading headers, decoding, spilling and writing.
    let delays_ms = [40u64, 150, 300, 600, 900];
    for (i, delay) in delays_ms.iter().enumerate() {
        let ds = tmp.path().join(format!("killed{i}"));
        let mut args = vec!["ingest".to_string(), "als".into(), "--out".into(), s(&ds).into()];
        args.extend(tiles.iter().map(|t| s(t).to_string()));
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_gedisim"))
            .args(&args)
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(*delay));
        let _ = child.kill(); // SIGKILL
        child.wait().unwrap();
        // Readers never see a partial table, even before the repair.
        for f in files_with_suffix(&ds, ".parquet") {
            gedisim::dataset::read::open(&f).unwrap_or_else(|e| panic!("kill after {delay} ms: {e}"));
        }
        let (ok, _, err) = ingest_als(&ds, &refs);
        assert!(ok, "kill after {delay} ms: {err}");
        assert_no_partial_tables(&ds);
        assert_eq!(table_digest(&ds), expected, "kill after {delay} ms");
    }
}

/// Row count and coordinate sums of every table of a dataset (equal ⇔ same content here).
fn table_digest(ds: &Path) -> String {
    let q = "select (select count(*) from als) || ' ' || (select sum(x) + sum(y) + sum(z) from als) || ' ' || \
             (select count(*) from tiles) || ' ' || (select sum(n_points) from tiles)";
    scalar(ds, q)
}
