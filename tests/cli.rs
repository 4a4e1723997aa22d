//! The command line's conventions, through the binary: shell completions, `-v`/`-q`, `--threads`,
//! and one name per concept (`--dataset` for a dataset, `--als` for tiles).

mod common;
#[path = "common/study.rs"]
mod study;

use common::{data, gedisim};
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
