//! The `gedisim` command line: parses the arguments and dispatches to `cli/` (one file per
//! subcommand), which calls one operation of the library (`gedisim::ops`).

mod cli;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    // gedisim only reads granules (and writes new ones nobody else has open): HDF5's advisory file
    // locks add nothing, and they fail on NFS/Lustre or when another process inherited the file's
    // descriptor. Set before any thread or HDF5 call exists; the user's own setting wins.
    if std::env::var_os("HDF5_USE_FILE_LOCKING").is_none() {
        std::env::set_var("HDF5_USE_FILE_LOCKING", "FALSE");
    }
    let cli = cli::Cli::parse();
    match cli::run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", gedisim::error::one_line(&e.to_string()));
            ExitCode::FAILURE
        }
    }
}
