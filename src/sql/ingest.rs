//! An ingest as one plan ([`IngestExec`]): a partition per unit of work — a GEDI granule, or an ALS
//! tile — each read where it runs and its files written into the dataset under temporary names, so
//! that a cluster reads granules and tiles on its executors (`gedisim run --cluster`; docs/scale.md).
//! Each partition returns one row: the unit's key, its staged files and its report; the client
//! checks them and commits the files ([`run_ingest`] gathers the rows; `ops::ingest_gedi::on_cluster`
//! and `ops::ingest_als::on_cluster` commit).
//!
//! Reading a granule or a tile is the operations layer's: it installs the function a partition runs
//! ([`install_stager`]) in every process that runs such a plan, and the plan carries the request and
//! each unit's job as that layer's JSON.

use std::collections::HashMap;
use std::fmt;
use std::path::PathBuf;
use std::sync::{Arc, OnceLock};

use arrow::array::{Array, AsArray, ListBuilder, RecordBatch, StringArray, StringBuilder};
use arrow::datatypes::{DataType, Field, Schema, SchemaRef};
use async_trait::async_trait;
use datafusion::catalog::{Session, TableProvider};
use datafusion::common::Result as DfResult;
use datafusion::datasource::TableType;
use datafusion::logical_expr::Expr;
use datafusion::physical_plan::ExecutionPlan;
use futures::StreamExt;
use serde::{Deserialize, Serialize};

use crate::dataset::Dataset;
use crate::error::{Error, Result};
use crate::sql::partitions::{to_df, PartitionBatches, PartitionExec, PartitionWork};
use crate::sql::Engine;

/// What an ingest plan reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum IngestKind {
    /// GEDI granules (L1B/L2A pairs) into `shots/`.
    Granules,
    /// ALS tiles into `als/` and `tiles/`.
    Tiles,
}

impl IngestKind {
    /// How errors name it.
    fn name(self) -> &'static str {
        match self {
            IngestKind::Granules => "GEDI ingest",
            IngestKind::Tiles => "ALS ingest",
        }
    }

    fn stager(self) -> &'static OnceLock<Stager> {
        static GRANULES: OnceLock<Stager> = OnceLock::new();
        static TILES: OnceLock<Stager> = OnceLock::new();
        match self {
            IngestKind::Granules => &GRANULES,
            IngestKind::Tiles => &TILES,
        }
    }
}

/// What a partition runs: the dataset, the request (JSON) and one unit's job (JSON) → the files it
/// wrote under temporary names, and its report (JSON).
pub type Stager = fn(&Dataset, &str, &str) -> Result<(Vec<PathBuf>, String)>;

/// Install what the partitions of an ingest of `kind` run in this process (once; later calls change
/// nothing).
pub fn install_stager(kind: IngestKind, stager: Stager) {
    let _ = kind.stager().set(stager);
}

/// The plan reading an [`Ingest`].
pub type IngestExec = PartitionExec<Ingest>;

/// Units to read into a dataset: a table of one row per unit.
#[derive(Clone)]
pub struct Ingest {
    pub(crate) kind: IngestKind,
    pub(crate) dataset: Dataset,
    /// The request every unit is read with (JSON of the operations layer).
    pub(crate) request: String,
    /// Each unit's key and job (JSON of the operations layer).
    pub(crate) jobs: Vec<(String, String)>,
}

impl Ingest {
    pub fn new(kind: IngestKind, dataset: Dataset, request: String, jobs: Vec<(String, String)>) -> Self {
        Ingest { kind, dataset, request, jobs }
    }
}

impl fmt::Debug for Ingest {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "ingest({:?} of {}, {} jobs)", self.kind, self.dataset.root().display(), self.jobs.len())
    }
}

/// One row per unit: `key`, `staged` (the files it wrote, complete under temporary names in the
/// dataset) and `report` (what its reading found, JSON of the operations layer).
pub fn ingested_schema() -> SchemaRef {
    static SCHEMA: OnceLock<SchemaRef> = OnceLock::new();
    SCHEMA
        .get_or_init(|| {
            Arc::new(Schema::new(vec![
                Field::new("key", DataType::Utf8, false),
                Field::new("staged", DataType::List(Arc::new(Field::new_list_field(DataType::Utf8, false))), false),
                Field::new("report", DataType::Utf8, false),
            ]))
        })
        .clone()
}

impl PartitionWork for Ingest {
    const NAME: &'static str = "IngestExec";

    fn schema(&self) -> SchemaRef {
        ingested_schema()
    }

    fn partitions(&self) -> usize {
        self.jobs.len()
    }

    fn batches(&self, partition: usize) -> PartitionBatches {
        let this = self.clone();
        Box::new(std::iter::once_with(move || this.unit(partition).map_err(to_df)))
    }
}

impl Ingest {
    /// The row of unit `k`.
    fn unit(&self, k: usize) -> Result<RecordBatch> {
        let (key, job) = &self.jobs[k];
        let Some(stage) = self.kind.stager().get() else {
            return Err(Error::Usage(format!(
                "{}: this process cannot read its inputs (nothing installed)",
                self.kind.name()
            )));
        };
        let (staged, report) = stage(&self.dataset, &self.request, job)?;
        let mut files =
            ListBuilder::new(StringBuilder::new()).with_field(Arc::new(Field::new_list_field(DataType::Utf8, false)));
        files.append_value(staged.iter().map(|p| Some(p.display().to_string())));
        RecordBatch::try_new(
            ingested_schema(),
            vec![
                Arc::new(StringArray::from(vec![key.as_str()])),
                Arc::new(files.finish()),
                Arc::new(StringArray::from(vec![report])),
            ],
        )
        .map_err(|e| {
            remove_all(&staged);
            Error::table(self.dataset.root(), e)
        })
    }
}

#[async_trait]
impl TableProvider for Ingest {
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

/// A unit read by [`IngestExec`].
pub struct Ingested {
    pub key: String,
    /// The files it wrote, complete under temporary names.
    pub staged: Vec<PathBuf>,
    /// What its reading found (JSON of the operations layer).
    pub report: String,
}

impl Ingested {
    /// Remove its staged files (what is not committed).
    pub fn discard(&self) {
        remove_all(&self.staged);
    }
}

fn remove_all(files: &[PathBuf]) {
    for f in files {
        let _ = std::fs::remove_file(f);
    }
}

/// The units of rows of [`ingested_schema`] (`origin` names where they came from in errors).
pub fn ingested_rows(origin: &std::path::Path, batch: &RecordBatch) -> Result<Vec<Ingested>> {
    let column = |name: &str| -> Result<&Arc<dyn Array>> {
        batch.column_by_name(name).ok_or_else(|| Error::field(origin, name, "missing from an ingest's rows"))
    };
    let strings = |name: &str| {
        column(name)?.as_string_opt::<i32>().ok_or_else(|| Error::field(origin, name, "not of the ingest's type"))
    };
    let (keys, reports) = (strings("key")?, strings("report")?);
    let staged = column("staged")?.as_list_opt::<i32>().ok_or_else(|| Error::field(origin, "staged", "not a list"))?;
    (0..batch.num_rows())
        .map(|i| {
            let files = staged.value(i);
            let files = files.as_string_opt::<i32>().ok_or_else(|| Error::field(origin, "staged", "not of paths"))?;
            Ok(Ingested {
                key: keys.value(i).to_string(),
                staged: files.iter().flatten().map(PathBuf::from).collect(),
                report: reports.value(i).to_string(),
            })
        })
        .collect()
}

/// Run `ingest` on `engine` and gather its rows by key (`done` told of each as it comes back). A
/// failure leaves no staged file behind; so must the caller, for the rows it does not commit.
pub fn run_ingest(engine: &Engine, ingest: Ingest, done: &dyn Fn(&Ingested)) -> Result<HashMap<String, Ingested>> {
    let (kind, dataset) = (ingest.kind, ingest.dataset.clone());
    let failed = |e: datafusion::error::DataFusionError| {
        Error::Usage(format!("{} on the cluster: {}", kind.name(), crate::error::one_line(&e.to_string())))
    };
    let mut rows: HashMap<String, Ingested> = HashMap::new();
    let read = crate::sql::runtime()?.block_on(async {
        let ctx = crate::sql::session_on(&dataset, &Default::default(), engine).await?;
        let mut stream = ctx.read_table(Arc::new(ingest)).map_err(failed)?.execute_stream().await.map_err(failed)?;
        while let Some(batch) = stream.next().await {
            for row in ingested_rows(dataset.root(), &batch.map_err(failed)?)? {
                done(&row);
                rows.insert(row.key.clone(), row);
            }
        }
        Ok::<_, Error>(())
    });
    match read {
        Ok(()) => Ok(rows),
        Err(e) => {
            rows.values().for_each(Ingested::discard);
            Err(e)
        }
    }
}
