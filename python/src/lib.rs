//! `gedisim._native`: the operations the command line runs (`gedisim::ops`), called from Python.
//! Each function is a thin wrapper: Python arguments → the operation's options (the command
//! line's defaults) → the operation, run without the GIL → its result as Arrow (handed to pyarrow
//! through the C data interface, not copied) or JSON text. The friendly API (`gedisim.Dataset`,
//! `gedisim.simulate`, …) is `python/gedisim/__init__.py`; docs/python.md describes both.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow::datatypes::SchemaRef;
use arrow::ffi_stream::ArrowArrayStreamReader;
use arrow::record_batch::RecordBatch;
use arrow_pyarrow::{PyArrowType, Table};
use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;

use gedisim::ops::progress::{Progress, Step};

create_exception!(_native, GedisimError, PyException, "A gedisim operation failed: the one-line message of the CLI.");

/// A gedisim error as the Python exception, with the command line's one-line message.
fn py_err(e: gedisim::Error) -> PyErr {
    GedisimError::new_err(gedisim::error::one_line(&e.to_string()))
}

fn paths(v: Vec<String>) -> Vec<PathBuf> {
    v.into_iter().map(PathBuf::from).collect()
}

/// Progress handed to a Python callable `progress(event, label, unit, n)`: event `start`
/// (n = total, 0 unknown), `total`, `advance` (n more done), `note` (label = what is done now),
/// `finish`. `gedisim._progress` turns these into tqdm bars.
struct PyProgress(Option<Py<PyAny>>);

impl PyProgress {
    fn send(&self, event: &str, label: &str, unit: &str, n: u64) {
        if let Some(f) = &self.0 {
            Python::attach(|py| {
                // A failing progress callback must not fail the operation: its error is printed, the work goes on.
                if let Err(e) = f.call1(py, (event, label, unit, n)) {
                    e.print(py);
                }
            });
        }
    }
}

impl Progress for PyProgress {
    fn start(&self, step: Step, total: u64) {
        self.send("start", step.label(), step.unit(), total);
    }
    fn set_total(&self, total: u64) {
        self.send("total", "", "", total);
    }
    fn advance(&self, n: u64) {
        self.send("advance", "", "", n);
    }
    fn note(&self, text: &str) {
        self.send("note", text, "", 0);
    }
    fn finish(&self) {
        self.send("finish", "", "", 0);
    }
}

/// The batches of the one statement of a query that has a result.
#[derive(Default)]
struct Collect {
    schema: Option<SchemaRef>,
    batches: Vec<RecordBatch>,
    results: usize,
}

impl gedisim::ops::sql::ResultSink for Collect {
    fn start(&mut self, schema: &SchemaRef) -> gedisim::Result<()> {
        self.results += 1;
        if self.results > 1 {
            return Err(gedisim::Error::Usage(
                "a second statement with a result: Dataset.sql returns one table (run the statements one by one)"
                    .into(),
            ));
        }
        self.schema = Some(schema.clone());
        Ok(())
    }
    fn batch(&mut self, batch: &RecordBatch) -> gedisim::Result<()> {
        self.batches.push(batch.clone());
        Ok(())
    }
    fn end(&mut self) -> gedisim::Result<()> {
        Ok(())
    }
}

/// sql(dataset, query) -> pyarrow.Table: the statements of `query` on `dataset` (read-only, the
/// functions of `gedisim sql`); the one with result columns is returned.
#[pyfunction]
fn sql(py: Python<'_>, dataset: String, query: String) -> PyResult<PyArrowType<Table>> {
    let collected = py.detach(|| {
        let limits = gedisim::sql::SessionLimits::default();
        let session = gedisim::ops::sql::SqlSession::open(Path::new(&dataset), &limits, &gedisim::sql::Engine::Local)?;
        let mut sink = Collect::default();
        session.run(&query, &mut sink)?;
        Ok::<_, gedisim::Error>(sink)
    });
    let sink = collected.map_err(py_err)?;
    let Some(schema) = sink.schema else {
        return Err(GedisimError::new_err(
            "SQL: no statement of the query has a result (Dataset.sql returns one table)",
        ));
    };
    Table::try_new(sink.batches, schema).map(PyArrowType).map_err(|e| GedisimError::new_err(e.to_string()))
}

/// run(dataset, als, l1b, l2a, epsg, landcover, geoid_offset, all_shots, progress) -> JSON text:
/// `gedisim run` with the command line's defaults; what `gedisim run --json` prints.
#[pyfunction]
#[pyo3(signature = (dataset, als, l1b, l2a, epsg=None, landcover=None, geoid_offset=None, all_shots=false,
                    progress=None))]
#[allow(clippy::too_many_arguments)] // one per keyword of the Python call
fn run(
    py: Python<'_>,
    dataset: String,
    als: Vec<String>,
    l1b: Vec<String>,
    l2a: Vec<String>,
    epsg: Option<u32>,
    landcover: Option<String>,
    geoid_offset: Option<f64>,
    all_shots: bool,
    progress: Option<Py<PyAny>>,
) -> PyResult<String> {
    use gedisim::ops::ingest_gedi::ShotChoice;
    let opts = gedisim::ops::run::RunOptions {
        als: paths(als),
        l1b: paths(l1b),
        l2a: paths(l2a),
        epsg,
        landcover: landcover.map(PathBuf::from),
        geoid_offset,
        shots: if all_shots { ShotChoice::All } else { ShotChoice::AlsCoverage },
        ..gedisim::ops::run::RunOptions::new(Path::new(&dataset))
    };
    let progress = PyProgress(progress);
    let report = py.detach(|| gedisim::ops::run::run_study(&opts, &progress)).map_err(py_err)?;
    Ok(report.json().to_string())
}

/// report(dataset, diagnosis, progress) -> path of report.html: `gedisim report --dataset …
/// [--diagnosis DIR]`.
#[pyfunction]
#[pyo3(signature = (dataset, diagnosis=None, progress=None))]
fn report(py: Python<'_>, dataset: String, diagnosis: Option<String>, progress: Option<Py<PyAny>>) -> PyResult<String> {
    let progress = PyProgress(progress);
    let summary = py
        .detach(|| {
            let ds = gedisim::dataset::Dataset::create(Path::new(&dataset))?;
            let opts = gedisim::ops::report::ReportOptions { out: None, diagnosis: diagnosis.map(PathBuf::from) };
            gedisim::ops::report::run_report(&ds, &opts, &gedisim::ops::report::Engine::Local, &progress)
        })
        .map_err(py_err)?;
    Ok(summary.html.to_string_lossy().into_owned())
}

/// diagnose(dataset, out, twins, effects, ranked_shots, force, progress) -> diagnosis.json's text:
/// `gedisim diagnose --dataset … --out …`.
#[pyfunction]
#[pyo3(signature = (dataset, out, twins=None, effects=None, ranked_shots=None, force=false, progress=None))]
#[allow(clippy::too_many_arguments)] // one per keyword of the Python call
fn diagnose(
    py: Python<'_>,
    dataset: String,
    out: String,
    twins: Option<usize>,
    effects: Option<Vec<String>>,
    ranked_shots: Option<usize>,
    force: bool,
    progress: Option<Py<PyAny>>,
) -> PyResult<String> {
    let defaults = gedisim::ops::diagnose::DiagnoseOptions::new();
    let opts = gedisim::ops::diagnose::DiagnoseOptions {
        effects: effects.unwrap_or_default(),
        twins: twins.unwrap_or(defaults.twins),
        ranked_shots: ranked_shots.unwrap_or(defaults.ranked_shots),
        force,
        ..defaults
    };
    let progress = PyProgress(progress);
    let input = gedisim::ops::diagnose::DiagnoseInput::Dataset(PathBuf::from(dataset));
    let report =
        py.detach(|| gedisim::ops::diagnose::diagnose(input, Path::new(&out), &opts, &progress)).map_err(py_err)?;
    serde_json::to_string(&report.output.json).map_err(|e| GedisimError::new_err(e.to_string()))
}

/// The batches of an Arrow stream (a pyarrow Table or anything with `__arrow_c_stream__`), read
/// with the GIL held (a stream made by Python code calls back into it); `what` names it in errors.
fn batches(stream: ArrowArrayStreamReader, what: &str) -> PyResult<Vec<RecordBatch>> {
    stream.collect::<Result<Vec<_>, _>>().map_err(|e| GedisimError::new_err(format!("{what}: {e}")))
}

/// simulate(als, footprints, out, points, als_crs, profile, fsigma, crs, pulse, progress) ->
/// (simulated, skipped): `gedisim simulate --als … --footprints <CSV> --out <Parquet>` (direct
/// mode), or the same on `points`, a points table (the columns of `als/`) in EPSG `als_crs`, when
/// `als` is empty. Unset options take the command line's defaults (`SimulateOptions::new`).
#[pyfunction]
#[pyo3(signature = (als, footprints, out, points=None, als_crs=None, profile="default", fsigma=None, crs=None,
                    pulse="gaussian", progress=None))]
#[allow(clippy::too_many_arguments)] // one per keyword of the Python call
fn simulate(
    py: Python<'_>,
    als: Vec<String>,
    footprints: String,
    out: String,
    points: Option<PyArrowType<ArrowArrayStreamReader>>,
    als_crs: Option<u32>,
    profile: &str,
    fsigma: Option<f32>,
    crs: Option<u32>,
    pulse: &str,
    progress: Option<Py<PyAny>>,
) -> PyResult<(usize, usize)> {
    use gedisim::kernels::sim::{Profile, PulseModel};
    use gedisim::ops::simulate::{SimulateOptions, Source};
    let (footprints, out) = (PathBuf::from(footprints), PathBuf::from(out));
    let source = match points {
        Some(stream) => {
            let batches = batches(stream.0, "als (points table)")?;
            let points = gedisim::dataset::als::points_from_batches(&batches, Path::new("als (points table)"))
                .map_err(py_err)?;
            Source::Points { points: Arc::new(points), epsg: als_crs, footprints, out, keep_all_classes: false }
        }
        None => Source::Direct { als: paths(als), footprints, out, keep_all_classes: false },
    };
    let mut opts = SimulateOptions::new(source);
    opts.profile = match profile {
        "default" => Profile::Default,
        "gedirat" => Profile::Gedirat,
        other => return Err(GedisimError::new_err(format!("profile: `{other}` is not default or gedirat"))),
    };
    opts.fsigma = fsigma.unwrap_or(opts.fsigma);
    opts.pulse = PulseModel::parse(pulse, None, Default::default());
    opts.footprints_crs = crs;
    let progress = PyProgress(progress);
    let r = py.detach(|| gedisim::ops::simulate::simulate(&opts, &progress)).map_err(py_err)?;
    Ok((r.simulated, r.skipped))
}

/// l2a(l1b, algorithms, out) -> (shots, rows, warnings): `gedisim l2a --l1b … --out <Parquet>`.
#[pyfunction]
fn l2a(py: Python<'_>, l1b: String, algorithms: Vec<u8>, out: String) -> PyResult<(usize, usize, Vec<String>)> {
    let r = py.detach(|| gedisim::ops::l2a::l2a(Path::new(&l1b), &algorithms, Path::new(&out))).map_err(py_err)?;
    Ok((r.shots, r.rows, r.warnings))
}

/// l2a_table(shots, algorithms, out) -> pyarrow.Table: the rows `gedisim l2a` writes, from a table
/// with the L1B columns of `shots/` instead of a granule; also written to `out` when given.
#[pyfunction]
#[pyo3(signature = (shots, algorithms, out=None))]
fn l2a_table(
    py: Python<'_>,
    shots: PyArrowType<ArrowArrayStreamReader>,
    algorithms: Vec<u8>,
    out: Option<String>,
) -> PyResult<PyArrowType<Table>> {
    let what = "waveforms (shots table)";
    let input = batches(shots.0, what)?;
    let out = out.map(PathBuf::from);
    let rows = py
        .detach(|| gedisim::ops::l2a::l2a_of_shots(&input, &algorithms, Path::new(what), out.as_deref()))
        .map_err(py_err)?;
    Table::try_new(rows, gedisim::dataset::l2a::l2a_schema())
        .map(PyArrowType)
        .map_err(|e| GedisimError::new_err(e.to_string()))
}

/// Read granules in child processes of the `gedisim` binary at `exe` (the one the wheel installs),
/// as the command line does: a corrupt granule that crashes the HDF5 library then ends as an
/// exception, not as the end of the Python process. The first call sets it; later ones change nothing.
#[pyfunction]
fn read_granules_with(exe: String) {
    use gedisim::ops::ingest_gedi::child;
    child::read_in_children(child::Reader { exe: PathBuf::from(exe), stall_limit: child::STALL_LIMIT });
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("GedisimError", m.py().get_type::<GedisimError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(sql, m)?)?;
    m.add_function(wrap_pyfunction!(run, m)?)?;
    m.add_function(wrap_pyfunction!(report, m)?)?;
    m.add_function(wrap_pyfunction!(diagnose, m)?)?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(l2a, m)?)?;
    m.add_function(wrap_pyfunction!(l2a_table, m)?)?;
    m.add_function(wrap_pyfunction!(read_granules_with, m)?)?;
    Ok(())
}
