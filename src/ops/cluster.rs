//! `gedisim cluster`: an Apache DataFusion Ballista scheduler and executors, embedded, that know
//! gedisim's SQL functions (feature `cluster`; issue 19). Work in progress: the table function
//! `gedi_simulate` needs a physical extension codec before executors can run it.

use std::net::SocketAddr;
use std::sync::Arc;

use ballista_core::registry::BallistaFunctionRegistry;
use ballista_executor::executor_process::{start_executor_process, ExecutorProcessConfig};
use ballista_scheduler::cluster::BallistaCluster;
use ballista_scheduler::config::SchedulerConfig;
use ballista_scheduler::scheduler_process::start_server;
use datafusion::execution::{FunctionRegistry, SessionState};
use datafusion::prelude::SessionConfig;

use crate::error::{Error, Result};

/// Ballista's function registry with gedisim's scalar functions added ([`crate::sql::scalar_functions`]).
pub fn function_registry() -> BallistaFunctionRegistry {
    let mut registry = BallistaFunctionRegistry::default();
    for f in crate::sql::scalar_functions() {
        registry.scalar_functions.insert(f.name().to_string(), Arc::new(f));
    }
    registry
}

/// The scheduler's sessions: Ballista's defaults with gedisim's scalar functions registered, so
/// that plans using them can be decoded and planned.
fn session_state(config: SessionConfig) -> datafusion::common::Result<SessionState> {
    let mut state = ballista_core::utils::default_session_builder(config)?;
    for f in crate::sql::scalar_functions() {
        state.register_udf(Arc::new(f))?;
    }
    Ok(state)
}

fn runtime() -> Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| Error::Usage(format!("cannot start the async runtime: {e}")))
}

/// Run a scheduler listening on `bind` until the process is stopped.
pub fn run_scheduler(bind: SocketAddr) -> Result<()> {
    let config = SchedulerConfig {
        bind_host: bind.ip().to_string(),
        bind_port: bind.port(),
        override_session_builder: Some(Arc::new(session_state)),
        ..SchedulerConfig::default()
    };
    runtime()?.block_on(async {
        let cluster = BallistaCluster::new_from_config(&config)
            .await
            .map_err(|e| Error::Usage(format!("scheduler: {}", crate::error::one_line(&e.to_string()))))?;
        start_server(cluster, bind, Arc::new(config))
            .await
            .map_err(|e| Error::Usage(format!("scheduler on {bind}: {}", crate::error::one_line(&e.to_string()))))
    })
}

/// Run an executor listening on `bind` (its Flight port; gRPC on the next one) that registers
/// with the scheduler at `scheduler` (`host:port`) and runs `concurrency` tasks at once.
pub fn run_executor(scheduler: &str, bind: SocketAddr, concurrency: usize) -> Result<()> {
    let (host, port) = scheduler
        .rsplit_once(':')
        .and_then(|(h, p)| Some((h.to_string(), p.parse::<u16>().ok()?)))
        .ok_or_else(|| Error::Usage(format!("--scheduler {scheduler}: expected host:port")))?;
    let config = ExecutorProcessConfig {
        bind_host: bind.ip().to_string(),
        port: bind.port(),
        grpc_port: bind.port().checked_add(1).ok_or_else(|| Error::Usage(format!("--bind {bind}: no port above")))?,
        scheduler_host: host,
        scheduler_port: port,
        scheduler_connect_timeout_seconds: 10,
        vcores: concurrency.max(1),
        override_function_registry: Some(Arc::new(function_registry())),
        ..ExecutorProcessConfig::default()
    };
    runtime()?.block_on(async {
        start_executor_process(Arc::new(config))
            .await
            .map_err(|e| Error::Usage(format!("executor: {}", crate::error::one_line(&e.to_string()))))
    })
}
