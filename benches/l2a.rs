//! L2A benchmark (prints figures, asserts nothing): waveform-algorithm pairs per second on one
//! core, on the 300 real waveforms of the shared V1 granule (tests/data/gedi) × a1–a6.
//!
//! Run: `cargo bench --bench l2a` (release) or `cargo bench --profile dev --bench l2a`.
//! Two paths are timed: `process_all` (one waveform, six algorithms, smoothing shared: the CLI)
//! and `process` (one pair per call: the `gedi_l2a` SQL function, one row per pair).

#[allow(dead_code)]
#[path = "../tests/common/nasa.rs"]
mod nasa;

use std::hint::black_box;
use std::time::Instant;

use gedisim::kernels::waveform::l2a::{AlgorithmSettings, GaussianKernel, L2aProcessor};

/// Repetitions of each measurement; the best is reported (least disturbed by other processes).
const REPEATS: usize = 3;
/// Passes over the 300 waveforms per repetition.
const ROUNDS: usize = 10;

/// CPU time this thread has run (ns), from `/proc/thread-self/schedstat` (Linux): unlike wall
/// time it does not grow while other processes hold the cores.
fn thread_cpu_ns() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    s.split_whitespace().next()?.parse().ok()
}

/// Wall and CPU seconds of one run, and its count of processed pairs.
struct Timing {
    wall: f64,
    cpu: Option<f64>,
    ok: usize,
}

impl Timing {
    fn print(&self, label: &str, pairs: usize) {
        let per_cpu = self
            .cpu
            .map(|c| format!("{:.0} pairs/s per CPU-second ({c:.3} s CPU)", pairs as f64 / c))
            .unwrap_or_else(|| "CPU time unavailable".into());
        println!(
            "{label}: {pairs} pairs ({} processed) in {:.3} s wall = {:.0} pairs/s; {per_cpu}",
            self.ok,
            self.wall,
            pairs as f64 / self.wall
        );
    }
}

fn main() {
    let shots = nasa::load_real_shots();
    let settings = AlgorithmSettings::all_gedi();
    let mean_len = shots.iter().map(|s| s.wave.len()).sum::<usize>() as f64 / shots.len() as f64;
    let pairs = ROUNDS * shots.len() * settings.len();
    let build = if cfg!(debug_assertions) {
        "debug assertions on: dev/test profile, not a release build"
    } else {
        "no debug assertions: release-like profile"
    };
    println!(
        "L2A benchmark: {} real waveforms (mean length {mean_len:.0} samples) × {} algorithms, one thread; {build}",
        shots.len(),
        settings.len()
    );

    let mut processor = L2aProcessor::new();
    let mut outcomes = Vec::new();
    let best = |run: &mut dyn FnMut() -> usize| {
        run(); // warm-up: buffers and kernels in place
        (0..REPEATS)
            .map(|_| {
                let (start, cpu) = (Instant::now(), thread_cpu_ns());
                let ok = run();
                let cpu = cpu.zip(thread_cpu_ns()).map(|(a, b)| (b - a) as f64 * 1e-9);
                Timing { wall: start.elapsed().as_secs_f64(), cpu, ok }
            })
            .min_by(|a, b| a.cpu.unwrap_or(a.wall).total_cmp(&b.cpu.unwrap_or(b.wall)))
            .expect("at least one repetition")
    };

    let timing = best(&mut || {
        let mut ok = 0;
        for _ in 0..ROUNDS {
            for shot in &shots {
                processor.process_all(&shot.wave, shot.noise, &shot.geo, &settings, &mut outcomes);
                ok += black_box(&outcomes).iter().filter(|o| o.is_ok()).count();
            }
        }
        ok
    });
    timing.print("process_all (CLI path: one waveform, six algorithms)", pairs);

    let timing = best(&mut || {
        let mut ok = 0;
        for _ in 0..ROUNDS {
            for shot in &shots {
                for s in &settings {
                    let r = processor.process(&shot.wave, shot.noise, &shot.geo, s);
                    ok += usize::from(black_box(&r).is_ok());
                }
            }
        }
        ok
    });
    timing.print("process     (SQL path: one pair per call)      ", pairs);

    // Where the time goes: the two smoothings every waveform needs (widths 6.5 and 3.5).
    let kernels = [GaussianKernel::for_width(6.5), GaussianKernel::for_width(3.5)];
    let mut smoothed = Vec::new();
    let timing = best(&mut || {
        for _ in 0..ROUNDS {
            for shot in &shots {
                for k in &kernels {
                    k.smooth_into(&shot.wave, &mut smoothed);
                    black_box(&smoothed);
                }
            }
        }
        ROUNDS * shots.len()
    });
    let per_wave = |t: f64| 1e6 * t / (ROUNDS * shots.len()) as f64;
    println!(
        "of which smoothing (two kernels per waveform): {:.1} µs per waveform ({:.1} µs CPU)",
        per_wave(timing.wall),
        per_wave(timing.cpu.unwrap_or(f64::NAN))
    );
}
