//! The DataFusion session: the dataset's tables registered by name, and gedisim's SQL functions
//! (thin wrappers over the kernels).

pub mod args;
pub mod l2a;
pub mod link_margin_twin;
pub mod noise_twin;
pub mod rh;
pub mod simulate;
pub mod twin;

use std::path::Path;

use std::path::PathBuf;
use std::sync::Arc;

use arrow::datatypes::SchemaRef;
use datafusion::catalog::{Session, TableProvider};
use datafusion::common::Statistics;
use datafusion::datasource::file_format::parquet::ParquetFormat;
use datafusion::datasource::listing::{ListingOptions, ListingTable, ListingTableConfig, ListingTableUrl};
use datafusion::datasource::TableType;
use datafusion::execution::runtime_env::RuntimeEnvBuilder;
use datafusion::logical_expr::dml::InsertOp;
use datafusion::logical_expr::{DocSection, Expr, ScalarUDF, TableProviderFilterPushDown};
use datafusion::physical_plan::ExecutionPlan;
use datafusion::prelude::{SQLOptions, SessionConfig, SessionContext};

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

/// A session with every table folder of `dataset` registered under its folder name (read-only)
/// and gedisim's functions, under the default [`SessionLimits`].
pub async fn session(ds: &Dataset) -> Result<SessionContext> {
    session_with(ds, &SessionLimits::default()).await
}

/// [`session`] with `limits`' memory pool.
pub async fn session_with(ds: &Dataset, limits: &SessionLimits) -> Result<SessionContext> {
    let config = SessionConfig::new().with_information_schema(true);
    let runtime = RuntimeEnvBuilder::new()
        .with_memory_limit(limits.memory_limit, 1.0)
        .build_arc()
        .map_err(|e| Error::Usage(format!("SQL: {e}")))?;
    let ctx = SessionContext::new_with_config_rt(config, runtime);
    register_functions(&ctx, ds);
    for entry in std::fs::read_dir(ds.root()).map_err(|e| Error::file(ds.root(), e))? {
        let dir = entry.map_err(|e| Error::file(ds.root(), e))?.path();
        let Some(name) = dir.file_name().and_then(|n| n.to_str()).map(str::to_string) else { continue };
        // `report/` holds the report's outputs (many schemas), not a table.
        if name == dataset::tables::REPORT || !dir.is_dir() {
            continue;
        }
        let files = ds.visible_files(&name).map_err(|e| Error::file(&dir, e))?;
        if !files.is_empty() {
            register_table(&ctx, &name, &files).await?;
        }
    }
    Ok(ctx)
}

/// What `limits` lets a statement do: reads always; DDL, DML and `COPY` only with `allow_writes`.
pub fn statement_options(limits: &SessionLimits) -> SQLOptions {
    SQLOptions::new().with_allow_ddl(limits.allow_writes).with_allow_dml(limits.allow_writes)
}

/// The section gedisim's functions are documented under (`documentation()`, `information_schema`).
pub const DOC_SECTION: DocSection =
    DocSection { include: true, label: "gedisim", description: Some("GEDI waveform functions") };

/// gedisim's scalar functions, one file each: `gedi_rh` ([`rh`]), `gedi_l2a` ([`l2a`]),
/// `gedi_noise_twin` ([`noise_twin`]), `gedi_link_margin_twin` ([`link_margin_twin`]).
pub fn scalar_functions() -> Vec<ScalarUDF> {
    vec![
        ScalarUDF::new_from_impl(rh::GediRh::new()),
        ScalarUDF::new_from_impl(l2a::GediL2a::new()),
        ScalarUDF::new_from_impl(twin::GediTwin::new(&noise_twin::NOISE_TWIN)),
        ScalarUDF::new_from_impl(twin::GediTwin::new(&link_margin_twin::LINK_MARGIN_TWIN)),
    ]
}

/// Register gedisim's SQL functions: [`scalar_functions`] and the table function
/// `gedi_simulate([profile])` ([`simulate`]), which reads `ds`.
pub fn register_functions(ctx: &SessionContext, ds: &Dataset) {
    for f in scalar_functions() {
        ctx.register_udf(f);
    }
    ctx.register_udtf("gedi_simulate", Arc::new(simulate::GediSimulate::new(ds.clone())));
}

/// Register the Parquet `files` (of one table folder) as the read-only table `name`.
pub async fn register_table(ctx: &SessionContext, name: &str, files: &[PathBuf]) -> Result<()> {
    let dir = files.first().and_then(|f| f.parent()).unwrap_or(Path::new("."));
    let table_err = |e: datafusion::error::DataFusionError| Error::table(dir, e);
    let urls = files
        .iter()
        .map(|f| {
            let path = f.canonicalize().map_err(|e| Error::file(f, e))?;
            ListingTableUrl::parse(path.to_string_lossy()).map_err(table_err)
        })
        .collect::<Result<Vec<_>>>()?;
    let options = ListingOptions::new(Arc::new(ParquetFormat::default())).with_file_extension(".parquet");
    let config = ListingTableConfig::new_with_multi_paths(urls)
        .with_listing_options(options)
        .infer_schema(&ctx.state())
        .await
        .map_err(table_err)?;
    let table = ListingTable::try_new(config).map_err(table_err)?;
    ctx.register_table(name, Arc::new(ReadOnly(Arc::new(table)))).map_err(table_err)?;
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
