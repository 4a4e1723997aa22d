//! Shared by the benchmarks: the 25 M-point scene and running the `gedisim` binary.
#![allow(dead_code)]

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
    let src = root.join("tests/data/als/lidarforfuel_2_bas_lig.laz");
    let mut reader = las::Reader::from_path(&src).unwrap();
    let points: Vec<las::Point> = reader.read_all().unwrap().points().map(|p| p.unwrap()).collect();
    let mut builder = las::Builder::from(reader.header().clone());
    builder.point_format.is_compressed = true;
    builder.evlrs.clear();
    let header = builder.into_header().unwrap();
    // The extension decides compression in `las::Writer::from_path`: keep `.laz` last.
    let tmp = dir.join("scene25M.tmp.laz");
    let mut writer = las::Writer::from_path(&tmp, header).unwrap();
    for i in 0..10 {
        for j in 0..10 {
            for p in &points {
                let mut q = p.clone();
                q.x += 100.0 * i as f64;
                q.y += 100.0 * j as f64;
                writer.write_point(q).unwrap();
            }
        }
    }
    writer.close().unwrap();
    drop(writer);
    std::fs::rename(&tmp, &path).unwrap();
    println!("generated {} ({} points) in {:.1} s", path.display(), points.len() * 100, start.elapsed().as_secs_f64());
    path
}

/// The scene's extent [xmin, ymin, xmax, ymax] from its LAS header.
pub fn extent(path: &Path) -> [f64; 4] {
    let reader = las::Reader::from_path(path).unwrap();
    let b = reader.header().bounds();
    [b.min.x, b.min.y, b.max.x, b.max.y]
}
