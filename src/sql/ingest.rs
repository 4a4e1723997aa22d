//! The GEDI ingest of some granules as one plan ([`IngestExec`]): a partition per granule, each read
//! where it runs and its shots written into the dataset's `shots/` under a temporary name, so that a
//! cluster reads granules on its executors (`gedisim run --cluster`; docs/scale.md). Each partition
//! returns one row: the granule's key, the temporary file and what its beams held; the client checks
//! the shots and commits the files (`ops::ingest_gedi::on_cluster`).
//!
//! Reading a granule is the operations layer's (`ops::ingest_gedi`): it installs the function a
//! partition runs ([`install_writer`]) in every process that runs such a plan, and the plan carries
//! the request and each granule's job as that layer's JSON.

use std::fmt;
use std::path::PathBuf;
use std::sync::{Arc, OnceLock};

use arrow::array::{Array, AsArray, RecordBatch, StringArray};
use arrow::datatypes::{DataType, Field, Schema, SchemaRef};
use async_trait::async_trait;
use datafusion::catalog::{Session, TableProvider};
use datafusion::common::Result as DfResult;
use datafusion::datasource::TableType;
use datafusion::logical_expr::Expr;
use datafusion::physical_plan::ExecutionPlan;

use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::sql::partitions::{to_df, PartitionBatches, PartitionExec, PartitionWork};

/// What a partition runs: the dataset, the request (JSON) and one granule's job (JSON) → its shots
/// written under a temporary name, and its report (JSON).
pub type GranuleWriter = fn(&Dataset, &str, &str) -> Result<(PathBuf, String)>;

static WRITER: OnceLock<GranuleWriter> = OnceLock::new();

/// Install what the partitions of an ingest run in this process (once; later calls change nothing).
pub fn install_writer(writer: GranuleWriter) {
    let _ = WRITER.set(writer);
}

/// The plan reading [`IngestedGranules`].
pub type IngestExec = PartitionExec<IngestedGranules>;

/// Granules to read into a dataset: a table of one row per granule.
#[derive(Clone)]
pub struct IngestedGranules {
    pub(crate) dataset: Dataset,
    /// The request every granule is read with (JSON of the operations layer).
    pub(crate) request: String,
    /// Each granule's key and job (JSON of the operations layer).
    pub(crate) jobs: Vec<(String, String)>,
}

impl IngestedGranules {
    pub fn new(dataset: Dataset, request: String, jobs: Vec<(String, String)>) -> Self {
        IngestedGranules { dataset, request, jobs }
    }
}

impl fmt::Debug for IngestedGranules {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "ingest({}, {} granules)", self.dataset.root().display(), self.jobs.len())
    }
}

/// One row per granule: `granule_key`, `staged` (its shots, complete under a temporary name in
/// `shots/`) and `report` (what its reading found, JSON of the operations layer).
pub fn ingested_schema() -> SchemaRef {
    static SCHEMA: OnceLock<SchemaRef> = OnceLock::new();
    SCHEMA
        .get_or_init(|| {
            Arc::new(Schema::new(vec![
                Field::new("granule_key", DataType::Utf8, false),
                Field::new("staged", DataType::Utf8, false),
                Field::new("report", DataType::Utf8, false),
            ]))
        })
        .clone()
}

impl PartitionWork for IngestedGranules {
    const NAME: &'static str = "IngestExec";

    fn schema(&self) -> SchemaRef {
        ingested_schema()
    }

    fn partitions(&self) -> usize {
        self.jobs.len()
    }

    fn batches(&self, partition: usize) -> PartitionBatches {
        let this = self.clone();
        Box::new(std::iter::once_with(move || this.granule(partition).map_err(to_df)))
    }
}

impl IngestedGranules {
    /// The row of granule `k`.
    fn granule(&self, k: usize) -> Result<RecordBatch> {
        let (key, job) = &self.jobs[k];
        let Some(write) = WRITER.get() else {
            return Err(Error::Usage("GEDI ingest: this process cannot read granules (no writer installed)".into()));
        };
        let (staged, report) = write(&self.dataset, &self.request, job)?;
        RecordBatch::try_new(
            ingested_schema(),
            vec![
                Arc::new(StringArray::from(vec![key.as_str()])),
                Arc::new(StringArray::from(vec![staged.display().to_string()])),
                Arc::new(StringArray::from(vec![report])),
            ],
        )
        .map_err(|e| {
            let _ = std::fs::remove_file(&staged);
            Error::table(&staged, e)
        })
    }
}

#[async_trait]
impl TableProvider for IngestedGranules {
    fn schema(&self) -> SchemaRef {
        ingested_schema()
    }
    fn table_type(&self) -> TableType {
        TableType::Temporary
    }
    async fn scan(
        &self,
        _state: &dyn Session,
        projection: Option<&Vec<usize>>,
        _filters: &[Expr],
        _limit: Option<usize>,
    ) -> DfResult<Arc<dyn ExecutionPlan>> {
        Ok(Arc::new(IngestExec::new(self.clone(), projection.cloned())?))
    }
}

/// A granule read by [`IngestExec`].
pub struct GranuleIngested {
    pub key: String,
    /// Its shots, complete under a temporary name.
    pub staged: PathBuf,
    /// What its reading found (JSON of the operations layer).
    pub report: String,
}

/// The granules of rows of [`ingested_schema`] (`origin` names where they came from in errors).
pub fn granule_results(origin: &std::path::Path, batch: &RecordBatch) -> Result<Vec<GranuleIngested>> {
    let column = |name: &str| -> Result<&Arc<dyn Array>> {
        batch.column_by_name(name).ok_or_else(|| Error::field(origin, name, "missing from an ingest's rows"))
    };
    let strings = |name: &str| {
        column(name)?.as_string_opt::<i32>().ok_or_else(|| Error::field(origin, name, "not of the ingest's type"))
    };
    let (keys, staged, reports) = (strings("granule_key")?, strings("staged")?, strings("report")?);
    Ok((0..batch.num_rows())
        .map(|i| GranuleIngested {
            key: keys.value(i).to_string(),
            staged: PathBuf::from(staged.value(i)),
            report: reports.value(i).to_string(),
        })
        .collect())
}
