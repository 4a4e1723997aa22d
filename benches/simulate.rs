//! Simulator benchmark (prints figures, asserts nothing): the 25 M-point scene of the ingest
//! benchmark, 2000 footprints on a 50 × 40 lattice inside [min+20, max−20] m, all three
//! weightings, ground split, default pulse, `default` profile — the job the reference gediRat
//! needs 50.1 s and 2.16 GB for on this machine kind (4.1 s and 1.19 GB with 2 footprints;
//! docs/contracts.md).
//!
//! Two paths are timed, each as separate processes, with 2 and with 2000 footprints:
//! - direct mode from the LAZ (`simulate --als scene.laz`: the whole file decoded into memory);
//! - the dataset path: `ingest als` once, then `simulate --dataset --footprints` (memory bounded
//!   by a batch of footprints).
//!
//! Run with `cargo bench --profile dev --bench simulate` (the README's build).

mod common;

use std::path::{Path, PathBuf};

use common::{field, run, scene_25m, write_lattice};

/// The reference (gediRat) on this job: wall seconds and peak GB, 2000 and 2 footprints.
const REF_2000_S: f64 = 50.1;
const REF_2_S: f64 = 4.1;
const REF_RSS_GB: f64 = 2.16;

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let scene = scene_25m(root);
    let dir = root.join("target/bench-data");
    let lattice = write_lattice(&dir, &scene, usize::MAX, "lattice2000.csv");
    let pair = write_lattice(&dir, &scene, 2, "lattice2.csv");
    let work = tempfile::tempdir().unwrap();
    let out = |name: &str| work.path().join(name).to_str().unwrap().to_string();
    let s = |p: &PathBuf| p.to_str().unwrap().to_string();

    println!("simulator benchmark: {} (2 cores; wall clock of separate processes)", scene.display());
    let direct = |fp: &PathBuf, name: &str| {
        run(&["simulate", "--als", &s(&scene), "--footprints", &s(fp), "--out", &out(name), "--stats"])
    };
    let d2 = direct(&pair, "d2.parquet");
    let d2000 = direct(&lattice, "d2000.parquet");
    report("direct mode from the LAZ", &d2, &d2000, None);

    let ds = out("ds");
    let ingest = run(&["ingest", "als", &s(&scene), "--out", &ds, "--stats"]);
    let on_dataset = |fp: &PathBuf, name: &str| {
        run(&["simulate", "--dataset", &ds, "--footprints", &s(fp), "--out", &out(name), "--stats"])
    };
    let t2 = on_dataset(&pair, "t2.parquet");
    let t2000 = on_dataset(&lattice, "t2000.parquet");
    report("dataset path (ingest once, then simulate --dataset --footprints)", &t2, &t2000, Some(&ingest));
}

/// Print one path's figures and its ratios to the reference.
fn report(title: &str, two: &str, all: &str, ingest: Option<&str>) {
    let (t2, t2000) = (field(two, " s,"), field(all, " s,"));
    let rss = field(all, " MB").max(field(two, " MB"));
    let per_wave_ms = (t2000 - t2) / 1998.0 * 1e3;
    let ref_per_wave_ms = (REF_2000_S - REF_2_S) / 1998.0 * 1e3;
    println!("{title}");
    println!("  2 footprints    : {}", two.trim());
    println!("  2000 footprints : {}", all.trim());
    println!(
        "  per additional footprint: {per_wave_ms:.3} ms (reference {ref_per_wave_ms:.1} ms): {:.0}× faster",
        ref_per_wave_ms / per_wave_ms
    );
    println!("  end to end (2000): {t2000:.2} s vs {REF_2000_S} s: {:.1}× faster", REF_2000_S / t2000);
    println!("  peak RSS {rss:.0} MB = {:.1} % of the reference's {REF_RSS_GB} GB", rss / (REF_RSS_GB * 1e3) * 100.0);
    if let Some(ingest) = ingest {
        let ti = field(ingest, " s,");
        println!("  one-time ingest : {}", ingest.trim());
        println!(
            "  ingest + 2000 footprints: {:.2} s vs {REF_2000_S} s: {:.1}× faster",
            ti + t2000,
            REF_2000_S / (ti + t2000)
        );
    }
}
