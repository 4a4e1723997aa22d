//! The same SQL, simulation and study on an Apache Ballista cluster (docs/scale.md): a scheduler and
//! two executors started as separate `gedisim cluster` processes on loopback. Every `queries/*.sql`
//! and a `gedi_simulate()` query give the local engine's rows; `run --cluster` writes the local
//! run's `offsets/`, `sim/` and `results/`; a query survives an executor killed while it runs (or ends with one
//! line and no output); a bad cluster address is one line, not a hang.

#![cfg(feature = "cluster")]

mod common;

use std::io::{BufRead, BufReader};
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use arrow::array::RecordBatch;
use arrow::datatypes::DataType;
use arrow::util::display::array_value_to_string;
use common::{data, gedisim};
use gedisim::dataset::Dataset;
use gedisim::ops::report::{run_queries, QueryOutcome};
use gedisim::ops::sql::SqlSession;
use gedisim::sql::Engine;

const BIN: &str = env!("CARGO_BIN_EXE_gedisim");

/// A process killed when dropped.
struct Process(Child);

impl Drop for Process {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A port `p` such that `p` and `p + 1` are free now.
fn free_port_pair() -> u16 {
    loop {
        let a = TcpListener::bind("127.0.0.1:0").unwrap();
        let p = a.local_addr().unwrap().port();
        if p < u16::MAX && TcpListener::bind(("127.0.0.1", p + 1)).is_ok() {
            return p;
        }
    }
}

/// Wait until `log` holds `needle` `times` times; false after `limit`.
fn wait_for_log(log: &Path, needle: &str, times: usize, limit: Duration) -> bool {
    let start = Instant::now();
    while start.elapsed() < limit {
        let text = std::fs::read_to_string(log).unwrap_or_default();
        if text.matches(needle).count() >= times {
            return true;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    false
}

/// The exit status and stderr lines of `child` (stderr piped), failing if it runs longer than `limit` (a hang).
fn finish(child: &mut Process, limit: Duration, what: &str) -> (std::process::ExitStatus, Vec<String>) {
    let start = Instant::now();
    let status = loop {
        if let Some(s) = child.0.try_wait().unwrap() {
            break s;
        }
        assert!(start.elapsed() < limit, "{what} hung");
        std::thread::sleep(Duration::from_millis(50));
    };
    let stderr = BufReader::new(child.0.stderr.take().unwrap()).lines().map(|l| l.unwrap()).collect();
    (status, stderr)
}

/// A scheduler and `executors` executors (one task at a time each), their logs in `dir`.
struct Cluster {
    url: String,
    executors: Vec<Process>,
    logs: Vec<PathBuf>,
    _scheduler: Process,
}

impl Cluster {
    /// The cluster, its processes given the environment `env` besides this one's.
    fn start(dir: &Path, executors: usize, executor_timeout: u64, env: &[(&str, String)]) -> Cluster {
        std::fs::create_dir_all(dir).unwrap();
        let spawn = |args: &[&str], log: &Path| {
            let file = std::fs::File::create(log).unwrap();
            let child = Command::new(BIN)
                .args(args)
                .env("RUST_LOG", "info")
                .envs(env.iter().map(|(k, v)| (k, v)))
                .stdout(Stdio::null())
                .stderr(file)
                .spawn()
                .unwrap();
            Process(child)
        };
        let port = free_port_pair();
        let address = format!("127.0.0.1:{port}");
        let log = dir.join("scheduler.log");
        let timeout = executor_timeout.to_string();
        let scheduler = spawn(&["cluster", "scheduler", "--bind", &address, "--executor-timeout", &timeout], &log);
        assert!(wait_for_log(&log, "listening on", 1, Duration::from_secs(60)), "scheduler did not start: {log:?}");
        let mut procs = Vec::new();
        let mut logs = Vec::new();
        for k in 0..executors {
            let bind = format!("127.0.0.1:{}", free_port_pair());
            let log = dir.join(format!("executor{k}.log"));
            procs.push(spawn(
                &["cluster", "executor", "--scheduler", &address, "--bind", &bind, "--concurrency", "1"],
                &log,
            ));
            assert!(
                wait_for_log(&log, "registration succeed", 1, Duration::from_secs(60)),
                "executor {k} did not register: {}",
                std::fs::read_to_string(&log).unwrap_or_default()
            );
            logs.push(log);
        }
        Cluster { url: format!("df://{address}"), executors: procs, logs, _scheduler: scheduler }
    }
}

/// A scenario world over the three bundled tiles, and the dataset a local `gedisim run` made of it.
struct World {
    _dir: tempfile::TempDir,
    root: PathBuf,
    local: PathBuf,
}

fn world() -> &'static World {
    static WORLD: OnceLock<World> = OnceLock::new();
    WORLD.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().join("world");
        let tiles = data("als");
        let (ok, _, err) = gedisim(&[
            "scenario",
            "--effect",
            "ground_detection",
            "--als",
            tiles.to_str().unwrap(),
            "--passes",
            "8",
            "--seed",
            "5",
            "--out",
            root.to_str().unwrap(),
        ]);
        assert!(ok, "{err}");
        let local = dir.path().join("local");
        let (ok, _, err) = gedisim(&run_args(&root, &local, None).iter().map(String::as_str).collect::<Vec<_>>());
        assert!(ok, "{err}");
        World { _dir: dir, root, local }
    })
}

fn run_args(world: &Path, out: &Path, cluster: Option<&str>) -> Vec<String> {
    let gedi = world.join("gedi").display().to_string();
    let mut args: Vec<String> =
        ["run", "--als", &world.join("als").display().to_string(), "--l1b", &gedi, "--l2a", &gedi]
            .map(String::from)
            .to_vec();
    // Segments of one shot and up: the bundled tiles are 50–100 m wide, so that offsets are solved.
    args.extend(["--min-segment", "1", "--out"].map(String::from));
    args.push(out.display().to_string());
    if let Some(url) = cluster {
        args.extend(["--cluster".to_string(), url.to_string()]);
    }
    args
}

/// Every row of `batches` as text (floats in their shortest exact form, so that any bit differs), sorted.
fn rows(batches: &[RecordBatch]) -> Vec<String> {
    let mut out = Vec::new();
    for b in batches {
        for i in 0..b.num_rows() {
            let cells: Vec<String> = b.columns().iter().map(|c| array_value_to_string(c, i).unwrap()).collect();
            out.push(cells.join(" | "));
        }
    }
    out.sort();
    out
}

/// Aggregates add their rows in the order partitions arrive, and a cluster splits a table into
/// tasks differently from the local engine: floating-point addition is not associative, so a sum,
/// mean or moment may differ in its last bits. Floats are compared to within this (absolute below
/// 1, relative above: a nanometre, far below any figure the study reports); everything else, and
/// the row set, exactly.
const AGGREGATE_TOLERANCE: f64 = 1e-9;

/// `local` and `cluster` hold the same rows (in any order), floats within [`AGGREGATE_TOLERANCE`].
fn same_rows(what: &str, local: &[RecordBatch], cluster: &[RecordBatch]) {
    let (l, c) = (rows(local), rows(cluster));
    if l == c {
        return;
    }
    let floats: Vec<bool> = local[0]
        .schema()
        .fields()
        .iter()
        .map(|f| matches!(f.data_type(), DataType::Float64 | DataType::Float32))
        .collect();
    // Rows keyed by their exact cells, so that both sides sort the same way.
    let keyed = |rows: &[String]| {
        let mut v: Vec<(Vec<String>, Vec<String>)> = rows
            .iter()
            .map(|r| {
                let cells: Vec<String> = r.split(" | ").map(String::from).collect();
                let key = cells.iter().zip(&floats).filter(|(_, f)| !**f).map(|(c, _)| c.clone()).collect();
                (key, cells)
            })
            .collect();
        v.sort();
        v
    };
    let (l, c) = (keyed(&l), keyed(&c));
    assert_eq!(l.len(), c.len(), "{what}: row count");
    let mut worst = 0.0f64;
    for ((lk, lc), (ck, cc)) in l.iter().zip(&c) {
        assert_eq!(lk, ck, "{what}: a row differs in a column that is not a float");
        for ((a, b), float) in lc.iter().zip(cc).zip(&floats) {
            if *float && a != b {
                let (x, y): (f64, f64) = (a.parse().unwrap(), b.parse().unwrap());
                let diff = (x - y).abs() / x.abs().max(y.abs()).max(1.0);
                assert!(diff <= AGGREGATE_TOLERANCE, "{what}: {a} vs {b}");
                worst = worst.max(diff);
            }
        }
    }
    eprintln!("{what}: floats within {worst:.1e} of the local engine's");
}

fn query(ds: &Path, engine: &Engine, sql: &str) -> Vec<RecordBatch> {
    let session = SqlSession::open(ds, &Default::default(), engine).unwrap();
    session.collect(sql).unwrap_or_else(|e| panic!("{sql}: {e}"))
}

/// Every column of every file of `table`, with its key-value metadata, by file name.
fn table_files(ds: &Path, table: &str) -> Vec<(String, Vec<RecordBatch>, Option<String>)> {
    let mut out = Vec::new();
    for path in common::files_with_suffix(&ds.join(table), ".parquet") {
        let file = std::fs::File::open(&path).unwrap();
        let builder = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file).unwrap();
        let meta = builder.metadata().file_metadata().key_value_metadata().map(|kv| {
            let mut kv: Vec<String> = kv.iter().map(|e| format!("{}={:?}", e.key, e.value)).collect();
            kv.sort();
            kv.join("\n")
        });
        let schema = builder.schema().clone();
        let batches: Vec<RecordBatch> = builder.build().unwrap().map(|b| b.unwrap()).collect();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        out.push((name, vec![arrow::compute::concat_batches(&schema, &batches).unwrap()], meta));
    }
    out.sort_by(|a, b| a.0.cmp(&b.0));
    out
}

#[test]
fn every_query_and_gedi_simulate_give_the_local_rows() {
    let w = world();
    let tmp = tempfile::tempdir().unwrap();
    let cluster = Cluster::start(tmp.path(), 2, 20, &[]);
    let engine = Engine::Cluster(cluster.url.clone());
    let ds = Dataset::open(&w.local).unwrap();
    let rt = tokio::runtime::Runtime::new().unwrap();
    let local = rt.block_on(run_queries(&ds, &Engine::Local, &|_| {})).unwrap();
    let remote = rt.block_on(run_queries(&ds, &engine, &|_| {})).unwrap();
    assert_eq!(local.len(), remote.len());
    let mut ran = 0;
    for (l, r) in local.iter().zip(&remote) {
        match (l, r) {
            (QueryOutcome::Ran(l), QueryOutcome::Ran(r)) => {
                assert_eq!(l.query.name, r.query.name);
                assert_eq!(l.schema, r.schema, "queries/{}.sql", l.query.name);
                assert_eq!(l.rows(), r.rows(), "queries/{}.sql", l.query.name);
                if l.rows() > 0 {
                    same_rows(&format!("queries/{}.sql", l.query.name), &l.batches, &r.batches);
                    ran += 1;
                }
            }
            (QueryOutcome::Skipped { query, .. }, QueryOutcome::Skipped { .. }) => {
                eprintln!("queries/{}.sql skipped on both (its tables are not in a run's dataset)", query.name)
            }
            _ => panic!("a query ran on one engine only"),
        }
    }
    assert!(ran >= 8, "only {ran} queries gave rows");

    // The simulation itself, every column, bit for bit.
    let sql = "select * from gedi_simulate() order by footprint_id, weighting";
    let (l, r) = (query(&w.local, &Engine::Local, sql), query(&w.local, &engine, sql));
    let concat = |b: &[RecordBatch]| arrow::compute::concat_batches(&b[0].schema(), b).unwrap();
    let (l, r) = (concat(&l), concat(&r));
    assert!(l.num_rows() > 100, "{} rows", l.num_rows());
    assert_eq!(l, r);
    // Both executors took part.
    for log in &cluster.logs {
        assert!(std::fs::read_to_string(log).unwrap().contains("Execute task"), "{log:?} ran no task");
    }
}

#[test]
fn run_on_the_cluster_writes_the_local_results() {
    let w = world();
    let tmp = tempfile::tempdir().unwrap();
    let cluster = Cluster::start(&tmp.path().join("cluster"), 2, 20, &[]);
    let out = tmp.path().join("distributed");
    let args = run_args(&w.root, &out, Some(&cluster.url));
    let (ok, _, err) = gedisim(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(ok, "{err}");
    // The ingest of the tiles (an als/ file and a tiles/ row each) and of the granules (a shots file
    // and a record per granule), both read on the executors, the collocation (one offsets file, a
    // partition per granule) and the simulation (a file per granule).
    let tables = [("als", 3), ("tiles", 3), ("shots", 6), ("granules", 6), ("offsets", 1), ("sim", 6), ("results", 6)];
    for (table, files) in tables {
        let (l, r) = (table_files(&w.local, table), table_files(&out, table));
        assert!(l.len() >= files, "{table}: {} files", l.len());
        assert!(l.iter().map(|f| f.1[0].num_rows()).sum::<usize>() > 0, "{table}: no rows");
        assert_eq!(l.len(), r.len(), "{table}");
        for (l, r) in l.iter().zip(&r) {
            assert_eq!(l.0, r.0);
            assert_eq!(l.1, r.1, "{table}/{}", l.0);
            assert_eq!(l.2, r.2, "{table}/{}: metadata", l.0);
        }
    }
    // The two ingests, the collocation and the simulation ran as jobs of tasks on the executors.
    assert!(jobs_run(&cluster.logs).len() >= 4, "{:?}", jobs_run(&cluster.logs));
    nothing_staged_in(&out, &["als", "tiles", "shots"]);
}

/// Every file of these tables of `ds` is a table file: nothing staged was left behind.
fn nothing_staged_in(ds: &Path, tables: &[&str]) {
    for table in tables {
        let left: Vec<_> = std::fs::read_dir(ds.join(table)).unwrap().flatten().map(|e| e.file_name()).collect();
        assert!(left.iter().all(|n| n.to_string_lossy().ends_with(".parquet")), "{table}: {left:?}");
    }
}

/// COPC tiles read in the windows around a dataset's shots, on the executors: the local `als/` and
/// `tiles/` files, a renamed copy of a tile taken as ingested, the same printed report; a second
/// ingest of the same tiles reads nothing.
#[test]
fn copc_tiles_ingested_on_the_cluster_in_windows_give_the_local_files() {
    let w = world();
    let tmp = tempfile::tempdir().unwrap();
    let cluster = Cluster::start(&tmp.path().join("cluster"), 2, 20, &[]);
    let copc = data("als-copc");
    let mut tiles: Vec<String> = ["lidarforfuel_1_42", "lidarforfuel_2_bas_lig", "pdal-ign-plugin_mnx_input_crop_2"]
        .map(|t| copc.join(format!("{t}.copc.laz")).display().to_string())
        .to_vec();
    let copy = tmp.path().join("copy-of-1_42.copc.laz");
    std::fs::copy(&tiles[0], &copy).unwrap();
    tiles.push(copy.display().to_string());
    let mut outcomes = Vec::new();
    for (name, engine) in [("here", None), ("cluster", Some(cluster.url.as_str()))] {
        let ds = tmp.path().join(name);
        for table in ["shots", "granules"] {
            copy_tree(&w.local.join(table), &ds.join(table));
        }
        let ds = ds.to_str().unwrap().to_string();
        let mut args = vec!["ingest", "als", "--dataset", &ds, "--als"];
        args.extend(tiles.iter().map(String::as_str));
        if let Some(url) = engine {
            args.extend(["--cluster", url]);
        }
        let mut printed = Vec::new();
        for _ in 0..2 {
            let (ok, _, err) = gedisim(&args);
            assert!(ok, "{err}");
            printed.push(err.lines().map(|l| l.replace(&ds, "<dataset>")).collect::<Vec<_>>());
        }
        nothing_staged_in(Path::new(&ds), &["als", "tiles"]);
        outcomes.push((table_files(Path::new(&ds), "als"), table_files(Path::new(&ds), "tiles"), printed));
    }
    let (here, there) = (&outcomes[0], &outcomes[1]);
    assert_eq!(here.0.len(), 3, "one als/ file per content");
    assert!(here.0.iter().all(|f| f.1[0].num_rows() > 0), "a tile without points");
    // Read in windows: each tiles/ row records the cells it read.
    for (name, rows, _) in &here.1 {
        let cells = rows[0].column_by_name("read_cells").unwrap();
        assert_eq!(cells.null_count(), 0, "tiles/{name} read whole");
    }
    assert_eq!(here.0, there.0, "als/");
    assert_eq!(here.1, there.1, "tiles/");
    assert_eq!(here.2, there.2, "the printed reports");
    assert!(jobs_run(&cluster.logs).len() >= 2, "{:?}", jobs_run(&cluster.logs));
}

/// The Ballista jobs whose tasks the executors of `logs` ran (`Execute task … [TID <job>/…]`).
fn jobs_run(logs: &[PathBuf]) -> std::collections::BTreeSet<String> {
    let mut jobs = std::collections::BTreeSet::new();
    for log in logs {
        for line in std::fs::read_to_string(log).unwrap().lines().filter(|l| l.contains("Execute task")) {
            if let Some(job) = line.split("[TID ").nth(1).and_then(|t| t.split('/').next()) {
                jobs.insert(job.to_string());
            }
        }
    }
    jobs
}

/// A copy of the directory tree `from` at `to`.
fn copy_tree(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let path = entry.unwrap().path();
        let dest = to.join(path.file_name().unwrap());
        if path.is_dir() {
            copy_tree(&path, &dest);
        } else {
            std::fs::copy(&path, &dest).unwrap();
        }
    }
}

#[test]
fn collocate_on_the_cluster_writes_the_local_offsets_and_report() {
    let w = world();
    let tmp = tempfile::tempdir().unwrap();
    let cluster = Cluster::start(&tmp.path().join("cluster"), 2, 20, &[]);
    let mut outcomes = Vec::new();
    for (name, engine) in [("here", None), ("cluster", Some(cluster.url.as_str()))] {
        let ds = tmp.path().join(name);
        copy_tree(&w.local, &ds);
        let ds = ds.to_str().unwrap().to_string();
        let mut args = vec!["collocate", "--dataset", &ds, "--min-segment", "1", "--level", "granule"];
        if let Some(url) = engine {
            args.extend(["--cluster", url]);
        }
        let (ok, _, err) = gedisim(&args);
        assert!(ok, "{err}");
        // The report (short runs, shots not used, counts) as printed, without the dataset's path.
        let report: Vec<String> = err.lines().map(|l| l.replace(&ds, "<dataset>")).collect();
        outcomes.push((table_files(Path::new(&ds), "offsets"), report));
    }
    let (here, cluster_run) = (&outcomes[0], &outcomes[1]);
    assert!(here.0[0].1[0].num_rows() > 0, "no offsets");
    assert_eq!(here.0, cluster_run.0, "offsets/");
    assert_eq!(here.1, cluster_run.1, "the printed report");
    assert_eq!(jobs_run(&cluster.logs).len(), 1, "one plan");
}

#[test]
fn a_query_survives_an_executor_killed_while_it_runs() {
    let w = world();
    let tmp = tempfile::tempdir().unwrap();
    // A short timeout: the scheduler gives a silent executor's tasks to the other after 6 s.
    let mut cluster = Cluster::start(&tmp.path().join("cluster"), 2, 6, &[]);
    let out = tmp.path().join("out.parquet");
    let sql = "select * from gedi_simulate() order by footprint_id, weighting";
    let mut client = Process(
        Command::new(BIN)
            .args(["sql", "--dataset", w.local.to_str().unwrap(), "--cluster", &cluster.url, "--out"])
            .arg(&out)
            .arg(sql)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    );
    // Kill the first executor as soon as it starts a task of this query.
    assert!(wait_for_log(&cluster.logs[0], "Execute task", 1, Duration::from_secs(120)), "no task reached executor 0");
    let mut victim = cluster.executors.remove(0);
    victim.0.kill().unwrap();
    victim.0.wait().unwrap();
    let (status, stderr) = finish(&mut client, Duration::from_secs(300), "the query after an executor died");
    if status.success() {
        let file = std::fs::File::open(&out).unwrap();
        let got: Vec<RecordBatch> = parquet::arrow::arrow_reader::ParquetRecordBatchReader::try_new(file, 8192)
            .unwrap()
            .map(|b| b.unwrap())
            .collect();
        assert_eq!(rows(&got), rows(&query(&w.local, &Engine::Local, sql)), "rows after the executor died");
        eprintln!("the query completed on the other executor");
    } else {
        assert_eq!(stderr.len(), 1, "{stderr:?}");
        assert!(!out.exists(), "partial output");
    }
    let left: Vec<_> = std::fs::read_dir(tmp.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert!(left.iter().all(|n| n == "cluster" || n == "out.parquet"), "left behind: {left:?}");
}

#[test]
fn a_bad_cluster_address_is_one_line_not_a_hang() {
    let w = world();
    let tmp = tempfile::tempdir().unwrap();
    let report = tmp.path().join("report").display().to_string();
    // Nothing listens on a port just freed.
    let port = free_port_pair();
    let dead = format!("127.0.0.1:{port}");
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            ["sql", "--dataset", w.local.to_str().unwrap(), "--cluster", &format!("df://{dead}"), "select 1"]
                .map(String::from)
                .to_vec(),
            "--cluster",
        ),
        (
            ["sql", "--dataset", w.local.to_str().unwrap(), "--cluster", &dead, "select 1"].map(String::from).to_vec(),
            "df://host:port",
        ),
        (
            ["report", "--dataset", w.local.to_str().unwrap(), "--out", &report, "--cluster", &format!("df://{dead}")]
                .map(String::from)
                .to_vec(),
            "--cluster",
        ),
        (["cluster", "executor", "--scheduler", &dead].map(String::from).to_vec(), "--scheduler"),
    ];
    for (args, names) in cases {
        let mut child = Process(Command::new(BIN).args(&args).stderr(Stdio::piped()).spawn().unwrap());
        let (status, stderr) = finish(&mut child, Duration::from_secs(120), &format!("{args:?}"));
        assert!(!status.success(), "{args:?}");
        let errors: Vec<&String> = stderr.iter().filter(|l| l.starts_with("error")).collect();
        assert_eq!(errors.len(), 1, "{args:?}: {stderr:?}");
        assert!(errors[0].contains(names), "{args:?}: {stderr:?}");
    }
}

/// An S3 server on loopback (moto's, `pip install "moto[server]"`), killed when dropped.
struct S3Server {
    endpoint: String,
    _process: Process,
}

impl S3Server {
    fn start() -> S3Server {
        let port = free_port_pair();
        let child = Command::new("moto_server")
            .args(["-H", "127.0.0.1", "-p", &port.to_string()])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("moto_server (pip install \"moto[server]\") runs the S3 server of the dataset-by-URL test");
        let process = Process(child);
        let start = Instant::now();
        while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
            assert!(start.elapsed() < Duration::from_secs(60), "moto_server did not start");
            std::thread::sleep(Duration::from_millis(100));
        }
        S3Server { endpoint: format!("http://127.0.0.1:{port}"), _process: process }
    }

    /// What a client of this server needs in its environment.
    fn env(&self) -> Vec<(&'static str, String)> {
        vec![
            ("AWS_ENDPOINT", self.endpoint.clone()),
            ("AWS_ACCESS_KEY_ID", "gedisim".into()),
            ("AWS_SECRET_ACCESS_KEY", "gedisim".into()),
            ("AWS_REGION", "us-east-1".into()),
        ]
    }

    /// Every file under `dir` copied to `s3://<bucket>/<prefix>/…` (the bucket created).
    fn upload(&self, dir: &Path, bucket: &str, prefix: &str) {
        let script = "import boto3, os, sys\n\
            endpoint, root, bucket, prefix = sys.argv[1:]\n\
            s3 = boto3.client('s3', endpoint_url=endpoint, aws_access_key_id='gedisim', \
            aws_secret_access_key='gedisim', region_name='us-east-1')\n\
            s3.create_bucket(Bucket=bucket)\n\
            for d, _, files in os.walk(root):\n    \
                for f in files:\n        \
                    p = os.path.join(d, f)\n        \
                    s3.upload_file(p, bucket, prefix + '/' + os.path.relpath(p, root))\n";
        let out = Command::new("python3")
            .args(["-c", script, &self.endpoint, dir.to_str().unwrap(), bucket, prefix])
            .output()
            .unwrap();
        assert!(out.status.success(), "upload: {}", String::from_utf8_lossy(&out.stderr));
    }
}

/// The rows `gedisim sql --dataset <dataset> -f <query> [--cluster …]` writes, or its error.
fn sql_rows(
    dataset: &str,
    query: &Path,
    cluster: Option<&str>,
    env: &[(&str, String)],
    out: &Path,
) -> Result<Vec<RecordBatch>, String> {
    let mut cmd = Command::new(BIN);
    cmd.args(["sql", "--dataset", dataset, "-f", query.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    if let Some(url) = cluster {
        cmd.args(["--cluster", url]);
    }
    let result = cmd.envs(env.iter().map(|(k, v)| (k, v))).output().unwrap();
    if !result.status.success() {
        return Err(String::from_utf8_lossy(&result.stderr).into_owned());
    }
    let file = std::fs::File::open(out).unwrap();
    let reader = parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(file).unwrap().build().unwrap();
    Ok(reader.map(|b| b.unwrap()).collect())
}

#[test]
fn a_dataset_by_url_gives_the_local_rows_here_and_on_the_cluster() {
    let w = world();
    let tmp = tempfile::tempdir().unwrap();
    let s3 = S3Server::start();
    s3.upload(&w.local, "gedi", "runs/france");
    let env = s3.env();
    let cluster = Cluster::start(&tmp.path().join("cluster"), 2, 20, &env);
    let url = "s3://gedi/runs/france";
    let mut compared = 0;
    for query in common::files_with_suffix(&Path::new(env!("CARGO_MANIFEST_DIR")).join("queries"), ".sql") {
        let name = query.file_stem().unwrap().to_string_lossy().into_owned();
        let out = |k: &str| tmp.path().join(format!("{name}.{k}.parquet"));
        let local = sql_rows(w.local.to_str().unwrap(), &query, None, &[], &out("dir"));
        let by_url = sql_rows(url, &query, None, &env, &out("url"));
        let on_cluster = sql_rows(url, &query, Some(&cluster.url), &env, &out("cluster"));
        // The simulation reads ALS points from a dataset directory: by URL it says so.
        if std::fs::read_to_string(&query).unwrap().contains("gedi_simulate(") {
            for err in [by_url.unwrap_err(), on_cluster.unwrap_err()] {
                assert!(err.trim().lines().count() == 1 && err.contains("dataset directory"), "{name}: {err}");
            }
            continue;
        }
        match (local, by_url, on_cluster) {
            (Ok(l), Ok(u), Ok(c)) => {
                same_rows(&format!("queries/{name}.sql by URL"), &l, &u);
                same_rows(&format!("queries/{name}.sql by URL on the cluster"), &l, &c);
                compared += usize::from(l.iter().map(RecordBatch::num_rows).sum::<usize>() > 0);
            }
            // A query whose tables a run's dataset lacks fails the same way everywhere.
            (Err(_), Err(u), Err(c)) => assert!(u.trim().lines().count() == 1 && c.trim().lines().count() == 1),
            (l, u, c) => {
                panic!("queries/{name}.sql: local {:?}, by URL {:?}, on the cluster {:?}", l.err(), u.err(), c.err())
            }
        }
    }
    assert!(compared >= 8, "only {compared} queries gave rows");
    for log in &cluster.logs {
        assert!(std::fs::read_to_string(log).unwrap().contains("Execute task"), "{log:?} ran no task");
    }

    // No statement may write where a dataset by URL is.
    let err = Command::new(BIN)
        .args(["sql", "--dataset", url, "--allow-writes", "select 1"])
        .envs(env.iter().map(|(k, v)| (k, v)))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&err.stderr);
    assert!(
        !err.status.success() && stderr.trim().lines().count() == 1 && stderr.contains("--allow-writes"),
        "{stderr}"
    );

    // What the object store cannot give is one line.
    let q = tmp.path().join("one.sql");
    std::fs::write(&q, "select 1").unwrap();
    for (dataset, expected) in [("s3://gedi/runs/nowhere", "no table folder"), ("s3://no-bucket/x", "no-bucket")] {
        let err = sql_rows(dataset, &q, None, &env, &tmp.path().join("x.parquet")).unwrap_err();
        assert!(err.trim().lines().count() == 1 && err.contains(expected), "{err}");
    }
}
