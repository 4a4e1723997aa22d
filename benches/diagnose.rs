//! The withheld-effect benchmark of `gedisim diagnose` (issue 10): for every effect × magnitude ×
//! seed, a world is built with `gedisim scenario` on the three bundled tiles, diagnosed with the
//! whole chain (`diagnose --als --l1b --l2a`, told nothing), and scored against truth.json: is the
//! right effect first, how far does the held-out gap shrink, how close is its main parameter;
//! controls (`none`) must come out `unexplained`. Prints a table and the summary; asserts nothing.
//!
//! `cargo bench --profile perf --bench diagnose`
//! Environment: `GEDISIM_BENCH_EFFECTS` (comma list, default every effect), `GEDISIM_BENCH_MAGNITUDES`
//! (default `1,2`), `GEDISIM_BENCH_SEEDS` (default `1,2`), `GEDISIM_BENCH_CONTROLS` (control seeds,
//! default `1,2,3,4`), `GEDISIM_BENCH_DIR` (worlds kept there; default a temporary folder).

use gedisim::kernels::diagnose::json::DiagnosisJson;
use gedisim::kernels::scenario::effects::ParamValue;
use gedisim::kernels::scenario::truth::Truth;
use std::path::Path;
use std::process::Command;
use std::time::Instant;

const EFFECTS: [&str; 9] = [
    "datum",
    "ground_detection",
    "canopy_change",
    "occlusion",
    "weighting",
    "pulse",
    "footprint",
    "noise",
    "geolocation",
];

/// Main parameter of an effect (the one `--magnitude` scales) and its nominal value.
fn main_param(effect: &str) -> (&'static str, f64) {
    match effect {
        "datum" => ("dz_m", 0.0),
        "ground_detection" => ("offset_m", 0.0),
        "canopy_change" => ("fraction", 0.0),
        "occlusion" => ("gain", 0.0),
        "weighting" => ("rho_ground_over_veg", 1.0),
        "pulse" => ("pulse_sigma_m", 0.0),
        "footprint" => ("fsigma_m", 5.5),
        "noise" => ("noise_sigma_factor", 1.0),
        _ => ("shot_sigma_m", 0.0),
    }
}

fn list(var: &str, default: &str) -> Vec<String> {
    std::env::var(var)
        .unwrap_or_else(|_| default.to_string())
        .split(',')
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
        .collect()
}

fn run(args: &[&str]) -> bool {
    let out = Command::new(env!("CARGO_BIN_EXE_gedisim")).args(args).output().expect("gedisim runs");
    if !out.status.success() {
        eprintln!("gedisim {}: {}", args.join(" "), String::from_utf8_lossy(&out.stderr).lines().last().unwrap_or(""));
    }
    out.status.success()
}

struct Row {
    effect: String,
    magnitude: String,
    seed: String,
    first: String,
    unexplained: bool,
    shrink: f64,
    truth: f64,
    fitted: f64,
    seconds: f64,
}

fn world(dir: &Path, effect: &str, magnitude: &str, seed: &str) -> Option<Row> {
    let w = dir.join(format!("{effect}-m{magnitude}-s{seed}"));
    let _ = std::fs::remove_dir_all(&w);
    let ws = w.join("world");
    let mut args = vec!["scenario", "--effect", effect, "--seed", seed, "--out", ws.to_str()?];
    if effect != "none" {
        args.extend(["--magnitude", magnitude]);
    }
    if !run(&args) {
        return None;
    }
    let start = Instant::now();
    let (g, a, o) = (ws.join("gedi"), ws.join("als"), w.join("diagnosis"));
    if !run(&["diagnose", "--als", a.to_str()?, "--l1b", g.to_str()?, "--l2a", g.to_str()?, "--out", o.to_str()?]) {
        return None;
    }
    let seconds = start.elapsed().as_secs_f64();
    let d: DiagnosisJson = serde_json::from_str(&std::fs::read_to_string(o.join("diagnosis.json")).ok()?).ok()?;
    let t: Truth = serde_json::from_str(&std::fs::read_to_string(ws.join("truth.json")).ok()?).ok()?;
    let first = d.effects.first()?;
    let (p, _) = main_param(effect);
    let truth = t.effects.first().and_then(|e| e.number(p)).unwrap_or(f64::NAN);
    let fitted = match first.params.get(p) {
        Some(ParamValue::Number(x)) if first.name == effect => *x,
        _ => f64::NAN,
    };
    Some(Row {
        effect: effect.to_string(),
        magnitude: if effect == "none" { "-".into() } else { magnitude.to_string() },
        seed: seed.to_string(),
        first: first.name.clone(),
        unexplained: d.unexplained,
        shrink: first.held_out.shrink.unwrap_or(f64::NAN),
        truth,
        fitted,
        seconds,
    })
}

fn main() {
    let tmp = tempfile::tempdir().expect("temporary folder");
    let dir =
        std::env::var("GEDISIM_BENCH_DIR").map(std::path::PathBuf::from).unwrap_or_else(|_| tmp.path().to_path_buf());
    let effects = list("GEDISIM_BENCH_EFFECTS", &EFFECTS.join(","));
    let magnitudes = list("GEDISIM_BENCH_MAGNITUDES", "1,2");
    let seeds = list("GEDISIM_BENCH_SEEDS", "1,2");
    let controls = list("GEDISIM_BENCH_CONTROLS", "1,2,3,4");
    let mut jobs: Vec<(String, String, String)> = Vec::new();
    for e in &effects {
        for m in &magnitudes {
            for s in &seeds {
                jobs.push((e.clone(), m.clone(), s.clone()));
            }
        }
    }
    jobs.extend(controls.iter().map(|s| ("none".to_string(), "1".to_string(), s.clone())));
    println!(
        "{:<17} {:>4} {:>4}  {:<17} {:>11} {:>7}  {:>9} {:>9} {:>7}  {:>6}",
        "effect", "mag", "seed", "first", "unexplained", "shrink", "truth", "fitted", "error", "s"
    );
    let mut rows = Vec::new();
    for (e, m, s) in &jobs {
        let Some(r) = world(&dir, e, m, s) else {
            println!("{e:<17} {m:>4} {s:>4}  failed");
            continue;
        };
        let err = (r.fitted - r.truth).abs() / r.truth.abs();
        println!(
            "{:<17} {:>4} {:>4}  {:<17} {:>11} {:>7.2}  {:>9.3} {:>9.3} {:>6.0}%  {:>6.0}",
            r.effect,
            r.magnitude,
            r.seed,
            r.first,
            r.unexplained,
            r.shrink,
            r.truth,
            r.fitted,
            100.0 * err,
            r.seconds
        );
        rows.push(r);
    }
    let with: Vec<&Row> = rows.iter().filter(|r| r.effect != "none").collect();
    let right: Vec<&&Row> = with.iter().filter(|r| r.first == r.effect && !r.unexplained).collect();
    let n = with.len().max(1) as f64;
    let mut shrinks: Vec<f64> = right.iter().map(|r| r.shrink).collect();
    shrinks.sort_by(|a, b| a.total_cmp(b));
    let within = right.iter().filter(|r| (r.fitted - r.truth).abs() <= 0.2 * r.truth.abs()).count();
    let controls: Vec<&Row> = rows.iter().filter(|r| r.effect == "none").collect();
    println!();
    println!(
        "right effect first (and named): {}/{} = {:.0} %",
        right.len(),
        with.len(),
        100.0 * right.len() as f64 / n
    );
    if !shrinks.is_empty() {
        println!(
            "held-out shrink when right: median {:.2}, min {:.2}; ≥ 0.70 in {}/{}",
            shrinks[shrinks.len() / 2],
            shrinks[0],
            shrinks.iter().filter(|&&s| s >= 0.7).count(),
            shrinks.len()
        );
        println!("main parameter within 20 % of the truth when right: {within}/{}", right.len());
    }
    println!("controls unexplained: {}/{}", controls.iter().filter(|r| r.unexplained).count(), controls.len());
    for e in &effects {
        let of: Vec<&&Row> = with.iter().filter(|r| &r.effect == e).collect();
        let ok = of.iter().filter(|r| r.first == r.effect && !r.unexplained).count();
        println!("  {e:<17} right first {ok}/{}", of.len());
    }
}
