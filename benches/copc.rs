//! The study's workload from COPC (prints figures, asserts nothing): the 25 M-point 1 km scene of
//! the simulator benchmark written as COPC by another tool (copclib, `tools/copc/write_copc.py
//! --depth 5 --grid 128`: 2729 nodes of 9,000 points on average),
//! two GEDI-like beams crossing it (600 m apart, shots 60 m apart along track), every shot
//! simulated with all three weightings.
//!
//! Side by side, interleaved, each a separate process timed by `/usr/bin/time` (wall, peak RSS):
//! - `gedisim simulate --als scene.copc.laz` (only the octree nodes around the shots decoded);
//! - gediRat on the same tile as LAS (it reads no LAZ), when `GEDISIM_GEDIRAT` names its binary;
//! - once each: `gedisim simulate --als scene.laz` (the whole tile decoded) and the COPC → LAS
//!   conversion gediRat needs (laspy with lazrs).
//!
//! Needs python3 with numpy, laspy, lazrs and copclib (`pip install copclib laspy lazrs`).
//! Run with `cargo bench --bench copc` (the README's build: the dev profile's optimisations).

mod common;

use std::path::Path;
use std::process::Command;

use common::{extent, scene_25m};

const REPS: usize = 5;

/// COPC → LAS with laspy: the COPC records dropped (laspy writes no COPC), the CRS EVLR kept.
const TO_LAS: &str = "import laspy, sys
from laspy.vlrs.vlrlist import VLRList
f = laspy.read(sys.argv[1])
f.header.vlrs = VLRList([v for v in f.header.vlrs if v.user_id != 'copc'])
f.vlrs = VLRList([v for v in f.vlrs if v.user_id != 'copc'])
f.evlrs = VLRList([v for v in (f.evlrs or []) if v.user_id != 'copc'])
f.write(sys.argv[2])";

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let scene = scene_25m(root);
    let dir = root.join("target/bench-data");
    let copc = dir.join("scene25M.copc.laz");
    if !copc.exists() {
        let tmp = dir.join("scene25M.tmp.copc.laz");
        let (s, _, _) = timed(
            "python3",
            &[
                root.join("tools/copc/write_copc.py").to_str().unwrap(),
                s(&scene),
                s(&tmp),
                "--depth",
                "5",
                "--grid",
                "128",
            ],
        );
        std::fs::rename(&tmp, &copc).unwrap();
        println!("wrote {} with copclib in {s:.1} s", copc.display());
    }
    let las = dir.join("scene25M.las");
    let (convert_s, convert_mb, _) = timed("python3", &["-c", TO_LAS, s(&copc), s(&las)]);
    let shots = beams(&extent(&scene));
    let csv = dir.join("beams.csv");
    let coords = dir.join("beams.coords");
    let mut c = String::from("id,x,y\n");
    let mut t = String::new();
    for (i, (x, y)) in shots.iter().enumerate() {
        c += &format!("s{i},{x:.2},{y:.2}\n");
        t += &format!("{x:.2} {y:.2} s{i}\n");
    }
    std::fs::write(&csv, c).unwrap();
    std::fs::write(&coords, t).unwrap();
    let work = tempfile::tempdir().unwrap();
    let out = |name: &str| work.path().join(name).to_str().unwrap().to_string();
    let gedisim = env!("CARGO_BIN_EXE_gedisim");
    let gedirat = std::env::var("GEDISIM_GEDIRAT").ok();

    println!(
        "study workload: {} shots on 2 beams over {} (25 M points), 2 cores, {REPS} interleaved runs",
        shots.len(),
        copc.display()
    );
    let (mut g, mut r) = (Vec::new(), Vec::new());
    let mut decoded = String::new();
    for _ in 0..REPS {
        let (w, m, err) =
            timed(gedisim, &["simulate", "--als", s(&copc), "--footprints", s(&csv), "--out", &out("copc.parquet")]);
        decoded = err.lines().find(|l| l.starts_with("COPC:")).unwrap_or("").to_string();
        g.push((w, m));
        if let Some(bin) = &gedirat {
            let args = ["-input", s(&las), "-listCoord", s(&coords), "-output", &out("rat.h5"), "-hdf", "-ground"];
            r.push(timed(bin, &args));
        }
    }
    let (lw, lm, _) =
        timed(gedisim, &["simulate", "--als", s(&scene), "--footprints", s(&csv), "--out", &out("laz.parquet")]);

    let (gw, gm) = medians(&g);
    println!("| path | wall (median) | peak RSS | points decoded |");
    println!("|---|---|---|---|");
    println!(
        "| `gedisim simulate --als scene.copc.laz` | {gw:.2} s | {gm:.0} MB | {} |",
        decoded.trim_start_matches("COPC: ")
    );
    println!("| `gedisim simulate --als scene.laz` (whole tile, 1 run) | {lw:.2} s | {lm:.0} MB | all |");
    println!(
        "| COPC → LAS with laspy (what gediRat needs first, 1 run) | {convert_s:.2} s | {convert_mb:.0} MB | all |"
    );
    if r.is_empty() {
        println!("(gediRat not run: set GEDISIM_GEDIRAT to its binary)");
        return;
    }
    let r: Vec<(f64, f64)> = r.into_iter().map(|(w, m, _)| (w, m)).collect();
    let (rw, rm) = medians(&r);
    println!("| gediRat on scene.las | {rw:.2} s | {rm:.0} MB | |");
    println!(
        "gedisim from COPC vs gediRat from LAS: {:.1}× faster (per run: {}), peak RSS {:.1} % of gediRat's",
        rw / gw,
        g.iter().zip(&r).map(|(a, b)| format!("{:.1}×", b.0 / a.0)).collect::<Vec<_>>().join(" "),
        100.0 * gm / rm
    );
    println!(
        "vs gediRat's whole workflow from the published COPC (conversion + gediRat): {:.1}×",
        (convert_s + rw) / gw
    );
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Run `program` under `/usr/bin/time`: (wall s, peak RSS MB, stderr). Panics if it fails.
fn timed(program: &str, args: &[&str]) -> (f64, f64, String) {
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

fn medians(v: &[(f64, f64)]) -> (f64, f64) {
    let med = |mut x: Vec<f64>| {
        x.sort_by(f64::total_cmp);
        x[x.len() / 2]
    };
    (med(v.iter().map(|p| p.0).collect()), med(v.iter().map(|p| p.1).collect()))
}

/// Two GEDI-like beams across the tile: parallel tracks heading 20° east of north, 600 m apart,
/// through the tile's centre ± 300 m, one shot every 60 m, those 20 m or more inside the tile.
fn beams(e: &[f64; 4]) -> Vec<(f64, f64)> {
    let (cx, cy) = ((e[0] + e[2]) / 2.0, (e[1] + e[3]) / 2.0);
    let (dx, dy) = (20f64.to_radians().sin(), 20f64.to_radians().cos());
    let mut out = Vec::new();
    for side in [-300.0, 300.0] {
        let (ox, oy) = (cx + side * dy, cy - side * dx);
        for k in -30..=30 {
            let (x, y) = (ox + 60.0 * k as f64 * dx, oy + 60.0 * k as f64 * dy);
            if x >= e[0] + 20.0 && x <= e[2] - 20.0 && y >= e[1] + 20.0 && y <= e[3] - 20.0 {
                out.push((x, y));
            }
        }
    }
    out
}
