//! Ingest benchmark (prints figures, asserts nothing): `gedisim ingest als` against the time the
//! `las` crate alone needs to decode the same LAZ, on the largest real tile and on a 25 M-point
//! scene (`lidarforfuel_2_bas_lig.laz` replicated 10 × 10 with X/Y offsets of (100·i, 100·j) m).
//!
//! Run with `cargo bench --profile dev --bench ingest` (the README's build). The scene is generated once into
//! `target/bench-data/`.

mod common;

use std::path::Path;

use common::{field, run, scene_25m};

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
