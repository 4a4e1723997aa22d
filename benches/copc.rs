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
//! Run with `cargo bench --profile dev --bench copc` (the README's build).

mod common;

use std::path::Path;

use common::{beams, extent, medians, s, scene_25m, timed, TO_LAS};

const REPS: usize = 5;

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
    let shots = beams(&extent(&scene), 2);
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
