//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

/// Path of a file under tests/data.
pub fn data(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data").join(rel)
}

/// The three real LiDAR HD tiles bundled in tests/data/als.
pub const TILES: [&str; 3] = ["lidarforfuel_1_42", "lidarforfuel_2_bas_lig", "pdal-ign-plugin_mnx_input_crop_2"];

/// A path as a command-line argument.
pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Run the gedisim binary; returns (success, stdout, stderr).
pub fn gedisim(args: &[&str]) -> (bool, String, String) {
    outcome(Command::new(env!("CARGO_BIN_EXE_gedisim")).args(args).output().expect("run gedisim"))
}

/// Run the gedisim binary with `input` on stdin; returns (success, stdout, stderr).
pub fn gedisim_with_stdin(args: &[&str], input: &str) -> (bool, String, String) {
    use std::io::Write;
    use std::process::Stdio;
    let mut child = Command::new(env!("CARGO_BIN_EXE_gedisim"))
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run gedisim");
    child.stdin.take().unwrap().write_all(input.as_bytes()).unwrap();
    outcome(child.wait_with_output().expect("run gedisim"))
}

/// Run the gedisim binary in the working directory `dir` with the environment `env` added.
pub fn gedisim_in(dir: &Path, env: &[(&str, &Path)], args: &[&str]) -> (bool, String, String) {
    let mut c = Command::new(env!("CARGO_BIN_EXE_gedisim"));
    c.args(args).current_dir(dir);
    for (k, v) in env {
        c.env(k, v);
    }
    outcome(c.output().expect("run gedisim"))
}

/// (success, stdout, stderr) of a finished process.
fn outcome(out: std::process::Output) -> (bool, String, String) {
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Every file (recursively) under `dir` whose name ends with `suffix`.
pub fn files_with_suffix(dir: &Path, suffix: &str) -> Vec<PathBuf> {
    let mut out = Vec::new();
    if let Ok(rd) = std::fs::read_dir(dir) {
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                out.extend(files_with_suffix(&p, suffix));
            } else if p.to_string_lossy().ends_with(suffix) {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

pub mod nasa;

pub mod planted;
pub mod scene;

/// A [`gedisim::ops::progress::Progress`] that records what it is told: the steps started with
/// their totals, the units advanced and the notes.
#[derive(Default)]
pub struct Recorder {
    pub events: std::sync::Mutex<Vec<String>>,
    pub advanced: std::sync::atomic::AtomicU64,
}

impl gedisim::ops::progress::Progress for Recorder {
    fn start(&self, step: gedisim::ops::progress::Step, total: u64) {
        self.events.lock().unwrap().push(format!("start {} {total}", step.label()));
    }
    fn set_total(&self, total: u64) {
        self.events.lock().unwrap().push(format!("total {total}"));
    }
    fn advance(&self, n: u64) {
        self.advanced.fetch_add(n, std::sync::atomic::Ordering::Relaxed);
    }
    fn note(&self, text: &str) {
        self.events.lock().unwrap().push(text.to_string());
    }
    fn finish(&self) {}
}

/// A `tiles/` file of the dataset holding only the extents `[xmin, ymin, xmax, ymax]` of tiles (what
/// the default area of `ingest gedi` reads).
pub fn write_tile_extents(ds: &gedisim::dataset::Dataset, extents: &[[f64; 4]]) {
    use arrow::array::{ArrayRef, Float64Array, RecordBatch};
    use arrow::datatypes::{DataType, Field, Schema};
    use std::sync::Arc;
    let names = ["xmin", "ymin", "xmax", "ymax"];
    let schema =
        Arc::new(Schema::new(names.iter().map(|n| Field::new(*n, DataType::Float64, false)).collect::<Vec<_>>()));
    let cols: Vec<ArrayRef> = (0..4)
        .map(|i| Arc::new(Float64Array::from(extents.iter().map(|e| e[i]).collect::<Vec<_>>())) as ArrayRef)
        .collect();
    let b = RecordBatch::try_new(schema.clone(), cols).unwrap();
    let file = ds.table_file("tiles", "extents").unwrap();
    gedisim::dataset::write_parquet(&file, schema, &[b], &Default::default()).unwrap();
}
