//! Shared by the benchmarks: the 25 M-point scene and running the `gedisim` binary.
#![allow(dead_code)]

#[path = "../../tests/common/scene.rs"]
mod scene;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// Run the `gedisim` binary of this build and return its stdout (panics with its stderr on failure).
pub fn run(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_gedisim")).args(args).output().expect("run gedisim");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The number printed just before `suffix` (e.g. "12.3" before " s,").
pub fn field(line: &str, suffix: &str) -> f64 {
    let end = line.find(suffix).expect("figure in output");
    line[..end].trim_end().rsplit(' ').next().unwrap().parse().expect("number")
}

/// The 25 M-point scene as LAZ, generated on first use.
pub fn scene_25m(root: &Path) -> PathBuf {
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

/// The scene's extent [xmin, ymin, xmax, ymax] from its LAS header.
pub fn extent(path: &Path) -> [f64; 4] {
    let reader = las::Reader::from_path(path).unwrap();
    let b = reader.header().bounds();
    [b.min.x, b.min.y, b.max.x, b.max.y]
}
