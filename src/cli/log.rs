//! What the command line says on stderr, through `tracing`: what each step did at `info` (shown
//! by default), warnings as `warning: …`, details at `debug` (`-v`) and `trace` (`-vv`); `-q`
//! keeps warnings and errors only, and hides the progress bars. `RUST_LOG` (an `EnvFilter`)
//! replaces the level when set. Other crates (DataFusion, Ballista through `log`) speak at
//! `warn` and above unless `RUST_LOG` says otherwise. Results go to stdout, never through here.

use std::fmt;

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

/// Install the stderr logger (once per process; later calls do nothing).
pub fn init(verbose: u8, quiet: bool) {
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new(filter(verbose, quiet)));
    let _ =
        tracing_subscriber::fmt().with_env_filter(filter).event_format(Lines).with_writer(std::io::stderr).try_init();
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
}
