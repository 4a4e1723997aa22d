//! The command line's conventions, through the binary: shell completions, `-v`/`-q`, `--threads`,
//! and one name per concept (`--dataset` for a dataset, `--als` for tiles).

mod common;
#[path = "common/study.rs"]
mod study;

use common::{data, gedisim, gedisim_in, gedisim_with_stdin};
use gedisim::dataset::Dataset;

/// A dataset with results, shots and tiles (the report's inputs).
fn report_dataset(dir: &std::path::Path) -> Dataset {
    let ds = Dataset::create(dir).unwrap();
    study::write_results(&ds, &study::synthetic_results(12));
    study::write_shots_and_sim(&ds, 12);
    study::write_tiles(&ds);
    ds
}

#[test]
fn completions_for_each_shell_name_the_subcommands() {
    for shell in ["bash", "zsh", "fish", "elvish", "powershell"] {
        let (ok, out, err) = gedisim(&["completions", shell]);
        assert!(ok, "{shell}: {err}");
        for sub in ["diagnose", "report", "ingest", "sql"] {
            assert!(out.contains(sub), "{shell}: {sub} missing");
        }
    }
    let (ok, _, err) = gedisim(&["completions", "tcsh"]);
    assert!(!ok && err.contains("possible values"), "{err}");
}

#[test]
fn quiet_verbose_and_threads() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = report_dataset(&tmp.path().join("ds"));
    let d = ds.root().to_str().unwrap();
    // Default: what each step did on stderr.
    let (ok, out, err) = gedisim(&["report", "--dataset", d]);
    assert!(ok, "{err}");
    assert!(err.contains("msd: ") && err.contains("report.html"), "{err}");
    assert!(!err.contains("debug: "), "{err}");
    assert!(out.is_empty(), "report prints nothing on stdout: {out}");
    // -q: nothing but warnings and errors.
    let (ok, _, err) = gedisim(&["-q", "report", "--dataset", d]);
    assert!(ok && err.is_empty(), "{err}");
    // -v: the steps' details too (each query as it starts).
    let (ok, _, err) = gedisim(&["report", "--dataset", d, "-v"]);
    assert!(ok, "{err}");
    assert!(err.contains("debug: report: query msd"), "{err}");
    let (ok, _, err) = gedisim(&["report", "--dataset", d, "-v", "-q"]);
    assert!(!ok && err.contains("cannot be used with"), "{err}");
    // --threads: the same report on one thread (sums in another order: equal to 1e-12); 0 is
    // refused in one line.
    let cells = || -> Vec<String> {
        let text = std::fs::read_to_string(ds.root().join("report/msd.csv")).unwrap();
        text.lines().flat_map(|l| l.split(',').map(str::to_string).collect::<Vec<_>>()).collect()
    };
    let before = cells();
    let (ok, _, err) = gedisim(&["--threads", "1", "report", "--dataset", d]);
    assert!(ok, "{err}");
    let after = cells();
    assert_eq!(before.len(), after.len());
    for (a, b) in before.iter().zip(&after) {
        match (a.parse::<f64>(), b.parse::<f64>()) {
            (Ok(x), Ok(y)) => assert!((x - y).abs() <= 1e-12 * x.abs().max(1.0), "{x} vs {y}"),
            _ => assert_eq!(a, b),
        }
    }
    // The SQL engine's partitions follow --threads.
    let show = "SHOW datafusion.execution.target_partitions";
    let (ok, out, err) = gedisim(&["--threads", "3", "sql", "--dataset", d, "--format", "csv", show]);
    assert!(ok && out.trim().ends_with(",3"), "{out}{err}");
    let (ok, _, err) = gedisim(&["report", "--dataset", d, "--threads", "0"]);
    assert!(!ok && err.contains("--threads"), "{err}");
}

#[test]
fn ingest_als_takes_its_tiles_like_every_command_and_a_dataset_by_name() {
    let tmp = tempfile::tempdir().unwrap();
    let tile = data("als/lidarforfuel_2_bas_lig.laz");
    let tile = tile.to_str().unwrap();
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    let (ok, _, err) = gedisim(&["ingest", "als", "--als", tile, "--dataset", a.to_str().unwrap()]);
    assert!(ok, "{err}");
    // The earlier form (positional tiles, --out) still works and ingests the same.
    let (ok, _, err) = gedisim(&["ingest", "als", tile, "--out", b.to_str().unwrap()]);
    assert!(ok, "{err}");
    let names = |d: &std::path::Path| {
        let mut v: Vec<String> = std::fs::read_dir(d.join("als"))
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into())
            .collect();
        v.sort();
        v
    };
    assert_eq!(names(&a), names(&b));
    assert!(!names(&a).is_empty());
    let (ok, _, err) = gedisim(&["ingest", "als", "--dataset", a.to_str().unwrap()]);
    assert!(!ok && err.contains("--als"), "no tiles given: {err}");
}

/// (footprint_id, weighting) → (x, y, wave) of a `simulate` output.
fn simulated(path: &std::path::Path) -> std::collections::BTreeMap<(String, String), (f64, f64, Vec<f32>)> {
    use arrow::array::{Array, AsArray};
    use arrow::datatypes::{Float32Type, Float64Type};
    let file = std::fs::File::open(path).unwrap();
    let reader = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file).unwrap().build().unwrap();
    let mut out = std::collections::BTreeMap::new();
    for b in reader {
        let b = b.unwrap();
        let s = |n: &str| b.column_by_name(n).unwrap().as_string::<i32>().clone();
        let f = |n: &str| b.column_by_name(n).unwrap().as_primitive::<Float64Type>().clone();
        let (id, w, x, y, rh) = (s("footprint_id"), s("weighting"), f("x"), f("y"), b.column_by_name("wave").unwrap());
        let rh = rh.as_list::<i32>();
        for i in 0..b.num_rows() {
            let r = if rh.is_null(i) { vec![] } else { rh.value(i).as_primitive::<Float32Type>().values().to_vec() };
            out.insert((id.value(i).to_string(), w.value(i).to_string()), (x.value(i), y.value(i), r));
        }
    }
    out
}

#[test]
fn footprints_as_users_have_them_lon_lat_or_another_crs() {
    use gedisim::kernels::geo::projection::Projector;
    let tmp = tempfile::tempdir().unwrap();
    let tile = data("als/lidarforfuel_2_bas_lig.laz");
    let plots = [("p1", 368_515.0, 6_807_440.0), ("p2", 368_545.0, 6_807_475.0)];
    let (l93, l2e) = (Projector::new(2154).unwrap(), Projector::new(27572).unwrap());
    let lonlat: Vec<(f64, f64)> = plots.iter().map(|p| l93.unproject(p.1, p.2).unwrap()).collect();
    let write = |name: &str, text: String| {
        let f = tmp.path().join(name);
        std::fs::write(&f, text).unwrap();
        f
    };
    // The tiles' CRS; WGS84 degrees as a spreadsheet exports them; Lambert II étendu (EPSG:27572).
    let xy = write(
        "xy.csv",
        plots.iter().map(|p| format!("{},{},{}\n", p.0, p.1, p.2)).fold("id,x,y\n".into(), |a, l| a + &l),
    );
    let deg = write(
        "deg.csv",
        plots.iter().zip(&lonlat).fold("\u{feff}plot_id;Latitude;Longitude\n".to_string(), |a, (p, (lon, lat))| {
            a + &format!("\"{}\";{lat:.12};{lon:.12}\n", p.0)
        }),
    );
    let ntf = write(
        "ntf.csv",
        plots.iter().zip(&lonlat).fold("plot\teasting\tnorthing\n".to_string(), |a, (p, (lon, lat))| {
            let (x, y) = l2e.project(*lon, *lat).unwrap();
            a + &format!("{}\t{x:.6}\t{y:.6}\n", p.0)
        }),
    );
    let run = |csv: &std::path::Path, extra: &[&str]| {
        let out = tmp.path().join(format!("{}.parquet", csv.file_stem().unwrap().to_string_lossy()));
        let mut args = vec![
            "simulate",
            "--als",
            tile.to_str().unwrap(),
            "--footprints",
            csv.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        let (ok, _, err) = gedisim(&args);
        (ok, err, out)
    };
    let (ok, err, out) = run(&xy, &[]);
    assert!(ok, "{err}");
    assert!(err.contains("taken in the ALS CRS EPSG:2154") && err.contains("--crs"), "said, not silent: {err}");
    let want = simulated(&out);
    assert_eq!(want.len(), 6);
    for (csv, extra, said) in
        [(&deg, &[][..], "lon, lat (WGS84) projected"), (&ntf, &["--crs", "EPSG:27572"][..], "EPSG:27572 reprojected")]
    {
        let (ok, err, out) = run(csv, extra);
        assert!(ok && err.contains(said), "{err}");
        let got = simulated(&out);
        assert_eq!(got.keys().collect::<Vec<_>>(), want.keys().collect::<Vec<_>>());
        for (k, (x, y, wave)) in &got {
            let (wx, wy, want_wave) = &want[k];
            assert!((x - wx).abs() < 1e-3 && (y - wy).abs() < 1e-3, "{k:?}: ({x}, {y}) vs ({wx}, {wy})");
            // The same waveform: positions equal to a micrometre weigh the points alike.
            assert_eq!(wave.len(), want_wave.len(), "{k:?}");
            let peak = want_wave.iter().fold(0f32, |m, v| m.max(*v));
            let worst = wave.iter().zip(want_wave).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
            assert!(worst <= 1e-4 * peak, "{k:?}: waveforms differ by {worst} (peak {peak})");
        }
    }
    // A CRS that cannot be right is one line, never a guess.
    for (csv, extra, needle) in [
        (&deg, &["--crs", "2154"][..], "lon, lat columns are WGS84 degrees"),
        // x, y said to be WGS84 degrees: these metres are out of range.
        (&xy, &["--crs", "4326"][..], "footprint `p1`: coordinate out of range"),
        (&xy, &["--crs", "4269"][..], "not a projected CRS"),
        (&xy, &["--crs", "999999"][..], "not in the EPSG database"),
    ] {
        let (ok, err, _) = run(csv, extra);
        assert!(!ok && err.trim().lines().count() == 1 && err.contains(needle), "{extra:?}: {err}");
    }
    let (ok, err, _) = run(&xy, &["--crs", "lambert"]);
    assert!(!ok && err.contains("`lambert` is not an EPSG code"), "{err}");
}

#[test]
fn sql_like_duckdb_statements_stdin_interactive_and_rh_by_name() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = report_dataset(&tmp.path().join("ds"));
    let d = ds.root().to_str().unwrap();
    // Several statements, results in order.
    let (ok, out, err) = gedisim(&["sql", "--dataset", d, "select 1 as first; select 2 as second"]);
    assert!(ok, "{err}");
    let (a, b) = (out.find("first").unwrap(), out.find("second").unwrap());
    assert!(a < b, "{out}");
    // RH by its percentile: rh(rh_sim, 98) is the list's element 99 (SQL lists count from 1).
    let q = "select count(*) as n, sum(case when rh(rh_sim, 98) = rh_sim[99] and rh(rh_aligned, 0) = rh_aligned[1] \
             then 1 else 0 end) as same from results";
    let (ok, out, err) = gedisim(&["sql", "--dataset", d, "--format", "csv", q]);
    assert!(ok, "{err}");
    let row: Vec<&str> = out.lines().nth(1).unwrap().split(',').collect();
    assert_eq!(row[0], row[1], "{out}");
    assert!(row[0].parse::<u64>().unwrap() > 0);
    let (ok, _, err) = gedisim(&["sql", "--dataset", d, "select rh(rh_sim, 101) from results"]);
    assert!(!ok && err.trim().lines().count() == 1 && err.contains("0…100"), "{err}");
    // From stdin: `-`, or nothing with a pipe.
    for args in
        [&["sql", "--dataset", d, "-"][..], &["sql", "--dataset", d][..], &["sql", "--dataset", d, "-f", "-"][..]]
    {
        let (ok, out, err) = gedisim_with_stdin(args, "select 40 + 2 as answer;\n");
        assert!(ok && out.contains("42"), "{args:?}: {err}");
    }
    // --out takes one result.
    let csv = tmp.path().join("two.csv");
    let (ok, _, err) =
        gedisim(&["sql", "--dataset", d, "--out", csv.to_str().unwrap(), "select 1 as a; select 2 as b"]);
    assert!(!ok && err.contains("a second statement gives a result") && !csv.exists(), "{err}");
    // Interactive: a failing statement is reported and the session goes on; a statement spans lines, also where a
    // line ends with a `;` inside a string or a comment.
    let input =
        "select 1 as a;\nselect nope from results;\nselect\n  3 as c;\nselect 'x;\ny' as s -- not yet;\n, 5 as \
                 five;\n\\q\nselect 4 as never;\n";
    let (ok, out, err) = gedisim_with_stdin(&["sql", "--dataset", d, "-i"], input);
    assert!(ok, "{err}");
    assert!(out.contains("| a |") && out.contains("| c |") && !out.contains("never"), "{out}");
    assert!(out.contains("| five |") && out.contains("x;"), "{out}");
    assert_eq!(err.matches("error: SQL").count(), 1, "{err}");
    assert!(err.contains("error: SQL") && err.contains("nope"), "{err}");
    // The functions document themselves: --help and information_schema.
    let (ok, out, _) = gedisim(&["sql", "--help"]);
    assert!(ok && out.contains("rh(rh_list, k)") && out.contains("gedi_l2a("), "{out}");
    let q = "select description from information_schema.routines where routine_name = 'rh'";
    let (ok, out, err) = gedisim(&["sql", "--dataset", d, q]);
    assert!(ok && out.contains("RH k (m) of an RH0"), "{out}{err}");
}

#[test]
fn demo_inputs_come_from_the_binary_not_the_source_tree() {
    // An empty working directory and a cache of its own: the tiles and the L1B the scenario needs
    // are written there from the binary, byte for byte the bundled files.
    let tmp = tempfile::tempdir().unwrap();
    let (work, cache) = (tmp.path().join("empty"), tmp.path().join("cache"));
    std::fs::create_dir_all(&work).unwrap();
    let scenario = |out: &str| {
        let args = ["scenario", "--effect", "none", "--passes", "1", "--out", out];
        let (ok, _, err) = gedisim_in(&work, &[("GEDISIM_CACHE", &cache)], &args);
        assert!(ok, "{err}");
    };
    scenario("world");
    let bundled = cache.join(format!("bundled-{}", env!("CARGO_PKG_VERSION")));
    for (dir, name) in [
        ("als", "lidarforfuel_1_42.laz"),
        ("als", "lidarforfuel_2_bas_lig.laz"),
        ("als", "pdal-ign-plugin_mnx_input_crop_2.laz"),
        ("gedi", "GEDI01_B_2019108080338_O01964_T05337_02_003_01_sub.h5"),
    ] {
        let written = std::fs::read(bundled.join(dir).join(name)).unwrap();
        assert!(written == std::fs::read(data(&format!("{dir}/{name}"))).unwrap(), "{name} differs");
    }
    assert!(work.join("world/truth.json").is_file() && work.join("world/als").is_dir());
    // A corrupted cached file is rewritten, not trusted.
    let tile = bundled.join("als/lidarforfuel_2_bas_lig.laz");
    std::fs::write(&tile, b"not a tile").unwrap();
    scenario("world2");
    assert!(std::fs::read(&tile).unwrap() == std::fs::read(data("als/lidarforfuel_2_bas_lig.laz")).unwrap());
}
