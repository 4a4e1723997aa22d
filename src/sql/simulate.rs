//! `gedi_simulate([profile])`: the simulation as a SQL table function. It streams the `sim`
//! rows of every ingested shot, block by block ([`crate::dataset::blocks::BlockSimulation`]): each
//! block reads only the ALS row groups its footprints touch, then the simulation kernel. Shots are moved by
//! their collocation offsets when the dataset has an `offsets/` table.
//!
//! The plan ([`SimulateExec`]) has one partition per group of whole blocks, so that a cluster runs the
//! groups on different executors (docs/scale.md); `gedisim run --cluster` gives the footprints of its
//! partitions itself (one granule's blocks per partition) through [`SimulatedShots::partitioned`].

use std::fmt;
use std::sync::Arc;

use arrow::array::{AsArray, UInt64Array};
use arrow::datatypes::{DataType, Field, Schema, SchemaRef, UInt64Type};
use arrow::record_batch::RecordBatch;
use async_trait::async_trait;
use datafusion::catalog::{Session, TableFunctionArgs, TableFunctionImpl, TableProvider};
use datafusion::common::tree_node::TreeNodeRecursion;
use datafusion::common::{internal_err, plan_err, Result as DfResult, ScalarValue};
use datafusion::datasource::memory::MemorySourceConfig;
use datafusion::datasource::source::DataSourceExec;
use datafusion::datasource::TableType;
use datafusion::execution::TaskContext;
use datafusion::logical_expr::Expr;
use datafusion::physical_expr::{EquivalenceProperties, PhysicalExpr};
use datafusion::physical_plan::execution_plan::{Boundedness, EmissionType};
use datafusion::physical_plan::stream::RecordBatchStreamAdapter;
use datafusion::physical_plan::{
    DisplayAs, DisplayFormatType, ExecutionPlan, ExecutionPlanProperties, Partitioning, PlanProperties,
    SendableRecordBatchStream,
};
use futures::StreamExt;

use crate::dataset::blocks::{blocks, BlockSimulation};
use crate::dataset::offsets::AppliedOffset;
use crate::dataset::shots::shot_footprints;
use crate::dataset::sim::sim_schema;
use crate::dataset::Dataset;
use crate::kernels::sim::{Footprint, Profile, SimConfig};

/// Footprints simulated by one partition, each with the collocation offset applied to it.
pub type FootprintPartition = Vec<(Footprint, Option<AppliedOffset>)>;

/// The `gedi_simulate` table function of one dataset.
#[derive(Debug)]
pub struct GediSimulate {
    dataset: Dataset,
}

impl GediSimulate {
    /// Table function over `dataset`'s shots and ALS points.
    pub fn new(dataset: Dataset) -> Self {
        GediSimulate { dataset }
    }
}

impl TableFunctionImpl for GediSimulate {
    fn call_with_args(&self, args: TableFunctionArgs) -> DfResult<Arc<dyn TableProvider>> {
        let profile = match args.exprs() {
            [] => Profile::Default,
            [Expr::Literal(ScalarValue::Utf8(Some(p)), _)] => match Profile::from_name(p) {
                Some(profile) => profile,
                None => return plan_err!("gedi_simulate([profile]): profile is 'default' or 'gedirat', got '{p}'"),
            },
            other => return plan_err!("gedi_simulate([profile]): profile is 'default' or 'gedirat', got {other:?}"),
        };
        Ok(Arc::new(SimulatedShots::every_shot(self.dataset.clone(), profile)))
    }
}

/// Which footprints a simulation covers.
#[derive(Debug, Clone)]
pub enum Footprints {
    /// Every ingested shot at its collocated position, its blocks dealt round-robin to the partitions
    /// (read when a partition runs, so that the plan stays small).
    EveryShot,
    /// The footprints of each partition, given.
    Partitions(Vec<FootprintPartition>),
}

/// The streamed `sim` rows of a dataset's footprints, as a table.
#[derive(Clone)]
pub struct SimulatedShots {
    pub(crate) dataset: Dataset,
    pub(crate) profile: Profile,
    pub(crate) footprints: Footprints,
}

impl SimulatedShots {
    /// Every ingested shot (`gedi_simulate`).
    pub fn every_shot(dataset: Dataset, profile: Profile) -> Self {
        SimulatedShots { dataset, profile, footprints: Footprints::EveryShot }
    }

    /// The footprints of `partitions`, one partition each.
    pub fn partitioned(dataset: Dataset, profile: Profile, partitions: Vec<FootprintPartition>) -> Self {
        SimulatedShots { dataset, profile, footprints: Footprints::Partitions(partitions) }
    }
}

impl fmt::Debug for SimulatedShots {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "gedi_simulate({})", self.dataset.root().display())
    }
}

#[async_trait]
impl TableProvider for SimulatedShots {
    fn schema(&self) -> SchemaRef {
        sim_schema()
    }
    fn table_type(&self) -> TableType {
        TableType::Temporary
    }
    async fn scan(
        &self,
        state: &dyn Session,
        projection: Option<&Vec<usize>>,
        _filters: &[Expr],
        _limit: Option<usize>,
    ) -> DfResult<Arc<dyn ExecutionPlan>> {
        let partitions = match &self.footprints {
            Footprints::EveryShot => state.config().target_partitions().max(1),
            Footprints::Partitions(p) => p.len(),
        };
        Ok(Arc::new(SimulateExec::new(self.clone(), partitions, projection.cloned())?))
    }
}

/// The simulation of [`SimulatedShots`] as an execution plan over `partitions` (global) partitions,
/// each a [`BlockSimulation`] of its footprints, the `sim` columns `projection` (all when `None`).
///
/// Its input is a table of partition numbers, one row per partition (an in-memory scan): the plan
/// maps each number to that partition's `sim` rows. A cluster hands each task the scan restricted
/// to the task's partitions, which Ballista can do for its own scans but not for a leaf of ours
/// (it would run every partition in every task).
#[derive(Debug)]
pub struct SimulateExec {
    pub(crate) shots: SimulatedShots,
    pub(crate) partitions: usize,
    pub(crate) projection: Option<Vec<usize>>,
    input: Arc<dyn ExecutionPlan>,
    properties: Arc<PlanProperties>,
}

impl SimulateExec {
    /// The plan of `shots` in `partitions` partitions.
    pub fn new(shots: SimulatedShots, partitions: usize, projection: Option<Vec<usize>>) -> DfResult<Self> {
        Self::with_input(shots, partitions, projection, partition_numbers(partitions)?)
    }

    /// The plan of `shots` in `partitions` partitions, whose partition numbers `input` lists.
    pub fn with_input(
        shots: SimulatedShots,
        partitions: usize,
        projection: Option<Vec<usize>>,
        input: Arc<dyn ExecutionPlan>,
    ) -> DfResult<Self> {
        if let Footprints::Partitions(p) = &shots.footprints {
            if p.len() != partitions {
                return internal_err!("gedi_simulate: {} footprint partitions for {partitions}", p.len());
            }
        }
        let schema = match &projection {
            Some(p) => Arc::new(sim_schema().project(p)?),
            None => sim_schema(),
        };
        let properties = PlanProperties::new(
            EquivalenceProperties::new(schema),
            Partitioning::UnknownPartitioning(input.output_partitioning().partition_count()),
            EmissionType::Incremental,
            Boundedness::Bounded,
        );
        Ok(SimulateExec { shots, partitions, projection, input, properties: Arc::new(properties) })
    }
}

/// The `sim` batches of (global) partition `partition` of `partitions`, simulated as they are pulled.
fn partition_batches(
    shots: SimulatedShots,
    partitions: usize,
    projection: Option<Vec<usize>>,
    partition: usize,
) -> Box<dyn Iterator<Item = DfResult<RecordBatch>> + Send> {
    if partition >= partitions {
        return Box::new(std::iter::once(internal_err!("gedi_simulate: partition {partition} of {partitions}")));
    }
    let start = move || -> crate::Result<BlockSimulation> {
        let footprints = match shots.footprints {
            Footprints::Partitions(mut p) => p.swap_remove(partition),
            Footprints::EveryShot => blocks(shot_footprints(&shots.dataset)?)
                .into_iter()
                .skip(partition)
                .step_by(partitions)
                .flatten()
                .collect(),
        };
        BlockSimulation::new(&shots.dataset, footprints, SimConfig::new(shots.profile))
    };
    let blocks = std::iter::once_with(start).flat_map(move |started| -> Box<dyn Iterator<Item = _> + Send> {
        match started {
            Err(e) => Box::new(std::iter::once(Err(to_df(e)))),
            Ok(blocks) => {
                let projection = projection.clone();
                Box::new(blocks.map(move |block| {
                    let batch = block.and_then(|b| b.batch()).map_err(to_df)?;
                    match &projection {
                        Some(p) => Ok(batch.project(p)?),
                        None => Ok(batch),
                    }
                }))
            }
        }
    });
    Box::new(blocks)
}

/// `n` partitions of one row each: the partition's number (`partition`, UInt64).
fn partition_numbers(n: usize) -> DfResult<Arc<dyn ExecutionPlan>> {
    let schema = Arc::new(Schema::new(vec![Field::new("partition", DataType::UInt64, false)]));
    let batches = (0..n as u64)
        .map(|p| Ok(vec![RecordBatch::try_new(schema.clone(), vec![Arc::new(UInt64Array::from(vec![p]))])?]))
        .collect::<DfResult<Vec<_>>>()?;
    Ok(DataSourceExec::from_data_source(MemorySourceConfig::try_new(&batches, schema, None)?))
}

impl DisplayAs for SimulateExec {
    fn fmt_as(&self, _t: DisplayFormatType, f: &mut fmt::Formatter) -> fmt::Result {
        write!(f, "SimulateExec: {:?}, partitions={}", self.shots, self.partitions)
    }
}

impl ExecutionPlan for SimulateExec {
    fn name(&self) -> &str {
        "SimulateExec"
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
            .map_err(|c| datafusion::error::DataFusionError::Internal(format!("SimulateExec: {} inputs", c.len())))?;
        Ok(Arc::new(SimulateExec::with_input(self.shots.clone(), self.partitions, self.projection.clone(), input)?))
    }

    fn execute(&self, partition: usize, ctx: Arc<TaskContext>) -> DfResult<SendableRecordBatchStream> {
        let numbers = self.input.execute(partition, ctx)?;
        let (shots, n, projection) = (self.shots.clone(), self.partitions, self.projection.clone());
        let stream = numbers.flat_map(move |batch| {
            let (shots, projection) = (shots.clone(), projection.clone());
            let iter: Box<dyn Iterator<Item = DfResult<RecordBatch>> + Send> =
                match batch.map(|b| b.column(0).as_primitive_opt::<UInt64Type>().cloned()) {
                    Err(e) => Box::new(std::iter::once(Err(e))),
                    Ok(None) => Box::new(std::iter::once(internal_err!("SimulateExec: partition numbers not UInt64"))),
                    Ok(Some(numbers)) => Box::new(
                        numbers
                            .values()
                            .to_vec()
                            .into_iter()
                            .flat_map(move |g| partition_batches(shots.clone(), n, projection.clone(), g as usize)),
                    ),
                };
            futures::stream::iter(iter)
        });
        Ok(Box::pin(RecordBatchStreamAdapter::new(self.schema(), stream)))
    }
}

fn to_df(e: crate::Error) -> datafusion::error::DataFusionError {
    datafusion::error::DataFusionError::External(Box::new(e))
}
