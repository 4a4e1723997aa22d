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

/// COPC → LAS with laspy: the COPC records dropped (laspy writes no COPC), the CRS EVLR kept.
pub const TO_LAS: &str = "import laspy, sys
from laspy.vlrs.vlrlist import VLRList
f = laspy.read(sys.argv[1])
f.header.vlrs = VLRList([v for v in f.header.vlrs if v.user_id != 'copc'])
f.vlrs = VLRList([v for v in f.vlrs if v.user_id != 'copc'])
f.evlrs = VLRList([v for v in (f.evlrs or []) if v.user_id != 'copc'])
f.write(sys.argv[2])";

pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Run `program` under `/usr/bin/time`: (wall s, peak RSS MB, stderr). Panics if it fails.
pub fn timed(program: &str, args: &[&str]) -> (f64, f64, String) {
    let stats = tempfile::NamedTempFile::new().unwrap();
    let o = Command::new("/usr/bin/time")
        .args(["-f", "%e %M", "-o", stats.path().to_str().unwrap(), program])
        .args(args)
        .output()
        .expect("run /usr/bin/time");
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "{program} {args:?}: {err}");
    let line = std::fs::read_to_string(stats.path()).unwrap();
    let mut f = line.split_whitespace().map(|v| v.parse::<f64>().unwrap());
    (f.next().unwrap(), f.next().unwrap() / 1024.0, err)
}

pub fn medians(v: &[(f64, f64)]) -> (f64, f64) {
    let med = |mut x: Vec<f64>| {
        x.sort_by(f64::total_cmp);
        x[x.len() / 2]
    };
    (med(v.iter().map(|p| p.0).collect()), med(v.iter().map(|p| p.1).collect()))
}

/// GEDI-like beams across the extent `e`: `n` parallel tracks heading 20° east of north, 600 m
/// apart, centred on the extent's centre, one shot every 60 m, those 20 m or more inside `e`.
pub fn beams(e: &[f64; 4], n: usize) -> Vec<(f64, f64)> {
    let (cx, cy) = ((e[0] + e[2]) / 2.0, (e[1] + e[3]) / 2.0);
    let (dx, dy) = (20f64.to_radians().sin(), 20f64.to_radians().cos());
    let reach = ((e[2] - e[0]).hypot(e[3] - e[1]) / 120.0).ceil() as i64;
    let mut out = Vec::new();
    for b in 0..n {
        let side = 600.0 * (b as f64 - (n as f64 - 1.0) / 2.0);
        let (ox, oy) = (cx + side * dy, cy - side * dx);
        for k in -reach..=reach {
            let (x, y) = (ox + 60.0 * k as f64 * dx, oy + 60.0 * k as f64 * dy);
            if x >= e[0] + 20.0 && x <= e[2] - 20.0 && y >= e[1] + 20.0 && y <= e[3] - 20.0 {
                out.push((x, y));
            }
        }
    }
    out
}

/// The lattice: x = xmin+20+(i+0.5)·W/50, y = ymin+20+(j+0.5)·H/40, W = H = extent − 40 m
/// (the first `n` of its 2000 points), as an `id,x,y` CSV.
pub fn write_lattice(dir: &Path, scene: &Path, n: usize, name: &str) -> PathBuf {
    let [xmin, ymin, xmax, ymax] = extent(scene);
    let (w, h) = (xmax - xmin - 40.0, ymax - ymin - 40.0);
    let mut csv = String::from("id,x,y\n");
    let mut k = 0;
    'outer: for j in 0..40 {
        for i in 0..50 {
            if k == n {
                break 'outer;
            }
            let x = xmin + 20.0 + (i as f64 + 0.5) * w / 50.0;
            let y = ymin + 20.0 + (j as f64 + 0.5) * h / 40.0;
            csv.push_str(&format!("fp{k},{x:.3},{y:.3}\n"));
            k += 1;
        }
    }
    let path = dir.join(name);
    std::fs::write(&path, csv).unwrap();
    path
}
