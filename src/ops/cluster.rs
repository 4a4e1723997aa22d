//! `gedisim cluster`: an Apache DataFusion Ballista scheduler and executors, embedded, that know
//! gedisim's SQL functions and ship `gedi_simulate`'s plans ([`crate::sql::codec`]) (feature
//! `cluster`; docs/scale.md).

use std::net::SocketAddr;
use std::sync::Arc;

use ballista_core::registry::BallistaFunctionRegistry;
use ballista_executor::executor_process::{start_executor_process, ExecutorProcessConfig};
use ballista_scheduler::cluster::BallistaCluster;
use ballista_scheduler::config::SchedulerConfig;
use ballista_scheduler::scheduler_process::start_server;
use datafusion::execution::runtime_env::{RuntimeEnv, RuntimeEnvBuilder};
use datafusion::execution::{FunctionRegistry, SessionState, SessionStateBuilder};
use datafusion::prelude::SessionConfig;

use crate::error::{Error, Result};
use crate::io::store::Stores;
use crate::sql::codec::{LogicalCodec, PhysicalCodec};

/// Every function a local session knows (DataFusion's defaults, including the nested-type functions
/// Ballista's default registry lacks, and gedisim's scalar functions, [`crate::sql::scalar_functions`]),
/// as an executor's registry.
pub fn function_registry() -> BallistaFunctionRegistry {
    let mut state = SessionStateBuilder::new().with_default_features().build();
    for f in crate::sql::scalar_functions() {
        // Registering a new name replaces nothing.
        let _ = state.register_udf(Arc::new(f));
    }
    BallistaFunctionRegistry {
        scalar_functions: state.scalar_functions().clone(),
        aggregate_functions: state.aggregate_functions().clone(),
        window_functions: state.window_functions().clone(),
        ..BallistaFunctionRegistry::default()
    }
}

/// The scheduler's sessions: Ballista's defaults with gedisim's scalar functions registered, so
/// that plans using them can be decoded and planned.
fn session_state(config: SessionConfig) -> datafusion::common::Result<SessionState> {
    let state = ballista_core::utils::default_session_builder(config)?;
    let mut state = SessionStateBuilder::new_from_existing(state).with_runtime_env(node_runtime(None)?).build();
    for f in crate::sql::scalar_functions() {
        state.register_udf(Arc::new(f))?;
    }
    Ok(state)
}

/// A node's runtime: object stores opened as URLs name them ([`Stores`]: datasets by URL), spill files
/// in `work_dir`.
fn node_runtime(work_dir: Option<&str>) -> datafusion::common::Result<Arc<RuntimeEnv>> {
    let mut builder = RuntimeEnvBuilder::new().with_object_store_registry(Arc::new(Stores::default()));
    if let Some(dir) = work_dir {
        builder = builder.with_temp_file_path(dir);
    }
    builder.build_arc()
}

fn runtime() -> Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| Error::Usage(format!("cannot start the async runtime: {e}")))
}

/// Seconds between an executor's heartbeats to the scheduler (Ballista's default is 60).
pub const HEARTBEAT_SECONDS: u64 = 2;

/// Run a scheduler listening on `bind` until the process is stopped. An executor silent for
/// `executor_timeout` seconds is taken as lost: its tasks run again on the others.
pub fn run_scheduler(bind: SocketAddr, executor_timeout: u64) -> Result<()> {
    if executor_timeout < 2 * HEARTBEAT_SECONDS {
        return Err(Error::Usage(format!(
            "--executor-timeout {executor_timeout}: at least {} s (two heartbeats)",
            2 * HEARTBEAT_SECONDS
        )));
    }
    let config = SchedulerConfig {
        bind_host: bind.ip().to_string(),
        bind_port: bind.port(),
        executor_timeout_seconds: executor_timeout,
        expire_dead_executor_interval_seconds: HEARTBEAT_SECONDS,
        override_session_builder: Some(Arc::new(session_state)),
        override_logical_codec: Some(Arc::new(LogicalCodec::default())),
        override_physical_codec: Some(Arc::new(PhysicalCodec::default())),
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
    // Ballista's executor waits for ever on a scheduler that does not answer.
    crate::sql::reachable(scheduler).map_err(|e| Error::Usage(format!("--scheduler {scheduler}: {e}")))?;
    // The partitions of an ingest read granules and tiles here.
    use crate::sql::ingest::{install_stager, IngestKind};
    install_stager(IngestKind::Granules, crate::ops::ingest_gedi::write_from_json);
    install_stager(IngestKind::Tiles, crate::ops::ingest_als::stage_from_json);
    // Shuffle and spill files: one folder per executor of this machine.
    let work_dir = std::env::temp_dir().join(format!("gedisim-executor-{}", bind.port()));
    std::fs::create_dir_all(&work_dir).map_err(|e| Error::file(&work_dir, format!("cannot create: {e}")))?;
    let work_dir = work_dir.to_string_lossy().into_owned();
    let spill_dir = work_dir.clone();
    let config = ExecutorProcessConfig {
        work_dir: Some(work_dir),
        override_runtime_producer: Some(Arc::new(move |_| node_runtime(Some(&spill_dir)))),
        bind_host: bind.ip().to_string(),
        port: bind.port(),
        grpc_port: bind.port().checked_add(1).ok_or_else(|| Error::Usage(format!("--bind {bind}: no port above")))?,
        scheduler_host: host,
        scheduler_port: port,
        scheduler_connect_timeout_seconds: 10,
        vcores: concurrency.max(1),
        executor_heartbeat_interval_seconds: HEARTBEAT_SECONDS,
        override_function_registry: Some(Arc::new(function_registry())),
        override_logical_codec: Some(Arc::new(LogicalCodec::default())),
        override_physical_codec: Some(Arc::new(PhysicalCodec::default())),
        ..ExecutorProcessConfig::default()
    };
    runtime()?.block_on(async {
        start_executor_process(Arc::new(config))
            .await
            .map_err(|e| Error::Usage(format!("executor: {}", crate::error::one_line(&e.to_string()))))
    })
}
