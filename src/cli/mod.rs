//! The `gedisim` command line: clap types and one file per subcommand, each turning arguments
//! into options for one operation (`gedisim::ops`) and printing what it did.

mod bench;
#[cfg(feature = "cluster")]
mod cluster;
mod collocate;
mod demo;
mod diagnose;
mod export;
mod granules;
mod ingest;
mod l2a;
mod log;
mod read_granule;
mod report;
mod reporters;
mod run;
mod scenario;
mod simulate;
mod sql;
mod values;

use std::path::PathBuf;

use clap::{Parser, Subcommand};

use gedisim::Result;

use collocate::CollocateArgs;
use demo::DemoArgs;
use diagnose::DiagnoseArgs;
use export::ExportGeoArgs;
use ingest::{IngestAlsArgs, IngestGediArgs, IngestStrataArgs};
use l2a::L2aArgs;
use report::ReportArgs;
use run::RunArgs;
use scenario::ScenarioArgs;
use simulate::SimulateArgs;
use sql::SqlArgs;

#[derive(Parser)]
#[command(
    name = "gedisim",
    version,
    about = "Simulate GEDI waveforms from ALS, process them like GEDI L2A, and diagnose the sim-to-real gap"
)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Say more on stderr (-v: details, -vv: every library's too). `RUST_LOG` adds to this, per target.
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    verbose: u8,
    /// Say only warnings and errors on stderr, without progress bars (results still go to stdout).
    #[arg(short, long, global = true, conflicts_with = "verbose")]
    quiet: bool,
    /// Worker threads for simulation, ingest, collocation, diagnosis and SQL (default: one per core).
    #[arg(long, global = true, value_name = "N")]
    threads: Option<std::num::NonZeroUsize>,
}

#[derive(Subcommand)]
pub enum Command {
    /// Ingest ALS tiles or GEDI granules into a dataset's Parquet tables.
    #[command(subcommand)]
    Ingest(IngestCommand),
    /// Simulate GEDI waveforms from ALS: direct mode (--als, --footprints, --out) or dataset mode (--dataset).
    Simulate(SimulateArgs),
    /// Geolocation offsets (dx, dy, dz) of the shots against the ALS → <dataset>/offsets/.
    Collocate(CollocateArgs),
    /// GEDI L2A processing (algorithms a1–a6) of the waveforms of an L1B file.
    L2a(L2aArgs),
    /// Run SQL over a dataset's tables (with gedisim's functions).
    Sql(SqlArgs),
    /// The study's tables (queries/*.sql over results/), figures and report.html → <dataset>/report/.
    Report(ReportArgs),
    /// Hand a table off in another format.
    #[command(subcommand)]
    Export(ExportCommand),
    /// The study end to end: ingest → collocate → simulate → filters → <dataset>/results/
    /// (only new granules are processed on a re-run).
    Run(RunArgs),
    /// The whole study on the bundled LiDAR HD tiles with generated GEDI granules: scenario,
    /// run, report, diagnose; prints the headline tables, the path of report.html and the
    /// diagnosis.
    Demo(DemoArgs),
    /// Build a test world: real ALS tiles + pseudo-real GEDI L1B/L2A granules with one withheld
    /// effect, and truth.json (docs/scenario.md).
    Scenario(ScenarioArgs),
    /// Where the sim-to-real gap lies, which unmodelled effect causes it and how far it shrinks
    /// once modelled (held-out tracks) → <out>/diagnosis.json, tables, figures (docs/diagnosis.md).
    Diagnose(DiagnoseArgs),
    /// The GEDI L1B and L2A V2 granules that cross a dataset's ALS tiles, found through NASA's CMR
    /// search, as CSV (docs/granules.md).
    Granules(granules::GranulesArgs),
    /// Shell completions: `gedisim completions bash > ~/.local/share/bash-completion/completions/gedisim`.
    Completions {
        /// bash, zsh, fish, elvish or powershell.
        shell: clap_complete::Shell,
    },
    /// An Apache Ballista cluster that runs gedisim's SQL (built with `--features cluster`).
    #[cfg(feature = "cluster")]
    #[command(subcommand)]
    Cluster(cluster::ClusterCommand),
    /// Measurements used by the benchmarks.
    #[command(subcommand, hide = true)]
    Bench(BenchCommand),
    /// The child process that reads one GEDI granule for the other commands (gedisim::ops::ingest_gedi::child).
    #[command(name = gedisim::ops::ingest_gedi::child::COMMAND, hide = true)]
    ReadGranule { request: String },
}

#[derive(Subcommand)]
pub enum IngestCommand {
    /// LAS/LAZ files or folders → <dataset>/als/ and <dataset>/tiles/.
    Als(IngestAlsArgs),
    /// GEDI L1B and/or L2A granules (V1 or V2) → <dataset>/shots/ and <dataset>/granules/.
    Gedi(IngestGediArgs),
    /// Forest type of every shot from a Corine Land Cover GeoTIFF (EPSG:3035) or a CSV
    /// `shot_number,forest_type` → <dataset>/strata/.
    Strata(IngestStrataArgs),
}

#[derive(Subcommand)]
pub enum ExportCommand {
    /// A table (shots or results) as GeoParquet 1.1: WKB point geometry (lon, lat; OGC:CRS84) and a bbox covering
    /// column.
    Geoparquet(ExportGeoArgs),
}

#[derive(Subcommand)]
pub enum BenchCommand {
    /// Decode a LAS/LAZ file with the las crate alone (the baseline of the ingest benchmark).
    Decode { file: PathBuf },
}

pub fn run(cli: Cli) -> Result<()> {
    log::init(cli.verbose, cli.quiet);
    reporters::set_quiet(cli.quiet);
    if let Some(n) = cli.threads {
        gedisim::ops::threads::set(n.get())?;
    }
    match cli.command {
        Command::Ingest(IngestCommand::Als(a)) => ingest::ingest_als(a),
        Command::Ingest(IngestCommand::Gedi(a)) => ingest::ingest_gedi(a),
        Command::Ingest(IngestCommand::Strata(a)) => ingest::ingest_strata(a),
        Command::Simulate(a) => simulate::simulate(a),
        Command::Collocate(a) => collocate::collocate(a),
        Command::L2a(a) => l2a::l2a(a),
        Command::Sql(a) => sql::sql(a),
        Command::Report(a) => report::report(a),
        Command::Export(ExportCommand::Geoparquet(a)) => export::export_geoparquet(a),
        Command::Run(a) => run::run_command(a),
        Command::Demo(a) => demo::demo(a),
        Command::Scenario(a) => scenario::scenario(a),
        Command::Diagnose(a) => diagnose::diagnose(a),
        Command::Granules(a) => granules::granules(a),
        #[cfg(feature = "cluster")]
        Command::Cluster(c) => cluster::cluster(c),
        Command::Completions { shell } => {
            clap_complete::generate(
                shell,
                &mut <Cli as clap::CommandFactory>::command(),
                "gedisim",
                &mut std::io::stdout(),
            );
            Ok(())
        }
        Command::Bench(BenchCommand::Decode { file }) => bench::bench_decode(file),
        Command::ReadGranule { request } => read_granule::read_granule(request),
    }
}
