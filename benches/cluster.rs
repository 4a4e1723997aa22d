//! Cluster benchmark (prints figures, asserts nothing): the dense scene of the simulator benchmark
//! (25 M points, 2000 footprints on a 50 × 40 lattice) simulated from its dataset by
//! `simulate --dataset --footprints`, locally and on a Ballista cluster on this machine (`gedisim
//! cluster`) with one and with two executors of one task each. The machine has 2 cores, and one
//! task already simulates on every core (rayon): a second executor on the same 2 cores adds
//! coordination, not compute. The figure to read is the cluster's overhead over the local run;
//! the scaling with machines is planned in docs/scale.md. Runs are interleaved, 3 of each; medians.
//!
//! Run with `cargo bench --profile dev --bench cluster` (the README's build).

mod common;

use std::net::TcpListener;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::{field, run, scene_25m, write_lattice};

const BIN: &str = env!("CARGO_BIN_EXE_gedisim");
const RUNS: usize = 3;

/// A scheduler and executors on loopback, killed when dropped.
struct Cluster {
    url: String,
    procs: Vec<Child>,
}

impl Cluster {
    fn start(executors: usize) -> Cluster {
        let spawn = |args: &[&str]| Command::new(BIN).args(args).stdout(Stdio::null()).stderr(Stdio::null()).spawn();
        let scheduler = format!("127.0.0.1:{}", free_port_pair());
        let mut procs = vec![spawn(&["cluster", "scheduler", "--bind", &scheduler]).unwrap()];
        wait_until(|| std::net::TcpStream::connect(&scheduler).is_ok());
        for _ in 0..executors {
            let bind = format!("127.0.0.1:{}", free_port_pair());
            let args = ["cluster", "executor", "--scheduler", &scheduler, "--bind", &bind, "--concurrency", "1"];
            procs.push(spawn(&args).unwrap());
            wait_until(|| std::net::TcpStream::connect(&bind).is_ok());
        }
        // Registration follows the Flight port by a moment.
        std::thread::sleep(Duration::from_secs(2));
        Cluster { url: format!("df://{scheduler}"), procs }
    }

    /// Peak resident memory (MB) of each executor so far.
    fn executor_peaks_mb(&self) -> Vec<f64> {
        self.procs[1..].iter().map(|p| peak_rss_mb(p.id())).collect()
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        for p in &mut self.procs {
            let _ = p.kill();
            let _ = p.wait();
        }
    }
}

/// A port `p` such that `p` and `p + 1` (an executor's Flight and gRPC ports) are free now.
fn free_port_pair() -> u16 {
    loop {
        let a = TcpListener::bind("127.0.0.1:0").unwrap();
        let p = a.local_addr().unwrap().port();
        if p < u16::MAX && TcpListener::bind(("127.0.0.1", p + 1)).is_ok() {
            return p;
        }
    }
}

fn wait_until(ok: impl Fn() -> bool) {
    let start = Instant::now();
    while !ok() {
        assert!(start.elapsed() < Duration::from_secs(60), "cluster did not start");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// VmHWM of process `pid`, MB.
fn peak_rss_mb(pid: u32) -> f64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
    let kb: f64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .unwrap_or(f64::NAN);
    kb / 1024.0
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn same_file(a: &Path, b: &Path) -> bool {
    let read = |p: &Path| {
        let file = std::fs::File::open(p).unwrap();
        let reader = parquet::arrow::arrow_reader::ParquetRecordBatchReader::try_new(file, 1 << 16).unwrap();
        let batches: Vec<_> = reader.map(|b| b.unwrap()).collect();
        arrow::compute::concat_batches(&batches[0].schema(), &batches).unwrap()
    };
    read(a) == read(b)
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let scene = scene_25m(root);
    let lattice = write_lattice(&root.join("target/bench-data"), &scene, usize::MAX, "lattice2000.csv");
    let work = tempfile::tempdir().unwrap();
    let ds = work.path().join("ds");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    println!("cluster benchmark: {} (2 cores; wall clock of separate processes)", scene.display());
    let ingest = run(&["ingest", "als", &s(&scene), "--out", &s(&ds), "--stats"]);
    println!("  one-time ingest: {}", ingest.trim());

    let simulate = |name: &str, cluster: Option<&str>| {
        let out = work.path().join(name);
        let (ds, lattice, out_s) = (s(&ds), s(&lattice), s(&out));
        let mut args = vec!["simulate", "--dataset", &ds, "--footprints", &lattice, "--out", &out_s, "--stats"];
        if let Some(url) = cluster {
            args.extend(["--cluster", url]);
        }
        let start = Instant::now();
        let line = run(&args);
        (start.elapsed().as_secs_f64(), field(&line, " MB"), out)
    };
    let (mut local, mut one, mut two) = (Vec::new(), Vec::new(), Vec::new());
    let (mut client_mb, mut local_mb, mut one_mb, mut two_mb) = (0.0f64, 0.0f64, Vec::new(), Vec::new());
    let mut identical = true;
    for k in 0..RUNS {
        let (t, mb, reference) = simulate(&format!("local{k}.parquet"), None);
        local.push(t);
        local_mb = local_mb.max(mb);
        for (executors, times, peaks) in [(1, &mut one, &mut one_mb), (2, &mut two, &mut two_mb)] {
            let cluster = Cluster::start(executors);
            let (t, mb, out) = simulate(&format!("cluster{executors}-{k}.parquet"), Some(&cluster.url));
            times.push(t);
            client_mb = client_mb.max(mb);
            *peaks = cluster.executor_peaks_mb();
            identical &= same_file(&reference, &out);
        }
    }
    let (l, o, t) = (median(local), median(one), median(two));
    println!("  2000 footprints, medians of {RUNS}:");
    println!("    local (simulate --dataset)      : {l:.2} s, peak RSS {local_mb:.0} MB");
    println!("    cluster, 1 executor × 1 task    : {o:.2} s ({:.2}× local), executor peak {:.0} MB", o / l, one_mb[0]);
    println!(
        "    cluster, 2 executors × 1 task   : {t:.2} s ({:.2}× local, {:.2}× one executor), \
         executor peaks {:.0} + {:.0} MB",
        t / l,
        t / o,
        two_mb[0],
        two_mb[1]
    );
    println!("    client (gedisim simulate --cluster) peak RSS {client_mb:.0} MB");
    println!("    cluster output identical to the local file: {}", if identical { "yes" } else { "NO" });
}
