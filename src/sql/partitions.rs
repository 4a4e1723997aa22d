//! Plans made of numbered units of work (a group of blocks to simulate, a granule to collocate): one
//! partition per unit, each mapped to its rows when it runs. What the unit does is a [`PartitionWork`];
//! [`PartitionExec`] is the execution plan around it.
//!
//! The plan's input is a table of partition numbers, one row per partition (an in-memory scan): the
//! plan maps each number to that partition's rows. A cluster hands each task the scan restricted to
//! the task's partitions, which Ballista can do for its own scans but not for a leaf of ours (it would
//! run every partition in every task; docs/scale.md).

use std::fmt;
use std::sync::Arc;

use arrow::array::{AsArray, UInt64Array};
use arrow::datatypes::{DataType, Field, Schema, SchemaRef, UInt64Type};
use arrow::record_batch::RecordBatch;
use datafusion::common::tree_node::TreeNodeRecursion;
use datafusion::common::{internal_err, Result as DfResult};
use datafusion::datasource::memory::MemorySourceConfig;
use datafusion::datasource::source::DataSourceExec;
use datafusion::execution::TaskContext;
use datafusion::physical_expr::{EquivalenceProperties, PhysicalExpr};
use datafusion::physical_plan::execution_plan::{Boundedness, EmissionType};
use datafusion::physical_plan::stream::RecordBatchStreamAdapter;
use datafusion::physical_plan::{
    DisplayAs, DisplayFormatType, ExecutionPlan, ExecutionPlanProperties, Partitioning, PlanProperties,
    SendableRecordBatchStream,
};
use futures::StreamExt;

/// Batches of one partition, computed as they are pulled.
pub type PartitionBatches = Box<dyn Iterator<Item = DfResult<RecordBatch>> + Send>;

/// What the partitions of a [`PartitionExec`] compute.
pub trait PartitionWork: fmt::Debug + Clone + Send + Sync + 'static {
    /// The plan's name (`EXPLAIN`, errors).
    const NAME: &'static str;
    /// Schema of every partition's rows (before the plan's projection).
    fn schema(&self) -> SchemaRef;
    /// Number of (global) partitions.
    fn partitions(&self) -> usize;
    /// The rows of partition `partition` (< [`partitions`](Self::partitions)).
    fn batches(&self, partition: usize) -> PartitionBatches;
}

/// The execution plan of a [`PartitionWork`], columns `projection` (all when `None`).
#[derive(Debug)]
pub struct PartitionExec<W: PartitionWork> {
    pub(crate) work: W,
    pub(crate) projection: Option<Vec<usize>>,
    input: Arc<dyn ExecutionPlan>,
    properties: Arc<PlanProperties>,
}

impl<W: PartitionWork> PartitionExec<W> {
    /// The plan of `work`, one partition per unit.
    pub fn new(work: W, projection: Option<Vec<usize>>) -> DfResult<Self> {
        let input = partition_numbers(work.partitions())?;
        Self::with_input(work, projection, input)
    }

    /// The plan of `work` whose partition numbers `input` lists (a cluster's task: some of them).
    pub fn with_input(work: W, projection: Option<Vec<usize>>, input: Arc<dyn ExecutionPlan>) -> DfResult<Self> {
        let schema = match &projection {
            Some(p) => Arc::new(work.schema().project(p)?),
            None => work.schema(),
        };
        let properties = PlanProperties::new(
            EquivalenceProperties::new(schema),
            Partitioning::UnknownPartitioning(input.output_partitioning().partition_count()),
            EmissionType::Incremental,
            Boundedness::Bounded,
        );
        Ok(PartitionExec { work, projection, input, properties: Arc::new(properties) })
    }
}

/// The (projected) batches of partition `partition` of `work`.
fn partition_batches<W: PartitionWork>(work: &W, projection: Option<Vec<usize>>, partition: usize) -> PartitionBatches {
    let n = work.partitions();
    if partition >= n {
        return Box::new(std::iter::once(internal_err!("{}: partition {partition} of {n}", W::NAME)));
    }
    Box::new(work.batches(partition).map(move |batch| match (&projection, batch) {
        (Some(p), Ok(b)) => Ok(b.project(p)?),
        (_, b) => b,
    }))
}

/// `n` partitions of one row each: the partition's number (`partition`, UInt64).
fn partition_numbers(n: usize) -> DfResult<Arc<dyn ExecutionPlan>> {
    let schema = Arc::new(Schema::new(vec![Field::new("partition", DataType::UInt64, false)]));
    let batches = (0..n as u64)
        .map(|p| Ok(vec![RecordBatch::try_new(schema.clone(), vec![Arc::new(UInt64Array::from(vec![p]))])?]))
        .collect::<DfResult<Vec<_>>>()?;
    Ok(DataSourceExec::from_data_source(MemorySourceConfig::try_new(&batches, schema, None)?))
}

impl<W: PartitionWork> DisplayAs for PartitionExec<W> {
    fn fmt_as(&self, _t: DisplayFormatType, f: &mut fmt::Formatter) -> fmt::Result {
        write!(f, "{}: {:?}, partitions={}", W::NAME, self.work, self.work.partitions())
    }
}

impl<W: PartitionWork> ExecutionPlan for PartitionExec<W> {
    fn name(&self) -> &str {
        W::NAME
    }

    fn properties(&self) -> &Arc<PlanProperties> {
        &self.properties
    }

    fn children(&self) -> Vec<&Arc<dyn ExecutionPlan>> {
        vec![&self.input]
    }

    fn benefits_from_input_partitioning(&self) -> Vec<bool> {
        // One row per partition: nothing to spread.
        vec![false]
    }

    fn apply_expressions(
        &self,
        _f: &mut dyn FnMut(&Arc<dyn PhysicalExpr>) -> DfResult<TreeNodeRecursion>,
    ) -> DfResult<TreeNodeRecursion> {
        Ok(TreeNodeRecursion::Continue)
    }

    fn with_new_children(self: Arc<Self>, children: Vec<Arc<dyn ExecutionPlan>>) -> DfResult<Arc<dyn ExecutionPlan>> {
        let [input] = <[_; 1]>::try_from(children)
            .map_err(|c| datafusion::error::DataFusionError::Internal(format!("{}: {} inputs", W::NAME, c.len())))?;
        Ok(Arc::new(PartitionExec::with_input(self.work.clone(), self.projection.clone(), input)?))
    }

    fn execute(&self, partition: usize, ctx: Arc<TaskContext>) -> DfResult<SendableRecordBatchStream> {
        let numbers = self.input.execute(partition, ctx)?;
        let (work, projection) = (self.work.clone(), self.projection.clone());
        let stream = numbers.flat_map(move |batch| {
            let iter: PartitionBatches = match batch.map(|b| b.column(0).as_primitive_opt::<UInt64Type>().cloned()) {
                Err(e) => Box::new(std::iter::once(Err(e))),
                Ok(None) => Box::new(std::iter::once(internal_err!("{}: partition numbers not UInt64", W::NAME))),
                Ok(Some(numbers)) => {
                    let (work, projection) = (work.clone(), projection.clone());
                    Box::new(
                        numbers
                            .values()
                            .to_vec()
                            .into_iter()
                            .flat_map(move |p| partition_batches(&work, projection.clone(), p as usize)),
                    )
                }
            };
            futures::stream::iter(iter)
        });
        Ok(Box::pin(RecordBatchStreamAdapter::new(self.schema(), stream)))
    }
}

/// A gedisim error as DataFusion's.
pub(crate) fn to_df(e: crate::Error) -> datafusion::error::DataFusionError {
    datafusion::error::DataFusionError::External(Box::new(e))
}
