//! `gedisim cluster scheduler|executor` (feature `cluster`).

use std::net::SocketAddr;
use tracing::info;

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
    // Ballista's own messages come through the command line's logger (cli/log.rs): warnings and
    // up unless `-vv` or `RUST_LOG` says otherwise.
    match c {
        ClusterCommand::Scheduler { bind, executor_timeout } => {
            info!("gedisim cluster scheduler on {bind}");
            gedisim::ops::cluster::run_scheduler(bind, executor_timeout)
        }
        ClusterCommand::Executor { scheduler, bind, concurrency } => {
            let n = concurrency.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
            info!("gedisim cluster executor on {bind}, scheduler {scheduler}, {n} tasks at once");
            gedisim::ops::cluster::run_executor(&scheduler, bind, n)
        }
    }
}
