//! Progress of every long operation: one trait the operations report to, implemented once by the
//! command line (indicatif bars, `src/cli/reporters.rs`) and once as a no-op ([`NoProgress`]) for
//! library and test use.

/// The long steps, for progress display.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// `gedisim demo` building its world (`scenario`).
    Scenario,
    IngestAls,
    IngestGedi,
    Strata,
    Collocate,
    Simulate,
    Results,
    /// `gedisim report`: running the study's queries, drawing figures (each named by a note).
    Report,
    /// The diagnosis simulating each shot at its sites and footprint widths.
    DiagnoseSimulate,
    /// The diagnosis fitting and scoring each effect (each named by a note).
    DiagnoseFit,
    /// `gedisim granules --download`.
    Download,
}

impl Step {
    /// What the step does, for people.
    pub fn label(self) -> &'static str {
        match self {
            Step::Scenario => "building the world (scenario)",
            Step::IngestAls => "ingest ALS",
            Step::IngestGedi => "ingest GEDI",
            Step::Strata => "strata",
            Step::Collocate => "collocate",
            Step::Simulate => "simulate",
            Step::Results => "results",
            Step::Report => "report",
            Step::DiagnoseSimulate => "diagnosis: simulating",
            Step::DiagnoseFit => "diagnosis: fitting and scoring",
            Step::Download => "download granules",
        }
    }

    /// Unit of the step's counts; empty for a step without counts (shown as a spinner).
    pub fn unit(self) -> &'static str {
        match self {
            Step::Scenario | Step::Report | Step::DiagnoseFit => "",
            Step::IngestAls => "points",
            Step::IngestGedi | Step::Results => "granules",
            Step::Download => "bytes",
            Step::Strata | Step::Collocate | Step::Simulate | Step::DiagnoseSimulate => "shots",
        }
    }
}

/// Progress of an operation: one step at a time.
pub trait Progress: Sync {
    /// `step` starts with `total` units (0: unknown).
    fn start(&self, step: Step, total: u64);
    /// The current step's total became known.
    fn set_total(&self, _total: u64) {}
    /// `n` more units of the current step are done.
    fn advance(&self, n: u64);
    /// What the current step is doing now (a query's name, the effect being fitted).
    fn note(&self, _text: &str) {}
    /// The current step ended.
    fn finish(&self);
}

/// No progress display.
pub struct NoProgress;

impl Progress for NoProgress {
    fn start(&self, _: Step, _: u64) {}
    fn advance(&self, _: u64) {}
    fn finish(&self) {}
}
