//! The DataFusion session: the dataset's tables registered by name, and gedisim's SQL functions
//! (thin wrappers over the kernels).

pub mod args;
pub mod blocks;
#[cfg(feature = "cluster")]
pub mod codec;
pub mod collocate;
pub mod collocation;
pub mod ingest;
pub mod l2a;
pub mod link_margin_twin;
pub mod noise_twin;
pub mod partitions;
pub mod pulses;
pub mod rh;
pub mod rh_at;
pub mod simulate;
pub mod twin;

use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow::datatypes::SchemaRef;
use datafusion::catalog::{Session, TableProvider};
use datafusion::common::Statistics;
use datafusion::datasource::file_format::parquet::ParquetFormat;
use datafusion::datasource::listing::{ListingOptions, ListingTable, ListingTableConfig, ListingTableUrl};
use datafusion::datasource::TableType;
use datafusion::execution::runtime_env::RuntimeEnvBuilder;
use datafusion::execution::{SessionState, SessionStateBuilder};
use datafusion::logical_expr::dml::InsertOp;
use datafusion::logical_expr::{DocSection, Expr, ScalarUDF, TableProviderFilterPushDown};
use datafusion::physical_plan::ExecutionPlan;
use datafusion::prelude::{SQLOptions, SessionConfig, SessionContext};

use url::Url;

use crate::dataset::{self, Dataset};
use crate::error::{Error, Result};

/// How a session may use the machine and the file system.
#[derive(Debug, Clone, Copy)]
pub struct SessionLimits {
    /// Bytes that sorts, joins and aggregations may hold before they spill to disk or fail.
    pub memory_limit: usize,
    /// Allow DDL (`CREATE …`), DML (`INSERT …`) and `COPY … TO`. Dataset tables stay read-only.
    pub allow_writes: bool,
}

impl Default for SessionLimits {
    fn default() -> Self {
        SessionLimits { memory_limit: default_memory_limit(), allow_writes: false }
    }
}

/// Half of the machine's physical memory (4 GiB when it cannot be read).
pub fn default_memory_limit() -> usize {
    let mut sys = sysinfo::System::new();
    sys.refresh_memory();
    match sys.total_memory() {
        0 => 4 << 30,
        total => usize::try_from(total / 2).unwrap_or(usize::MAX),
    }
}

/// Where a session's plans run.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub enum Engine {
    /// In this process.
    #[default]
    Local,
    /// On the Ballista cluster whose scheduler is at this `df://host:port` address (feature `cluster`).
    Cluster(String),
}

/// Worker threads of the SQL engine (`--threads`); unset: one per core.
static THREADS: std::sync::OnceLock<usize> = std::sync::OnceLock::new();

/// Cap the query runtime's worker threads and each session's partitions at `n` (once per process,
/// before the first query; `crate::ops::threads::set`).
pub fn set_threads(n: usize) {
    let _ = THREADS.set(n.max(1));
}

/// The runtime a command's queries run on.
pub fn runtime() -> Result<tokio::runtime::Runtime> {
    let mut b = tokio::runtime::Builder::new_multi_thread();
    if let Some(&n) = THREADS.get() {
        b.worker_threads(n);
    }
    b.enable_all().build().map_err(|e| Error::Usage(format!("cannot start the query runtime: {e}")))
}

/// A session with every table folder of `dataset` registered under its folder name (read-only)
/// and gedisim's functions, under the default [`SessionLimits`].
pub async fn session(ds: &Dataset) -> Result<SessionContext> {
    session_with(ds, &SessionLimits::default()).await
}

/// [`session`] with `limits`' memory pool.
pub async fn session_with(ds: &Dataset, limits: &SessionLimits) -> Result<SessionContext> {
    session_on(ds, limits, &Engine::Local).await
}

/// [`session_with`] whose plans run on `engine`. On a cluster the dataset's tables are plain
/// Parquet listings (what Ballista ships) and no statement may write.
pub async fn session_on(ds: &Dataset, limits: &SessionLimits, engine: &Engine) -> Result<SessionContext> {
    let ctx = new_session(limits, engine)?;
    register_functions(&ctx, simulate::GediSimulate::new(ds.clone()));
    let read_only = *engine == Engine::Local;
    for entry in std::fs::read_dir(ds.root()).map_err(|e| Error::file(ds.root(), e))? {
        let dir = entry.map_err(|e| Error::file(ds.root(), e))?.path();
        let Some(name) = dir.file_name().and_then(|n| n.to_str()).map(str::to_string) else { continue };
        // `report/` holds the report's outputs (many schemas), not a table.
        if name == dataset::tables::REPORT || !dir.is_dir() {
            continue;
        }
        let files = ds.visible_files(&name).map_err(|e| Error::file(&dir, e))?;
        if !files.is_empty() {
            dataset::foreign_file(&name, &files)?;
            register_table(&ctx, &name, &files, read_only).await?;
        }
    }
    Ok(ctx)
}

/// A session over the dataset at `url` (`s3://bucket/prefix`, `https://host/path`), read through an
/// object store ([`crate::io::store`]): every table folder under it registered by name, as its
/// Parquet files are listed now (a dataset copied to the store is read as it is), and gedisim's
/// scalar functions. `gedi_simulate` says it is not available: the simulation reads ALS from a filesystem.
pub async fn session_at_url(url: &Url, limits: &SessionLimits, engine: &Engine) -> Result<SessionContext> {
    let ctx = new_session(limits, engine)?;
    let why = format!("not on a dataset by URL ({url}): the simulation reads ALS points from a dataset directory");
    register_functions(&ctx, simulate::GediSimulate::unavailable(why));
    let fail = |e: &dyn std::fmt::Display| Error::file(Path::new(url.as_str()), crate::error::one_line(&e.to_string()));
    let store = ctx.runtime_env().object_store_registry.get_store(url).map_err(|e| fail(&e))?;
    let prefix = object_store::path::Path::from_url_path(url.path()).map_err(|e| fail(&e))?;
    // Every table folder's Parquet files (names sorted), then those readers may see.
    let mut tables: Vec<(String, Vec<object_store::path::Path>)> = Vec::new();
    for folder in store.list_with_delimiter(Some(&prefix)).await.map_err(|e| fail(&e))?.common_prefixes {
        let Some(name) = folder.filename().map(str::to_string) else { continue };
        if name == dataset::tables::REPORT {
            continue;
        }
        let listed = store.list_with_delimiter(Some(&folder)).await.map_err(|e| fail(&e))?.objects;
        let mut files: Vec<_> =
            listed.into_iter().map(|o| o.location).filter(|l| l.extension() == Some("parquet")).collect();
        files.sort();
        tables.push((name, files));
    }
    let tiles: std::collections::HashSet<String> = tables
        .iter()
        .filter(|(name, _)| name == dataset::tables::TILES)
        .flat_map(|(_, files)| files.iter().filter_map(|f| f.filename().map(str::to_string)))
        .collect();
    let mut registered = 0;
    for (name, files) in tables {
        let urls: Vec<ListingTableUrl> = files
            .iter()
            .filter(|f| f.filename().is_some_and(|file| dataset::is_visible(&name, file, |t| tiles.contains(t))))
            .map(|f| {
                // The key's parts as path segments, so that any character of a key stays in the path.
                let mut file_url = url.clone();
                file_url.set_query(None);
                file_url.set_fragment(None);
                file_url.path_segments_mut().map_err(|_| fail(&"cannot hold a path"))?.clear().extend(f.parts());
                ListingTableUrl::try_new(file_url, None).map_err(|e| fail(&e))
            })
            .collect::<Result<_>>()?;
        if urls.is_empty() {
            continue;
        }
        let read_only = *engine == Engine::Local;
        register_listing(
            &ctx,
            &name,
            Path::new(&format!("{}/{name}", url.as_str().trim_end_matches('/'))),
            urls,
            read_only,
        )
        .await?;
        registered += 1;
    }
    if registered == 0 {
        return Err(fail(&"no table folder with Parquet files there (the dataset's root, holding shots/, results/ …)"));
    }
    Ok(ctx)
}

/// A session under `limits` whose plans run on `engine`, reading object stores through
/// [`crate::io::store::Stores`]; no table or function registered.
fn new_session(limits: &SessionLimits, engine: &Engine) -> Result<SessionContext> {
    let mut config = SessionConfig::new().with_information_schema(true);
    if let Some(&n) = THREADS.get() {
        config = config.with_target_partitions(n);
    }
    let runtime = RuntimeEnvBuilder::new()
        .with_memory_limit(limits.memory_limit, 1.0)
        .with_object_store_registry(Arc::new(crate::io::store::Stores::default()))
        .build_arc()
        .map_err(|e| Error::Usage(format!("SQL: {e}")))?;
    let state =
        SessionStateBuilder::new().with_config(config).with_runtime_env(runtime).with_default_features().build();
    match engine {
        Engine::Local => Ok(SessionContext::new_with_state(state)),
        Engine::Cluster(url) => {
            if limits.allow_writes {
                return Err(Error::Usage("--allow-writes: not with --cluster (a cluster only reads)".into()));
            }
            Ok(SessionContext::new_with_state(cluster_state(state, url)?))
        }
    }
}

/// `state` made a client of the Ballista scheduler at `url` (`df://host:port`), with gedisim's
/// codecs ([`codec`]). The scheduler must answer within a few seconds: one line if it does not.
#[cfg(feature = "cluster")]
fn cluster_state(state: SessionState, url: &str) -> Result<SessionState> {
    use ballista_core::extension::{SessionConfigExt, SessionStateExt};
    let address = scheduler_address(url)?;
    let config = state
        .config()
        .clone()
        .with_ballista_logical_extension_codec(Arc::new(codec::LogicalCodec::default()))
        .with_ballista_physical_extension_codec(Arc::new(codec::PhysicalCodec::default()));
    SessionStateBuilder::new_from_existing(state)
        .with_config(config)
        .build()
        .upgrade_for_ballista(format!("http://{address}"))
        .map_err(|e| Error::Usage(format!("--cluster {url}: {}", crate::error::one_line(&e.to_string()))))
}

#[cfg(not(feature = "cluster"))]
fn cluster_state(_state: SessionState, url: &str) -> Result<SessionState> {
    Err(Error::Usage(format!(
        "--cluster {url}: this gedisim was built without the `cluster` feature (on by default; build without \
         --no-default-features)"
    )))
}

/// The `host:port` of a `df://host:port` scheduler address, checked to accept a connection.
pub fn scheduler_address(url: &str) -> Result<String> {
    let bad = |why: &str| Error::Usage(format!("--cluster {url}: {why}"));
    let rest = url.strip_prefix("df://").ok_or_else(|| bad("expected df://host:port"))?;
    let address = rest.trim_end_matches('/');
    reachable(address).map_err(|e| bad(&e))?;
    Ok(address.to_string())
}

/// Whether something accepts TCP connections at `address` (`host:port`) within 5 s, as one line.
pub fn reachable(address: &str) -> std::result::Result<(), String> {
    use std::net::ToSocketAddrs;
    let addrs: Vec<_> = address.to_socket_addrs().map_err(|e| format!("{address}: {e}"))?.collect();
    let mut last = format!("{address}: no address");
    for a in addrs {
        match std::net::TcpStream::connect_timeout(&a, std::time::Duration::from_secs(5)) {
            Ok(_) => return Ok(()),
            Err(e) => last = format!("nothing answers at {a} ({e})"),
        }
    }
    Err(last)
}

/// What `limits` lets a statement do: reads always; DDL, DML and `COPY` only with `allow_writes`.
pub fn statement_options(limits: &SessionLimits) -> SQLOptions {
    SQLOptions::new().with_allow_ddl(limits.allow_writes).with_allow_dml(limits.allow_writes)
}

/// The section gedisim's functions are documented under (`documentation()`, `information_schema`).
pub const DOC_SECTION: DocSection =
    DocSection { include: true, label: "gedisim", description: Some("GEDI waveform functions") };

/// gedisim's scalar functions, one file each: `gedi_rh` ([`rh`]), `rh` ([`rh_at`]), `gedi_l2a`
/// ([`l2a`]), `gedi_noise_twin` ([`noise_twin`]), `gedi_link_margin_twin` ([`link_margin_twin`]).
pub fn scalar_functions() -> Vec<ScalarUDF> {
    vec![
        ScalarUDF::new_from_impl(rh::GediRh::new()),
        ScalarUDF::new_from_impl(rh_at::RhAt::new()),
        ScalarUDF::new_from_impl(l2a::GediL2a::new()),
        ScalarUDF::new_from_impl(twin::GediTwin::new(&noise_twin::NOISE_TWIN)),
        ScalarUDF::new_from_impl(twin::GediTwin::new(&link_margin_twin::LINK_MARGIN_TWIN)),
    ]
}

/// Register gedisim's SQL functions: [`scalar_functions`] and the table function
/// `gedi_simulate([profile])` ([`simulate`]) over a dataset (or saying why there is none).
pub fn register_functions(ctx: &SessionContext, gedi_simulate: simulate::GediSimulate) {
    for f in scalar_functions() {
        ctx.register_udf(f);
    }
    ctx.register_udtf("gedi_simulate", Arc::new(gedi_simulate));
}

/// Register the Parquet `files` (of one table folder) as the table `name`, refusing `INSERT` when
/// `read_only`.
pub async fn register_table(ctx: &SessionContext, name: &str, files: &[PathBuf], read_only: bool) -> Result<()> {
    let dir = files.first().and_then(|f| f.parent()).unwrap_or(Path::new("."));
    let urls = files
        .iter()
        .map(|f| {
            let path = f.canonicalize().map_err(|e| Error::file(f, e))?;
            // As a file URL, percent-encoded: a bare path would read `?`, `*` and `[` as glob
            // characters, and a dataset folder may hold them.
            let url = url::Url::from_file_path(&path).map_err(|_| Error::file(f, "not an absolute path"))?;
            ListingTableUrl::parse(url.as_str()).map_err(|e| Error::table(dir, e))
        })
        .collect::<Result<Vec<_>>>()?;
    register_listing(ctx, name, dir, urls, read_only).await.map_err(|e| unreadable_file(files).unwrap_or(e))
}

/// The table file of `ds` that a query failing with `e` could not read, as its error, when `e` is a
/// Parquet error (a stray file in a table folder); `None` otherwise, and the caller says `e`.
pub fn unreadable_cause(ds: &Dataset, e: &datafusion::error::DataFusionError) -> Option<Error> {
    let parquet = matches!(e.find_root(), datafusion::error::DataFusionError::ParquetError(_))
        || e.to_string().contains("Parquet error");
    parquet.then(|| unreadable_table_file(ds)).flatten()
}

/// The first file of a table of `ds` that is not a readable Parquet file, as its error (see
/// [`unreadable_file`]): what a query's Parquet error is about. Reads every table file's footer, so
/// it is called only once a statement has failed.
fn unreadable_table_file(ds: &Dataset) -> Option<Error> {
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(ds.root()).ok()?.flatten().map(|e| e.path()).collect();
    dirs.sort();
    dirs.iter()
        .filter(|d| d.is_dir())
        .filter_map(|d| d.file_name().and_then(|n| n.to_str()))
        .filter(|name| *name != dataset::tables::REPORT)
        .find_map(|name| unreadable_file(&ds.visible_files(name).ok()?))
}

/// The first of `files` that is not a readable Parquet file, as its error: a table that cannot be
/// registered is named by its folder, and the user needs the file (a 5-byte or foreign file put in a
/// table folder by hand). docs/robustness.md.
fn unreadable_file(files: &[PathBuf]) -> Option<Error> {
    files.iter().find_map(|f| {
        let why = match std::fs::File::open(f) {
            Ok(file) => parquet::file::reader::SerializedFileReader::new(file).err()?.to_string(),
            Err(e) => e.to_string(),
        };
        Some(Error::file(
            f,
            format!(
                "not a Parquet file gedisim can read ({}): a table folder holds only gedisim's own files; move it out",
                crate::error::one_line(&why)
            ),
        ))
    })
}

/// Register the Parquet files `urls` of the table folder `dir` as the table `name`.
async fn register_listing(
    ctx: &SessionContext,
    name: &str,
    dir: &Path,
    urls: Vec<ListingTableUrl>,
    read_only: bool,
) -> Result<()> {
    let table_err = |e: datafusion::error::DataFusionError| Error::table(dir, e);
    let options = ListingOptions::new(Arc::new(ParquetFormat::default())).with_file_extension(".parquet");
    let config = ListingTableConfig::new_with_multi_paths(urls)
        .with_listing_options(options)
        .infer_schema(&ctx.state())
        .await
        .map_err(table_err)?;
    let table = ListingTable::try_new(config).map_err(table_err)?;
    let table: Arc<dyn TableProvider> = if read_only { Arc::new(ReadOnly(Arc::new(table))) } else { Arc::new(table) };
    ctx.register_table(name, table).map_err(table_err)?;
    Ok(())
}

/// A dataset table as SQL sees it: every read of the inner table, no `INSERT` (a dataset's tables
/// change only through gedisim's commands, which keep their schemas and registries).
#[derive(Debug)]
struct ReadOnly(Arc<dyn TableProvider>);

#[async_trait::async_trait]
impl TableProvider for ReadOnly {
    fn schema(&self) -> SchemaRef {
        self.0.schema()
    }
    fn table_type(&self) -> TableType {
        self.0.table_type()
    }
    async fn scan(
        &self,
        state: &dyn Session,
        projection: Option<&Vec<usize>>,
        filters: &[Expr],
        limit: Option<usize>,
    ) -> datafusion::error::Result<Arc<dyn ExecutionPlan>> {
        self.0.scan(state, projection, filters, limit).await
    }
    fn supports_filters_pushdown(
        &self,
        filters: &[&Expr],
    ) -> datafusion::error::Result<Vec<TableProviderFilterPushDown>> {
        self.0.supports_filters_pushdown(filters)
    }
    fn statistics(&self) -> Option<Statistics> {
        self.0.statistics()
    }
    async fn insert_into(
        &self,
        _state: &dyn Session,
        _input: Arc<dyn ExecutionPlan>,
        _op: InsertOp,
    ) -> datafusion::error::Result<Arc<dyn ExecutionPlan>> {
        datafusion::common::plan_err!("dataset tables are read-only: they change only through gedisim's commands")
    }
}
