//! The study's workload over 16 tiles (prints figures, asserts nothing): a 4 × 4 km block of 1 km
//! COPC tiles, eight GEDI-like beams crossing it (600 m apart across track, shots 60 m apart along
//! track), every shot simulated with all three weightings.
//!
//! The tiles: the 25 M-point scene of the simulator benchmark (the bundled LiDAR HD tile
//! replicated to 1 km), written as COPC by copclib (`tools/copc/write_copc.py --depth 5 --grid
//! 128`, as the `copc` bench does), then copied 16 times with the header's offsets and bounds (and
//! the COPC cube's centre) moved by whole kilometres: the same compressed points, translated. The
//! LAS files gediRat reads are the scene's LAS translated alike.
//!
//! Side by side, interleaved, each a separate process timed by `/usr/bin/time` (wall, peak RSS):
//! - `gedisim simulate --als <the 16 COPC tiles>` (only the octree nodes around the shots decoded);
//! - gediRat on the 16 LAS tiles, when `GEDISIM_GEDIRAT` names its binary: one run per tile with
//!   the shots inside it, as a study scripts it. (One run over all 16 with `-inList` would hold the
//!   points of the whole block, ≈ 400 M: more memory than the machine has.) Its wall time is the
//!   sum over the tiles, its peak RSS the largest.
//!
//! Needs what the `copc` bench needs (it makes the scene's COPC and LAS files first: run it once).
//! Run with `GEDISIM_GEDIRAT=<gediRat> cargo bench --profile dev --bench workload`.

mod common;

use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use common::{beams, medians, s, timed};

const REPS: usize = 3;
const SIDE: usize = 4;

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = root.join("target/bench-data");
    let (copc, las) = (dir.join("scene25M.copc.laz"), dir.join("scene25M.las"));
    assert!(copc.exists() && las.exists(), "run `cargo bench --profile dev --bench copc` first");
    let (copc_dir, las_dir) = (dir.join("grid16-copc"), dir.join("grid16-las"));
    let mut las_files = Vec::new();
    let mut extents = Vec::new();
    let e = header_extent(&copc);
    for i in 0..SIDE {
        for j in 0..SIDE {
            let (dx, dy) = (1000.0 * i as f64, 1000.0 * j as f64);
            translated(&copc, &copc_dir.join(format!("t{i}{j}.copc.laz")), dx, dy);
            las_files.push(translated(&las, &las_dir.join(format!("t{i}{j}.las")), dx, dy));
            extents.push([e[0] + dx, e[1] + dy, e[2] + dx, e[3] + dy]);
        }
    }
    let block = [e[0], e[1], e[2] + 1000.0 * (SIDE - 1) as f64, e[3] + 1000.0 * (SIDE - 1) as f64];
    let shots = beams(&block, 8);
    let csv = dir.join("grid16.csv");
    let mut c = String::from("id,x,y\n");
    for (i, (x, y)) in shots.iter().enumerate() {
        c += &format!("s{i},{x:.2},{y:.2}\n");
    }
    std::fs::write(&csv, c).unwrap();
    // gediRat's coordinate list of each tile: the shots inside it.
    let mut per_tile = Vec::new();
    for (k, t) in extents.iter().enumerate() {
        let inside: Vec<String> = (shots.iter().enumerate())
            .filter(|(_, (x, y))| *x >= t[0] && *x < t[2] && *y >= t[1] && *y < t[3])
            .map(|(i, (x, y))| format!("{x:.2} {y:.2} s{i}\n"))
            .collect();
        if !inside.is_empty() {
            let coords = dir.join(format!("grid16-t{k}.coords"));
            std::fs::write(&coords, inside.concat()).unwrap();
            per_tile.push((las_files[k].clone(), coords));
        }
    }
    let work = tempfile::tempdir().unwrap();
    let out = |name: &str| work.path().join(name).to_str().unwrap().to_string();
    let gedisim = env!("CARGO_BIN_EXE_gedisim");
    let gedirat = std::env::var("GEDISIM_GEDIRAT").ok();

    println!(
        "study workload: {} shots on 8 beams over {} COPC tiles of 1 km (25 M points each), 2 cores, {REPS} \
         interleaved runs",
        shots.len(),
        SIDE * SIDE
    );
    let (mut g, mut r) = (Vec::new(), Vec::new());
    let mut decoded = String::new();
    for _ in 0..REPS {
        let (w, m, err) =
            timed(gedisim, &["simulate", "--als", s(&copc_dir), "--footprints", s(&csv), "--out", &out("g.parquet")]);
        decoded = err.lines().find(|l| l.starts_with("COPC:")).unwrap_or("").to_string();
        g.push((w, m));
        if let Some(bin) = &gedirat {
            let (mut wall, mut rss) = (0.0, 0.0f64);
            for (las, coords) in &per_tile {
                let args = ["-input", s(las), "-listCoord", s(coords), "-output", &out("rat.h5"), "-hdf", "-ground"];
                let (w, m, _) = timed(bin, &args);
                (wall, rss) = (wall + w, rss.max(m));
            }
            r.push((wall, rss));
        }
    }
    let (gw, gm) = medians(&g);
    println!("| path | wall (median) | peak RSS | points decoded |");
    println!("|---|---|---|---|");
    println!(
        "| `gedisim simulate --als <16 COPC tiles>` | {gw:.2} s | {gm:.0} MB | {} |",
        decoded.trim_start_matches("COPC: ")
    );
    if r.is_empty() {
        println!("(gediRat not run: set GEDISIM_GEDIRAT to its binary)");
        return;
    }
    let (rw, rm) = medians(&r);
    println!("| gediRat on the LAS tiles, one run per tile ({} runs) | {rw:.2} s | {rm:.0} MB | all |", per_tile.len());
    println!(
        "gedisim from COPC vs gediRat from LAS: {:.1}× faster (per run: {}), peak RSS {:.1} % of gediRat's",
        rw / gw,
        g.iter().zip(&r).map(|(a, b)| format!("{:.1}×", b.0 / a.0)).collect::<Vec<_>>().join(" "),
        100.0 * gm / rm
    );
}

/// [xmin, ymin, xmax, ymax] of a LAS/LAZ file's header.
fn header_extent(path: &Path) -> [f64; 4] {
    let b = las::Reader::from_path(path).unwrap().header().bounds();
    [b.min.x, b.min.y, b.max.x, b.max.y]
}

/// A copy of the LAS/LAZ/COPC file `src` moved by (dx, dy) m, at `dest` (made once): the header's
/// x and y offsets and bounds moved, and the COPC info VLR's cube centre when there is one. The
/// point records store coordinates relative to the offsets, so they are the same bytes.
fn translated(src: &Path, dest: &Path, dx: f64, dy: f64) -> PathBuf {
    if dest.exists() {
        return dest.to_path_buf();
    }
    std::fs::create_dir_all(dest.parent().unwrap()).unwrap();
    let tmp = dest.with_extension("tmp");
    std::fs::copy(src, &tmp).unwrap();
    let mut f = std::fs::OpenOptions::new().read(true).write(true).open(&tmp).unwrap();
    let mut head = vec![0u8; 375];
    f.read_exact(&mut head).unwrap();
    let get = |b: &[u8], at: usize| f64::from_le_bytes(b[at..at + 8].try_into().unwrap());
    // LAS 1.2–1.4: x/y offsets at 155/163, max x/min x/max y/min y at 179/187/195/203.
    for (at, d) in [(155, dx), (163, dy), (179, dx), (187, dx), (195, dy), (203, dy)] {
        let v = get(&head, at) + d;
        head[at..at + 8].copy_from_slice(&v.to_le_bytes());
    }
    f.seek(SeekFrom::Start(0)).unwrap();
    f.write_all(&head).unwrap();
    // The COPC info VLR (`copc`/1) is the first VLR: its data (cube centre x, y first) after its
    // 54-byte header.
    let header_size = u16::from_le_bytes([head[94], head[95]]) as u64;
    let mut vlr = [0u8; 54 + 16];
    f.seek(SeekFrom::Start(header_size)).unwrap();
    if f.read_exact(&mut vlr).is_ok() && &vlr[2..6] == b"copc" && u16::from_le_bytes([vlr[18], vlr[19]]) == 1 {
        let (x, y) = (get(&vlr, 54) + dx, get(&vlr, 62) + dy);
        f.seek(SeekFrom::Start(header_size + 54)).unwrap();
        f.write_all(&x.to_le_bytes()).unwrap();
        f.write_all(&y.to_le_bytes()).unwrap();
    }
    drop(f);
    std::fs::rename(&tmp, dest).unwrap();
    dest.to_path_buf()
}
