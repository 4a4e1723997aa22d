//! Progress bars (indicatif) and process statistics for `--stats`.


use indicatif::{ProgressBar, ProgressStyle};



/// Progress of `run` and `demo`: one indicatif bar per step.
pub struct Bars(std::sync::Mutex<Option<ProgressBar>>);

impl Bars {
    pub fn new() -> Self {
        Bars(std::sync::Mutex::new(None))
    }
}




impl gedisim::ops::run::Progress for Bars {
    fn start(&self, step: gedisim::ops::run::Step, total: u64) {
        let bar = if step.unit().is_empty() {
            let b = ProgressBar::new_spinner();
            b.set_message(step.label());
            b.enable_steady_tick(std::time::Duration::from_millis(200));
            b
        } else {
            let b = ProgressBar::new(total);
            b.set_style(
                ProgressStyle::with_template(&format!(
                    "{{prefix:>11}} {{elapsed_precise}} [{{bar:40}}] {{human_pos}}/{{human_len}} {} ({{per_sec}}, eta {{eta}})",
                    step.unit()
                ))
                .expect("valid template")
                .progress_chars("=> "),
            );
            b.set_prefix(step.label());
            b
        };
        if let Some(old) = self.0.lock().expect("progress lock").replace(bar) {
            old.finish_and_clear();
        }
    }

    fn set_total(&self, total: u64) {
        if let Some(b) = self.0.lock().expect("progress lock").as_ref() {
            b.set_length(total);
        }
    }

    fn advance(&self, n: u64) {
        if let Some(b) = self.0.lock().expect("progress lock").as_ref() {
            b.inc(n);
        }
    }

    fn finish(&self) {
        if let Some(b) = self.0.lock().expect("progress lock").take() {
            b.finish_and_clear();
        }
    }
}

pub fn progress(total: u64, unit: &str) -> ProgressBar {
    let bar = ProgressBar::new(total);
    bar.set_style(
        ProgressStyle::with_template(&format!("{{elapsed_precise}} [{{bar:40}}] {{human_pos}}/{{human_len}} {unit} ({{per_sec}}, eta {{eta}})"))
            .expect("valid template")
            .progress_chars("=> "),
    );
    bar
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
        .and_then(|s| s.lines().find(|l| l.starts_with("VmHWM:")).and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok()))
        .map(|kb| kb / 1024.0)
        .unwrap_or(0.0)
}
