//! What the command line says on stderr, through `tracing`: what each step did at `info` (shown
//! by default), warnings as `warning: …`, details at `debug` (`-v`) and `trace` (`-vv`); `-q`
//! keeps warnings and errors only, and hides the progress bars. `RUST_LOG` (an `EnvFilter`'s
//! directives) adds to the flags' levels, overriding them for the targets it names. Other crates
//! (DataFusion, Ballista through `log`) speak at `warn` and above unless `RUST_LOG` says
//! otherwise. Lines are written above the progress bars, never into them. Results go to stdout,
//! never through here.

use std::fmt;
use std::io::Write;

use tracing::{Event, Level, Subscriber};
use tracing_subscriber::fmt::format::{FormatEvent, FormatFields, Writer};
use tracing_subscriber::fmt::FmtContext;
use tracing_subscriber::registry::LookupSpan;
use tracing_subscriber::EnvFilter;

/// The filter of `-v` counts and `-q`.
pub fn filter(verbose: u8, quiet: bool) -> String {
    let ours = match (quiet, verbose) {
        (true, _) => "warn",
        (false, 0) => "info",
        (false, 1) => "debug",
        (false, _) => "trace",
    };
    let others = if verbose >= 2 { "info" } else { "warn" };
    format!("{others},gedisim={ours}")
}

/// Plain lines: the message alone for `info`, with `warning: ` / `error: ` / `debug: ` /
/// `trace: ` before the others.
struct Lines;

impl<S, N> FormatEvent<S, N> for Lines
where
    S: Subscriber + for<'a> LookupSpan<'a>,
    N: for<'a> FormatFields<'a> + 'static,
{
    fn format_event(&self, ctx: &FmtContext<'_, S, N>, mut w: Writer<'_>, event: &Event<'_>) -> fmt::Result {
        match *event.metadata().level() {
            Level::INFO => {}
            Level::WARN => write!(w, "warning: ")?,
            Level::ERROR => write!(w, "error: ")?,
            Level::DEBUG => write!(w, "debug: ")?,
            Level::TRACE => write!(w, "trace: ")?,
        }
        ctx.field_format().format_fields(w.by_ref(), event)?;
        writeln!(w)
    }
}

/// The flags' filter with `RUST_LOG`'s directives after it (a later directive for the same target wins).
fn directives(verbose: u8, quiet: bool, rust_log: Option<&str>) -> String {
    match rust_log.map(str::trim).filter(|d| !d.is_empty()) {
        Some(d) => format!("{},{d}", filter(verbose, quiet)),
        None => filter(verbose, quiet),
    }
}

/// One log line, gathered then written to stderr at once with the progress bars hidden.
struct AboveBars(Vec<u8>);

impl Write for AboveBars {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.extend_from_slice(buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Drop for AboveBars {
    fn drop(&mut self) {
        if !self.0.is_empty() {
            super::reporters::above_bars(|| {
                let _ = std::io::stderr().write_all(&self.0);
            });
        }
    }
}

/// Install the stderr logger (once per process; later calls do nothing).
pub fn init(verbose: u8, quiet: bool) {
    let rust_log = std::env::var("RUST_LOG").ok();
    let wanted = directives(verbose, quiet, rust_log.as_deref());
    let filter = EnvFilter::try_new(&wanted).unwrap_or_else(|e| {
        eprintln!("warning: RUST_LOG={}: {e}; ignored", rust_log.unwrap_or_default());
        EnvFilter::new(filter(verbose, quiet))
    });
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .event_format(Lines)
        .with_writer(|| AboveBars(Vec::new()))
        .try_init();
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_of_the_flags() {
        assert_eq!(filter(0, false), "warn,gedisim=info");
        assert_eq!(filter(1, false), "warn,gedisim=debug");
        assert_eq!(filter(2, false), "info,gedisim=trace");
        assert_eq!(filter(0, true), "warn,gedisim=warn");
    }

    #[test]
    fn rust_log_adds_to_the_flags() {
        assert_eq!(directives(0, true, None), "warn,gedisim=warn");
        assert_eq!(directives(0, true, Some(" ")), "warn,gedisim=warn");
        assert_eq!(directives(0, true, Some("datafusion=debug")), "warn,gedisim=warn,datafusion=debug");
        // Valid as one filter (EnvFilter keeps the later of two directives for one target).
        EnvFilter::try_new(directives(1, false, Some("gedisim=trace"))).unwrap();
    }
}
