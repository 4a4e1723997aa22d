//! Progress bars (indicatif): the command line's one implementation of the operations'
//! [`Progress`] trait; process statistics for `--stats`; and the writer lock every writing
//! command takes ([`writer`]).

use std::sync::Mutex;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressStyle};

use gedisim::ops::progress::{Progress, Step};

/// One indicatif bar per step: a bar with its total and unit, or a spinner for steps without
/// counts, whose message follows the step's notes.
pub struct Bars(Mutex<Option<(Step, ProgressBar)>>);

impl Bars {
    pub fn new() -> Self {
        Bars(Mutex::new(None))
    }
}

impl Progress for Bars {
    fn start(&self, step: Step, total: u64) {
        let bar = if step.unit().is_empty() {
            let b = ProgressBar::new_spinner();
            b.set_message(step.label());
            b.enable_steady_tick(Duration::from_millis(200));
            b
        } else {
            let b = ProgressBar::new(total);
            b.set_style(
                ProgressStyle::with_template(&format!(
                    "{{prefix:>11}} {{elapsed_precise}} [{{bar:40}}] {{human_pos}}/{{human_len}} {} ({{per_sec}}, \
                        eta {{eta}})",
                    step.unit()
                ))
                .expect("valid template")
                .progress_chars("=> "),
            );
            b.set_prefix(step.label());
            b
        };
        if let Some((_, old)) = self.0.lock().expect("progress lock").replace((step, bar)) {
            old.finish_and_clear();
        }
    }

    fn set_total(&self, total: u64) {
        if let Some((_, b)) = self.0.lock().expect("progress lock").as_ref() {
            b.set_length(total);
        }
    }

    fn advance(&self, n: u64) {
        if let Some((_, b)) = self.0.lock().expect("progress lock").as_ref() {
            b.inc(n);
        }
    }

    fn note(&self, text: &str) {
        if let Some((step, b)) = self.0.lock().expect("progress lock").as_ref() {
            b.set_message(format!("{}: {text}", step.label()));
        }
    }

    fn finish(&self) {
        if let Some((_, b)) = self.0.lock().expect("progress lock").take() {
            b.finish_and_clear();
        }
    }
}

/// User + system CPU time of this process, all threads (s); 0 where /proc is unavailable.
/// `/proc/self/stat` counts in USER_HZ, which Linux fixes at 100 for this interface.
pub fn cpu_seconds() -> f64 {
    std::fs::read_to_string("/proc/self/stat")
        .ok()
        .and_then(|s| {
            // Fields after the parenthesised command name; utime and stime are fields 14 and 15.
            let rest = s.rsplit_once(')')?.1;
            let f: Vec<&str> = rest.split_whitespace().collect();
            Some((f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?) / 100.0)
        })
        .unwrap_or(0.0)
}

/// Peak resident memory of this process (VmHWM), MB; 0 where /proc is unavailable.
pub fn peak_rss_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines().find(|l| l.starts_with("VmHWM:")).and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map(|kb| kb / 1024.0)
        .unwrap_or(0.0)
}

/// Open (or create) the dataset at `root` as its one writer (see `gedisim::dataset::lock`),
/// saying on stderr what an interrupted writer left and this one removed. Every command that
/// writes into a dataset calls it first and holds the returned dataset until it ends.
pub fn writer(root: &std::path::Path) -> gedisim::Result<gedisim::dataset::Dataset> {
    let (ds, cleanup) = gedisim::dataset::Dataset::writer(root)?;
    let (tmp, orphans) = (cleanup.temporaries.len(), cleanup.orphan_points.len());
    if tmp + orphans > 0 {
        eprintln!(
            "{}: removed what an interrupted writer left: {tmp} temporary file(s), \
             {orphans} als/ file(s) without a tiles/ row",
            root.display()
        );
    }
    Ok(ds)
}

/// What was fetched from each remote input (`https://…`, `s3://…`) that was read (stderr).
pub fn print_fetched(inputs: &[std::path::PathBuf]) {
    for (input, f) in gedisim::ops::ingest_als::remote_reads(inputs) {
        eprintln!(
            "{}: fetched {} of {} bytes ({:.1} %) in {} range requests",
            input.display(),
            f.bytes,
            f.size,
            100.0 * f.bytes as f64 / f.size.max(1) as f64,
            f.requests
        );
    }
}
