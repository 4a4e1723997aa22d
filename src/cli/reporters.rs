//! Progress bars (indicatif): the command line's one implementation of the operations'
//! [`Progress`] trait; process statistics for `--stats`; and the writer lock every writing
//! command takes ([`writer`]).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{LazyLock, Mutex};
use std::time::Duration;
use tracing::{debug, info};

use indicatif::{HumanCount, MultiProgress, ProgressBar, ProgressDrawTarget, ProgressState, ProgressStyle};

use gedisim::ops::progress::{Progress, Step};

/// One indicatif bar per step: a bar with its total and unit, or a spinner for steps without
/// counts, whose message follows the step's notes.
pub struct Bars(Mutex<Option<(Step, ProgressBar)>>);

impl Bars {
    pub fn new() -> Self {
        Bars(Mutex::new(None))
    }
}

/// Where every bar is drawn: the log (`super::log`) writes its lines through it, above the bars.
static DRAWN: LazyLock<MultiProgress> = LazyLock::new(MultiProgress::new);

/// Run `write` with the bars hidden, then draw them again below what it wrote.
pub fn above_bars(write: impl FnOnce()) {
    DRAWN.suspend(write)
}

/// `-q`: no bars.
static QUIET: AtomicBool = AtomicBool::new(false);

pub fn set_quiet(quiet: bool) {
    QUIET.store(quiet, Ordering::Relaxed);
}

/// The bar's look: with its total and eta once the total is known, else the count alone (never
/// `127/0 shots … eta 0s`).
fn bar_style(step: Step, total: u64) -> ProgressStyle {
    ProgressStyle::with_template(&bar_template(step, total))
        .expect("valid template")
        .with_key("rate", |s: &ProgressState, w: &mut dyn std::fmt::Write| {
            let _ = write!(w, "{}/s", HumanCount(s.per_sec() as u64));
        })
        .progress_chars("=> ")
}

fn bar_template(step: Step, total: u64) -> String {
    if total > 0 {
        format!(
            "{{prefix:>11}} {{elapsed_precise}} [{{bar:40}}] {{human_pos}}/{{human_len}} {} ({{rate}}, eta {{eta}})",
            step.unit()
        )
    } else {
        format!("{{prefix:>11}} {{elapsed_precise}} {{spinner}} {{human_pos}} {} so far ({{rate}})", step.unit())
    }
}

impl Progress for Bars {
    fn start(&self, step: Step, total: u64) {
        debug!(
            "{}: started{}",
            step.label(),
            if total > 0 { format!(" ({total} {})", step.unit()) } else { "".into() }
        );
        let bar = if step.unit().is_empty() {
            let b = ProgressBar::new_spinner();
            b.set_message(step.label());
            b.enable_steady_tick(Duration::from_millis(200));
            b
        } else {
            let b = ProgressBar::new(total);
            b.set_style(bar_style(step, total));
            b.set_prefix(step.label());
            b
        };
        let bar = match QUIET.load(Ordering::Relaxed) {
            true => {
                bar.set_draw_target(ProgressDrawTarget::hidden());
                bar
            }
            false => DRAWN.add(bar),
        };
        if let Some((_, old)) = self.0.lock().expect("progress lock").replace((step, bar)) {
            old.finish_and_clear();
            DRAWN.remove(&old);
        }
    }

    fn set_total(&self, total: u64) {
        if let Some((step, b)) = self.0.lock().expect("progress lock").as_ref() {
            if !step.unit().is_empty() {
                b.set_style(bar_style(*step, total));
            }
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
            debug!("{}: {text}", step.label());
            b.set_message(format!("{}: {text}", step.label()));
        }
    }

    fn finish(&self) {
        if let Some((step, b)) = self.0.lock().expect("progress lock").take() {
            b.finish_and_clear();
            DRAWN.remove(&b);
            debug!("{}: done in {:.1} s", step.label(), b.elapsed().as_secs_f64());
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

/// What was fetched from each remote input (`https://…`, `s3://…`) that was read (stderr).
pub fn print_fetched(inputs: &[std::path::PathBuf]) {
    for (input, f) in gedisim::ops::ingest_als::remote_reads(inputs) {
        info!(
            "{}: fetched {} of {} bytes ({:.1} %) in {} range requests",
            input.display(),
            f.bytes,
            f.size,
            100.0 * f.bytes as f64 / f.size.max(1) as f64,
            f.requests
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bar_without_its_total_shows_no_total_and_no_eta() {
        let unknown = bar_template(Step::DiagnoseSimulate, 0);
        assert!(!unknown.contains("human_len") && !unknown.contains("eta"), "{unknown}");
        let known = bar_template(Step::DiagnoseSimulate, 129);
        assert!(known.contains("{human_pos}/{human_len} shots") && known.contains("eta"), "{known}");
        // Both are valid indicatif templates.
        for t in [0, 129] {
            ProgressStyle::with_template(&bar_template(Step::IngestAls, t)).unwrap();
        }
    }
}
