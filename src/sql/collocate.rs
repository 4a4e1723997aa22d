//! The collocation of some granules as one plan ([`CollocateExec`]): a partition per granule file of
//! `shots/`, each planned and solved where it runs ([`Collocation`]), so that a cluster collocates
//! granules on different executors (`gedisim run --cluster`, `gedisim collocate --cluster`;
//! docs/scale.md). Each partition returns one row: the granule's offset rows (Arrow IPC) and what its
//! collocation did; [`granule_results`] reads them back.

use std::fmt;
use std::sync::{Arc, OnceLock};

use arrow::array::{Array, AsArray, BinaryArray, RecordBatch, StringArray, UInt64Array};
use arrow::datatypes::{DataType, Field, Schema, SchemaRef, UInt64Type};
use async_trait::async_trait;
use datafusion::catalog::{Session, TableProvider};
use datafusion::common::Result as DfResult;
use datafusion::datasource::TableType;
use datafusion::logical_expr::Expr;
use datafusion::physical_plan::ExecutionPlan;

use crate::dataset::offsets::{offsets_batch, offsets_schema};
use crate::dataset::{tables, Dataset};
use crate::error::{Error, Result};
use crate::sql::collocation::{CollocateOptions, CollocateReport, Collocation};
use crate::sql::partitions::{to_df, PartitionBatches, PartitionExec, PartitionWork};

/// The plan collocating [`CollocatedGranules`].
pub type CollocateExec = PartitionExec<CollocatedGranules>;

/// Granule files of a dataset's `shots/` collocated with some options: a table of one row per granule.
#[derive(Clone)]
pub struct CollocatedGranules {
    pub(crate) dataset: Dataset,
    pub(crate) opts: CollocateOptions,
    /// File names in `shots/`, one granule each.
    pub(crate) files: Vec<String>,
}

impl CollocatedGranules {
    /// The granules of `files` (file names in `shots/`).
    pub fn new(dataset: Dataset, opts: CollocateOptions, files: Vec<String>) -> Self {
        CollocatedGranules { dataset, opts, files }
    }
}

impl fmt::Debug for CollocatedGranules {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "collocate({}, {} granules, {})",
            self.dataset.root().display(),
            self.files.len(),
            self.opts.level.name()
        )
    }
}

/// One row per granule: `granule_file` (its name in `shots/`), `shots_correlated`, `report`
/// ([`CollocateReport`] as JSON) and `offsets` (its offset rows as an Arrow IPC stream).
pub fn collocated_schema() -> SchemaRef {
    static SCHEMA: OnceLock<SchemaRef> = OnceLock::new();
    SCHEMA
        .get_or_init(|| {
            Arc::new(Schema::new(vec![
                Field::new("granule_file", DataType::Utf8, false),
                Field::new("shots_correlated", DataType::UInt64, false),
                Field::new("report", DataType::Utf8, false),
                Field::new("offsets", DataType::Binary, false),
            ]))
        })
        .clone()
}

impl PartitionWork for CollocatedGranules {
    const NAME: &'static str = "CollocateExec";

    fn schema(&self) -> SchemaRef {
        collocated_schema()
    }

    fn partitions(&self) -> usize {
        self.files.len()
    }

    fn batches(&self, partition: usize) -> PartitionBatches {
        let this = self.clone();
        Box::new(std::iter::once_with(move || this.granule(partition).map_err(to_df)))
    }
}

impl CollocatedGranules {
    /// The row of granule `k`.
    fn granule(&self, k: usize) -> Result<RecordBatch> {
        let file = &self.files[k];
        let path = self.dataset.root().join(tables::SHOTS).join(file);
        let plan = Collocation::plan_files(&self.dataset, &self.opts, vec![path.clone()])?;
        let correlated = plan.shots_to_process() as u64;
        let (rows, report) = plan.solve(&|| {})?;
        let mut ipc = Vec::new();
        let batch = offsets_batch(&rows)?;
        let mut writer = arrow::ipc::writer::StreamWriter::try_new(&mut ipc, &offsets_schema())
            .map_err(|e| Error::table(&path, e))?;
        writer.write(&batch).and_then(|_| writer.finish()).map_err(|e| Error::table(&path, e))?;
        let report = serde_json::to_string(&report).map_err(|e| Error::table(&path, e))?;
        RecordBatch::try_new(
            collocated_schema(),
            vec![
                Arc::new(StringArray::from(vec![file.as_str()])),
                Arc::new(UInt64Array::from(vec![correlated])),
                Arc::new(StringArray::from(vec![report])),
                Arc::new(BinaryArray::from(vec![ipc.as_slice()])),
            ],
        )
        .map_err(|e| Error::table(&path, e))
    }
}

#[async_trait]
impl TableProvider for CollocatedGranules {
    fn schema(&self) -> SchemaRef {
        collocated_schema()
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
        Ok(Arc::new(CollocateExec::new(self.clone(), projection.cloned())?))
    }
}

/// A granule collocated by [`CollocateExec`].
pub struct GranuleCollocation {
    /// Its file name in `shots/`.
    pub file: String,
    /// Shots whose waveforms were correlated.
    pub shots_correlated: u64,
    pub report: CollocateReport,
    /// Its offset rows (`offsets` schema).
    pub offsets: Vec<RecordBatch>,
}

/// The granules of rows of [`collocated_schema`] (`origin` names where they came from in errors).
pub fn granule_results(origin: &std::path::Path, batch: &RecordBatch) -> Result<Vec<GranuleCollocation>> {
    let column = |name: &str| -> Result<&Arc<dyn Array>> {
        batch.column_by_name(name).ok_or_else(|| Error::field(origin, name, "missing from a collocation's rows"))
    };
    let bad = |name: &str| Error::field(origin, name, "not of the collocation's type");
    let files = column("granule_file")?.as_string_opt::<i32>().ok_or_else(|| bad("granule_file"))?;
    let correlated =
        column("shots_correlated")?.as_primitive_opt::<UInt64Type>().ok_or_else(|| bad("shots_correlated"))?;
    let reports = column("report")?.as_string_opt::<i32>().ok_or_else(|| bad("report"))?;
    let offsets = column("offsets")?.as_binary_opt::<i32>().ok_or_else(|| bad("offsets"))?;
    (0..batch.num_rows())
        .map(|i| {
            let report = serde_json::from_str(reports.value(i)).map_err(|e| Error::field(origin, "report", e))?;
            let reader = arrow::ipc::reader::StreamReader::try_new(std::io::Cursor::new(offsets.value(i)), None)
                .map_err(|e| Error::field(origin, "offsets", e))?;
            let offsets =
                reader.collect::<std::result::Result<Vec<_>, _>>().map_err(|e| Error::field(origin, "offsets", e))?;
            Ok(GranuleCollocation {
                file: files.value(i).to_string(),
                shots_correlated: correlated.value(i),
                report,
                offsets,
            })
        })
        .collect()
}

/// File name of a `shots/` file (what [`CollocatedGranules`] is given).
pub fn shots_file_name(path: &std::path::Path) -> Result<String> {
    path.file_name()
        .and_then(|n| n.to_str())
        .map(str::to_string)
        .ok_or_else(|| Error::file(path, "not a file name of the shots table"))
}
