//! Ingest benchmark (prints figures, asserts nothing): `gedisim ingest als` against the time the
//! `las` crate alone needs to decode the same LAZ, on the largest real tile and on a 25 M-point
//! scene (`lidarforfuel_2_bas_lig.laz` replicated 10 × 10 with X/Y offsets of (100·i, 100·j) m).
//!
//! Run with `cargo bench --bench ingest`. The scene is generated once into `target/bench-data/`.

#[path = "../tests/common/scene.rs"]
mod scene;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let tile = root.join("tests/data/als/lidarforfuel_1_42.laz");
    let scene = scene_25m(root);
    println!("ingest benchmark (2 cores; times are wall clock of separate processes)");
    for file in [tile, scene] {
        let decode = run(&["bench", "decode", file.to_str().unwrap()]);
        let out = tempfile::tempdir().unwrap();
        let ingest = run(&["ingest", "als", file.to_str().unwrap(), "--out", out.path().to_str().unwrap(), "--stats"]);
        let (td, ti) = (field(&decode, " s,"), field(&ingest, " s,"));
        println!("{}", file.file_name().unwrap().to_string_lossy());
        println!("  las decode alone : {}", decode.trim());
        println!("  gedisim ingest   : {}", ingest.trim());
        println!("  ratio ingest/decode = {:.2}", ti / td);
    }
}

/// Run the release `gedisim` binary and return its stdout.
fn run(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_gedisim")).args(args).output().expect("run gedisim");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The number printed just before `suffix` (e.g. "12.3" before " s,").
fn field(line: &str, suffix: &str) -> f64 {
    let end = line.find(suffix).expect("figure in output");
    line[..end].trim_end().rsplit(' ').next().unwrap().parse().expect("number")
}

/// The 25 M-point scene as LAZ, generated on first use.
fn scene_25m(root: &Path) -> PathBuf {
    let dir = root.join("target/bench-data");
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("scene25M.laz");
    if path.exists() {
        return path;
    }
    let start = Instant::now();
    let n = scene::replicated_tile(&root.join("tests/data/als/lidarforfuel_2_bas_lig.laz"), 10, 10, 100.0, &path);
    println!("generated {} ({n} points) in {:.1} s", path.display(), start.elapsed().as_secs_f64());
    path
}
