//! Full-size GEDI granules (issue 42; prints figures, asserts nothing): `ingest gedi` of a V2
//! L1B/L2A pair at real size with 0.01 %, 0.1 %, 1 % and 100 % of its shots kept, side by side with
//! the small pair holding only the kept shots.
//!
//! The generator (here, not committed as data): 8 beams of `GEDISIM_BENCH_SHOTS / 8` shots
//! (default 1,040,000 in all), each beam a track going north 60 m a shot, beams 0.006° apart; every
//! shot's received record is one of the 300 real waveforms of the bundled V1 subset
//! (tests/data/gedi), padded at its top with that record's noise floor to 1,000–1,399 samples, with
//! fresh Gaussian noise of the record's own σ added to every sample (so that gzip meets real-like
//! noise); its transmit record is the real one's, with noise too; L2A values vary per shot. Stored as
//! the real subset's datasets are (`Storage::nasa`: per-shot chunks of 554,085 rows, waveform
//! chunks of 14,200 samples, N×101 chunks of 32 × 32, gzip 4). Shots are kept by `--bbox` (a run in the middle of every
//! beam); the small pair is written by the same generator with only those shots, under the same file
//! names. Each ingest runs with a cold page cache when the machine allows (`/proc/sys/vm/drop_caches`),
//! so the bytes read are those read from the disk (`/usr/bin/time` %I).
//!
//! Run with `cargo bench --profile dev --bench granule` (the README's build). The pairs are written
//! to `target/bench-data/granule/` and reused.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use arrow::array::{Array, AsArray};
use arrow::datatypes::{Float32Type, Float64Type};
use gedisim::io::granule::{write_l1b_v2, write_l2a_v2, Beam, GranuleMeta, Storage};
use gedisim::kernels::gedi::{v2_file_name, L1bShot, L2aShot};
use gedisim::ops::ingest_gedi::{read_gedi, GediOptions};
use rand_chacha::rand_core::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

const BEAMS: [&str; 8] =
    ["BEAM0000", "BEAM0001", "BEAM0010", "BEAM0011", "BEAM0101", "BEAM0110", "BEAM1000", "BEAM1011"];
const SHOT0: u64 = 241_560_000_200_000_000;
const LAT0: f64 = -30.0;
const DLAT: f64 = 5.4e-4;

/// A real shot of the bundled subset: received and transmitted records, noise σ.
struct Template {
    rx: Vec<f32>,
    tx: Vec<f32>,
    sigma: f32,
}

fn templates(root: &Path) -> Vec<Template> {
    let gedi = root.join("tests/data/gedi");
    let l1b = gedi.join("GEDI01_B_2019108080338_O01964_T05337_02_003_01_sub.h5");
    let l2a = gedi.join("GEDI02_A_2019108080338_O01964_T05337_02_001_01_sub.h5");
    let (batches, _) = read_gedi(&[l1b], &[l2a], &GediOptions::default()).unwrap();
    let mut out = Vec::new();
    for b in &batches {
        let (rx, tx) = (
            b.column_by_name("rx_waveform").unwrap().as_list::<i32>(),
            b.column_by_name("tx_waveform").unwrap().as_list::<i32>(),
        );
        let sigma = b.column_by_name("noise_stddev_corrected").unwrap().as_primitive::<Float64Type>();
        for i in 0..b.num_rows() {
            if rx.is_valid(i) && tx.is_valid(i) && sigma.is_valid(i) {
                let v = |l: &arrow::array::ListArray| l.value(i).as_primitive::<Float32Type>().values().to_vec();
                out.push(Template { rx: v(rx), tx: v(tx), sigma: sigma.value(i) as f32 });
            }
        }
    }
    out
}

/// A standard normal draw (Box–Muller).
fn normal(rng: &mut ChaCha8Rng) -> f32 {
    let u = |r: &mut ChaCha8Rng| ((r.next_u64() >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
    let (a, b) = (u(rng), u(rng));
    ((-2.0 * a.ln()).sqrt() * (2.0 * std::f64::consts::PI * b).cos()) as f32
}

fn lat_of(k: usize) -> f64 {
    LAT0 + k as f64 * DLAT
}

/// Shot `k` of beam `b` (the same whichever granule holds it).
fn shot(b: usize, k: usize, t: &[Template]) -> (L1bShot, L2aShot) {
    let mut rng = ChaCha8Rng::seed_from_u64(((b as u64) << 40) | k as u64);
    let tpl = &t[(k * 7 + b * 31) % t.len()];
    let len = 1000 + (rng.next_u32() % 400) as usize;
    let floor = tpl.rx[..20].iter().sum::<f32>() / 20.0;
    let pad = len.saturating_sub(tpl.rx.len());
    let rx: Vec<f32> = std::iter::repeat_n(floor, pad)
        .chain(tpl.rx.iter().copied())
        .take(len)
        .map(|v| v + tpl.sigma * normal(&mut rng))
        .collect();
    let tx: Vec<f32> = tpl.tx.iter().map(|v| v + 0.5 * tpl.sigma * normal(&mut rng)).collect();
    let (lat, lon) = (lat_of(k), 3.0 + b as f64 * 0.006);
    let shot_number = SHOT0 + b as u64 * 100_000_000 + k as u64;
    let delta_time = 52_000_000.0 + k as f64 * 0.0083;
    let l1b = L1bShot {
        shot_number,
        delta_time,
        rx_waveform: rx,
        tx_waveform: tx,
        latitude_bin0: lat + 1e-6,
        longitude_bin0: lon - 1e-6,
        latitude_lastbin: lat - 1e-6,
        longitude_lastbin: lon + 1e-6,
        elevation_bin0: 500.0 + normal(&mut rng) as f64,
        elevation_lastbin: 500.0 - 0.15 * (len - 1) as f64,
        noise_mean_corrected: floor as f64,
        noise_stddev_corrected: tpl.sigma as f64,
        stale_return_flag: 0,
        degrade: 0,
        geoid: 49.5,
        digital_elevation_model: 400.0,
    };
    let mut l2a =
        L2aShot { shot_number, delta_time, energy_total: 1500.0 + normal(&mut rng) * 50.0, ..Default::default() };
    let top = 1500.0 + 800.0 * normal(&mut rng).abs();
    for (a, alg) in l2a.algorithms.iter_mut().enumerate() {
        alg.elev_lowestmode = 420.0 + a as f32 + normal(&mut rng);
        alg.lat_lowestmode = lat + 2e-6;
        alg.lon_lowestmode = lon;
        alg.rh_cm = (0..101)
            .map(|i| (-300.0 + (top + 300.0) * (i as f32 / 100.0).powf(0.7) + normal(&mut rng) * 5.0) as i16)
            .collect();
        alg.sensitivity = 0.9 + 0.09 * (rng.next_u32() % 100) as f32 / 100.0;
        alg.quality_flag = (rng.next_u32() % 4 != 0) as u8;
    }
    l2a.select_algorithm(1 + (rng.next_u32() % 6) as u8);
    (l1b, l2a)
}

/// Write the pair of the shots `keep` of beams of `n` shots into `dir` (reused when present).
fn write_pair(dir: &Path, n: usize, keep: &dyn Fn(usize) -> bool, t: &[Template]) -> (PathBuf, PathBuf) {
    let l1b = dir.join(v2_file_name("01_B", "2023100120000", 24561, 2, 1234));
    let l2a = dir.join(v2_file_name("02_A", "2023100120000", 24561, 2, 1234));
    if l1b.exists() && l2a.exists() {
        return (l1b, l2a);
    }
    std::fs::create_dir_all(dir).unwrap();
    let start = Instant::now();
    let meta = GranuleMeta { storage: Storage::nasa(), ..Default::default() };
    let (mut b1, mut b2) = (Vec::new(), Vec::new());
    for (b, name) in BEAMS.iter().enumerate() {
        let (s1, s2): (Vec<_>, Vec<_>) = (0..n).filter(|&k| keep(k)).map(|k| shot(b, k, t)).unzip();
        b1.push(Beam::new(*name, s1));
        b2.push(Beam::new(*name, s2));
    }
    write_l2a_v2(&l2a, &b2, &meta).unwrap();
    drop(b2);
    write_l1b_v2(&l1b, &b1, &meta).unwrap();
    let size = |p: &Path| std::fs::metadata(p).unwrap().len() as f64 / 1e6;
    println!(
        "generated {} ({} shots): L1B {:.0} MB, L2A {:.0} MB in {:.0} s",
        dir.display(),
        b1.iter().map(|b| b.shots.len()).sum::<usize>(),
        size(&l1b),
        size(&l2a),
        start.elapsed().as_secs_f64()
    );
    (l1b, l2a)
}

/// Empty the page cache (root only): whether it could.
fn cold_cache() -> bool {
    let _ = Command::new("sync").status();
    std::fs::write("/proc/sys/vm/drop_caches", "1").is_ok()
}

/// `gedisim ingest gedi` into a new dataset: (wall s, peak RSS MB, MB read from disk, stderr).
fn ingest(l1b: &Path, l2a: &Path, area: &[&str]) -> (f64, f64, f64, String) {
    ingest_with(Path::new(env!("CARGO_BIN_EXE_gedisim")), l1b, l2a, area)
}

/// [`ingest`] by the gedisim binary `exe`.
fn ingest_with(exe: &Path, l1b: &Path, l2a: &Path, area: &[&str]) -> (f64, f64, f64, String) {
    let out = tempfile::tempdir().unwrap();
    let stats = tempfile::NamedTempFile::new().unwrap();
    let o = Command::new("/usr/bin/time")
        .args(["-f", "%e %M %I", "-o", common::s(stats.path()), common::s(exe), "ingest", "gedi"])
        .args(["--l1b", common::s(l1b), "--l2a", common::s(l2a), "--dataset", common::s(out.path())])
        .args(area)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "{err}");
    let line = std::fs::read_to_string(stats.path()).unwrap();
    let v: Vec<f64> = line.split_whitespace().map(|x| x.parse().unwrap()).collect();
    (v[0], v[1] / 1024.0, v[2] * 512.0 / 1e6, err)
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let total: usize = std::env::var("GEDISIM_BENCH_SHOTS").ok().and_then(|v| v.parse().ok()).unwrap_or(1_040_000);
    let n = total / BEAMS.len();
    let t = templates(root);
    let data = root.join(format!("target/bench-data/granule/{n}"));
    let (f1, f2) = write_pair(&data.join("full"), n, &|_| true, &t);
    let cold = cold_cache();
    println!(
        "granule benchmark: {} beams × {n} shots; `ingest gedi`, one run each, {} page cache (2 cores)",
        BEAMS.len(),
        if cold { "cold" } else { "warm (no permission to drop it; MB read are 0)" }
    );
    println!("| shots kept | granule | wall s | peak RSS MB | MB read | shots stored |");
    println!("|---|---|---|---|---|---|");
    for frac in [0.0001, 0.001, 0.01, 1.0] {
        let k = ((n as f64 * frac).round() as usize).max(1);
        let lo = (n - k) / 2;
        let keep = move |i: usize| (lo..lo + k).contains(&i);
        let (area, small) = if frac < 1.0 {
            let bbox = format!("2.99,{},3.06,{}", lat_of(lo) - DLAT / 2.0, lat_of(lo + k - 1) + DLAT / 2.0);
            (vec!["--bbox".to_string(), bbox], Some(write_pair(&data.join(format!("kept{k}")), n, &keep, &t)))
        } else {
            (vec!["--all-shots".to_string()], None)
        };
        let area: Vec<&str> = area.iter().map(String::as_str).collect();
        let stored = |err: &str| {
            err.lines()
                .find_map(|l| l.split(": ").last()?.strip_suffix(" shots").map(str::to_string))
                .unwrap_or_default()
        };
        cold_cache();
        let (w, m, r, err) = ingest(&f1, &f2, &area);
        println!(
            "| {:.2} % ({}) | full, {} | {w:.2} | {m:.0} | {r:.0} | {} |",
            frac * 100.0,
            k * BEAMS.len(),
            area[0],
            stored(&err)
        );
        if let Some((s1, s2)) = small {
            cold_cache();
            let (ws, ms, rs, err) = ingest(&s1, &s2, &["--all-shots"]);
            println!("| | small, only those shots | {ws:.2} | {ms:.0} | {rs:.0} | {} |", stored(&err));
            println!("| | ratio full / small | {:.1} | {:.1} | | |", w / ws, m / ms);
        }
    }
    many_runs(n, &f1, &f2);
}

/// Runs of kept shots a beam in [`many_runs`].
const RUNS: usize = 50;

/// 0.1 % of the shots kept in [`RUNS`] runs a beam (`--within` boxes across every beam, as plots
/// along the tracks), against the same count in one run; with `GEDISIM_BENCH_BEFORE=<a gedisim
/// binary>`, that binary too, in the same run (e.g. one without the chunk cache of src/io/gedi.rs).
fn many_runs(n: usize, f1: &Path, f2: &Path) {
    let per_run = ((n as f64 * 0.001 / RUNS as f64).round() as usize).max(1);
    let step = n / (RUNS + 1);
    let box_of = |lo: usize, hi: usize| {
        let (s, n) = (lat_of(lo) - DLAT / 2.0, lat_of(hi - 1) + DLAT / 2.0);
        format!("[[[2.99,{s}],[3.06,{s}],[3.06,{n}],[2.99,{n}],[2.99,{s}]]]")
    };
    let boxes: Vec<String> = (1..=RUNS).map(|j| box_of(j * step, j * step + per_run)).collect();
    let dir = tempfile::tempdir().unwrap();
    let within = dir.path().join("runs.geojson");
    std::fs::write(&within, format!(r#"{{"type":"MultiPolygon","coordinates":[{}]}}"#, boxes.join(","))).unwrap();
    let one = box_of(n / 2, n / 2 + per_run * RUNS);
    let single = dir.path().join("one.geojson");
    std::fs::write(&single, format!(r#"{{"type":"Polygon","coordinates":{one}}}"#)).unwrap();
    let mut binaries = vec![("this build".to_string(), PathBuf::from(env!("CARGO_BIN_EXE_gedisim")))];
    if let Ok(before) = std::env::var("GEDISIM_BENCH_BEFORE") {
        binaries.push((format!("GEDISIM_BENCH_BEFORE ({before})"), PathBuf::from(before)));
    }
    println!("\n{} shots a beam kept in {RUNS} runs of {per_run} vs one run (`--within`, 8 beams):", RUNS * per_run);
    println!("| binary | runs a beam | wall s | peak RSS MB | MB read | shots stored |");
    println!("|---|---|---|---|---|---|");
    for (name, exe) in &binaries {
        for (runs, file) in [(1, &single), (RUNS, &within)] {
            cold_cache();
            let (w, m, r, err) = ingest_with(exe, f1, f2, &["--within", common::s(file)]);
            let kept = err.lines().find(|l| l.contains("kept within")).and_then(|l| l.split_whitespace().next());
            let kept = kept.unwrap_or("?");
            println!("| {name} | {runs} | {w:.2} | {m:.0} | {r:.0} | {kept} |");
        }
    }
}
