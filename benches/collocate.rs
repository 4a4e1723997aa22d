//! Collocation benchmark (prints figures, asserts nothing): `gedisim collocate` on the 25 M-point
//! scene of `benches/ingest.rs` (`lidarforfuel_2_bas_lig.laz` replicated 10 × 10 with X/Y offsets
//! of (100·i, 100·j) m), a 40-shot beam on the diagonal from (xmin+100, ymin+100) to
//! (xmax−100, ymax−100) whose "real" waveforms were formed 4 m east and 3 m south of the reported
//! positions and 47.5 m higher (ingested with `--geoid-offset 0`, so the vertical solve finds the
//! whole datum gap). Search ±10 m at 1 m, vertical solve included; one segment of 40 shots.
//!
//! Run with `cargo bench --bench collocate` (release) or `cargo bench --profile dev --bench
//! collocate`. The scene and its ingested `als/` table are made once into `target/bench-data/`.
//! Reference (docs/contracts.md, docs/simulator-reference.md §6.4): collocateWaves on a planted 40-shot
//! track of the same scene, same grid: 105.7 s wall, 1.27 GB max RSS.

mod common;
#[path = "../tests/common/planted.rs"]
mod planted;

use std::path::{Path, PathBuf};
use std::time::Instant;

use arrow::array::AsArray;
use arrow::datatypes::{Float64Type, UInt32Type};
use common::{field, run, scene_25m};
use gedisim::dataset::Dataset;
use planted::{write_planted_l1b, Plant, PlantedBeam};

/// Scene extent (docs/simulator-reference.md §6.3).
const SCENE: [f64; 4] = [368478.10, 6807406.82, 369478.09, 6808406.81];

const REFERENCE_S: f64 = 105.7;
const REFERENCE_GB: f64 = 1.27;

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let laz = scene_25m(root);
    let bench_data = root.join("target/bench-data");
    let als_dataset = bench_data.join("scene25M-dataset");
    if !als_dataset.join("tiles").is_dir() {
        let t = Instant::now();
        let _ = std::fs::remove_dir_all(&als_dataset);
        run(&["ingest", "als", laz.to_str().unwrap(), "--out", als_dataset.to_str().unwrap()]);
        println!("ingested the scene into {} in {:.1} s", als_dataset.display(), t.elapsed().as_secs_f64());
    }

    // A dataset sharing the scene's `als/` and `tiles/` tables (points are visible with their tile
    // row), with the planted granule.
    let tmp = tempfile::tempdir().unwrap();
    for table in ["als", "tiles"] {
        std::os::unix::fs::symlink(als_dataset.join(table), tmp.path().join(table)).unwrap();
    }
    let ds = Dataset::open(tmp.path()).unwrap();
    let beam = PlantedBeam {
        name: "BEAM0101",
        start: (SCENE[0] + 100.0, SCENE[1] + 100.0),
        end: (SCENE[2] - 100.0, SCENE[3] - 100.0),
        shots: 40,
        energy: 6000.0,
    };
    let plant = Plant { shift: (4.0, -3.0), datum: 47.5, l1b_geoid: 47.3, noise_sigma: 2.5, seed: 11 };
    let l1b: PathBuf = tmp.path().join(gedisim::kernels::gedi::v2_file_name("01_B", "2019108080338", 1964, 2, 5337));
    write_planted_l1b(&ds, &[beam], &plant, &l1b);
    run(&[
        "ingest",
        "gedi",
        "--l1b",
        l1b.to_str().unwrap(),
        "--out",
        tmp.path().to_str().unwrap(),
        "--geoid-offset",
        "0",
    ]);

    let t = Instant::now();
    let out = run(&["collocate", "--dataset", tmp.path().to_str().unwrap(), "--stats"]);
    let wall = t.elapsed().as_secs_f64();
    let rss_mb = field(&out, " MB,");
    println!(
        "collocate benchmark: 24,719,400 ALS points, 40 shots, ±10 m at 1 m (441 offsets), vertical solve \
        included (2 cores)"
    );
    println!("  gedisim collocate : {wall:.2} s wall (process), {}", out.trim());
    println!(
        "  reference         : {REFERENCE_S} s, {REFERENCE_GB} GB (collocateWaves, docs/simulator-reference.md §6.4)"
    );
    let cpu = field(&out, " s, peak");
    println!(
        "  speed-up {:.0}× (wall), {:.0}× (CPU time against the reference's single-threaded user time 100.0 s); \
            memory {:.1}× smaller",
        REFERENCE_S / wall,
        100.0 / cpu,
        REFERENCE_GB * 1024.0 / rss_mb
    );
    print_offsets(tmp.path(), &plant);
}

fn print_offsets(ds: &Path, plant: &Plant) {
    let f = std::fs::File::open(ds.join("offsets/offsets.parquet")).unwrap();
    let reader = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(f).unwrap().build().unwrap();
    for b in reader {
        let b = b.unwrap();
        let v = |c: &str, i: usize| b.column_by_name(c).unwrap().as_primitive::<Float64Type>().value(i);
        let n = b.column_by_name("n_shots").unwrap().as_primitive::<UInt32Type>().clone();
        for i in 0..b.num_rows() {
            println!(
                "  recovered: dx {:+.2} dy {:+.2} dz {:+.3} m (planted {:+.1} {:+.1} {:+.1}) from {} shots; r {:.3} \
                    → {:.4}",
                v("dx", i),
                v("dy", i),
                v("dz", i),
                plant.shift.0,
                plant.shift.1,
                plant.datum,
                n.value(i),
                v("r_before", i),
                v("r_after", i)
            );
            println!(
                "  sharpness (half-extent within 0.005 of the best r): dx {:.2} dy {:.2} dz {:.3} m",
                v("dx_halfwidth", i),
                v("dy_halfwidth", i),
                v("dz_halfwidth", i)
            );
        }
    }
}
