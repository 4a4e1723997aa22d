//! The `gedisim` command line: parses the arguments and dispatches to `cli/` (one file per
//! subcommand), which calls one operation of the library (`gedisim::ops`).

mod cli;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let cli = cli::Cli::parse();
    // A corrupt granule can crash the HDF5 C library: granules are read in child processes of this
    // binary, so that such a crash ends as one error line (gedisim::ops::ingest_gedi::child).
    if let Ok(exe) = std::env::current_exe() {
        use gedisim::ops::ingest_gedi::child;
        child::read_in_children(child::Reader { exe, stall_limit: child::STALL_LIMIT });
    }
    // Errors are one line. A panic is a bug: it too ends with one line (and exit code 101), and a
    // panic the library catches (the LAZ decoder's, see io::las) prints nothing. RUST_BACKTRACE
    // keeps Rust's own report for debugging.
    let quiet_panics = std::env::var_os("RUST_BACKTRACE").is_none();
    if quiet_panics {
        std::panic::set_hook(Box::new(|info| {
            *LAST_PANIC.lock().unwrap_or_else(|e| e.into_inner()) = Some(info.to_string());
        }));
    }
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| cli::run(cli))) {
        Ok(Ok(())) => ExitCode::SUCCESS,
        Ok(Err(e)) => {
            eprintln!("error: {}", gedisim::error::one_line(&e.to_string()));
            ExitCode::FAILURE
        }
        Err(_) => {
            let what = LAST_PANIC.lock().unwrap_or_else(|e| e.into_inner()).take().unwrap_or_default();
            if quiet_panics {
                eprintln!("error: internal error (a bug; please report it): {}", gedisim::error::one_line(&what));
            }
            ExitCode::from(101)
        }
    }
}

/// The message of the last panic, for the one-line report of an uncaught one.
static LAST_PANIC: std::sync::Mutex<Option<String>> = std::sync::Mutex::new(None);
