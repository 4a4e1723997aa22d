//! `gedisim cluster scheduler|executor` (feature `cluster`).

use std::net::SocketAddr;

use clap::Subcommand;

use gedisim::Result;

#[derive(Subcommand)]
pub enum ClusterCommand {
    /// Start a Ballista scheduler; runs until stopped.
    Scheduler {
        /// Address to listen on.
        #[arg(long, default_value = "127.0.0.1:50050")]
        bind: SocketAddr,
        /// Seconds without a heartbeat after which an executor is lost and its tasks run on the
        /// others (executors beat every 2 s).
        #[arg(long, default_value_t = 20)]
        executor_timeout: u64,
    },
    /// Start a Ballista executor that knows gedisim's functions; runs until stopped.
    Executor {
        /// The scheduler's address, host:port.
        #[arg(long)]
        scheduler: String,
        /// Address of the executor's Flight service (its gRPC service takes the next port).
        #[arg(long, default_value = "127.0.0.1:50051")]
        bind: SocketAddr,
        /// Tasks run at once (default: the machine's cores).
        #[arg(long)]
        concurrency: Option<usize>,
    },
}

pub fn cluster(c: ClusterCommand) -> Result<()> {
    // Ballista's own messages (warnings and up unless RUST_LOG says otherwise), on stderr.
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn"));
    let _ = tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).try_init();
    match c {
        ClusterCommand::Scheduler { bind, executor_timeout } => {
            eprintln!("gedisim cluster scheduler on {bind}");
            gedisim::ops::cluster::run_scheduler(bind, executor_timeout)
        }
        ClusterCommand::Executor { scheduler, bind, concurrency } => {
            let n = concurrency.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
            eprintln!("gedisim cluster executor on {bind}, scheduler {scheduler}, {n} tasks at once");
            gedisim::ops::cluster::run_executor(&scheduler, bind, n)
        }
    }
}
