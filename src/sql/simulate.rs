//! `gedi_simulate([profile])`: the simulation as a SQL table function. It streams the `sim`
//! rows of every ingested shot, block by block ([`crate::sql::blocks::BlockSimulation`]): each
//! block reads only the ALS row groups its footprints touch, then the simulation kernel. Shots are moved by
//! their collocation offsets when the dataset has an `offsets/` table.
//!
//! The plan ([`SimulateExec`], a [`PartitionExec`]) has one partition per group of whole blocks, so
//! that a cluster runs the groups on different executors (docs/scale.md); `gedisim run --cluster`
//! gives the footprints of its partitions itself (one granule's blocks per partition) through
//! [`SimulatedShots::partitioned`].

use std::fmt;
use std::sync::Arc;

use arrow::datatypes::SchemaRef;
use async_trait::async_trait;
use datafusion::catalog::{Session, TableFunctionArgs, TableFunctionImpl, TableProvider};
use datafusion::common::{internal_err, plan_err, Result as DfResult, ScalarValue};
use datafusion::datasource::TableType;
use datafusion::logical_expr::Expr;
use datafusion::physical_plan::ExecutionPlan;

use crate::dataset::offsets::AppliedOffset;
use crate::dataset::shots::shot_footprints;
use crate::dataset::sim::sim_schema;
use crate::dataset::Dataset;
use crate::kernels::sim::{Footprint, Profile, SimConfig};
use crate::sql::blocks::{blocks, BlockSimulation};
use crate::sql::partitions::{to_df, PartitionBatches, PartitionExec, PartitionWork};

/// Footprints simulated by one partition, each with the collocation offset applied to it.
pub type FootprintPartition = Vec<(Footprint, Option<AppliedOffset>)>;

/// The `gedi_simulate` table function of one dataset.
#[derive(Debug)]
pub struct GediSimulate {
    /// The dataset, or why there is none to simulate from.
    dataset: std::result::Result<Dataset, String>,
}

impl GediSimulate {
    /// Table function over `dataset`'s shots and ALS points.
    pub fn new(dataset: Dataset) -> Self {
        GediSimulate { dataset: Ok(dataset) }
    }

    /// The function where it cannot run, saying `why` when called.
    pub fn unavailable(why: String) -> Self {
        GediSimulate { dataset: Err(why) }
    }
}

impl TableFunctionImpl for GediSimulate {
    fn call_with_args(&self, args: TableFunctionArgs) -> DfResult<Arc<dyn TableProvider>> {
        let dataset = match &self.dataset {
            Ok(ds) => ds.clone(),
            Err(why) => return plan_err!("gedi_simulate: {why}"),
        };
        let profile = match args.exprs() {
            [] => Profile::Default,
            [Expr::Literal(ScalarValue::Utf8(Some(p)), _)] => match Profile::from_name(p) {
                Some(profile) => profile,
                None => return plan_err!("gedi_simulate([profile]): profile is 'default' or 'gedirat', got '{p}'"),
            },
            other => return plan_err!("gedi_simulate([profile]): profile is 'default' or 'gedirat', got {other:?}"),
        };
        Ok(Arc::new(SimulatedShots::every_shot(dataset, profile)))
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
        Ok(Arc::new(SimulateExec::new(SimulateWork::new(self.clone(), partitions)?, projection.cloned())?))
    }
}

/// The simulation of [`SimulatedShots`] in `partitions` (global) partitions, each a [`BlockSimulation`]
/// of its footprints.
#[derive(Debug, Clone)]
pub struct SimulateWork {
    pub(crate) shots: SimulatedShots,
    pub(crate) partitions: usize,
}

impl SimulateWork {
    /// `shots` in `partitions` partitions (as many as given footprint partitions, if given).
    pub fn new(shots: SimulatedShots, partitions: usize) -> DfResult<Self> {
        if let Footprints::Partitions(p) = &shots.footprints {
            if p.len() != partitions {
                return internal_err!("gedi_simulate: {} footprint partitions for {partitions}", p.len());
            }
        }
        Ok(SimulateWork { shots, partitions })
    }
}

/// The plan of `gedi_simulate`.
pub type SimulateExec = PartitionExec<SimulateWork>;

impl PartitionWork for SimulateWork {
    const NAME: &'static str = "SimulateExec";

    fn schema(&self) -> SchemaRef {
        sim_schema()
    }

    fn partitions(&self) -> usize {
        self.partitions
    }

    fn batches(&self, partition: usize) -> PartitionBatches {
        let (shots, partitions) = (self.shots.clone(), self.partitions);
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
        let blocks = std::iter::once_with(start).flat_map(|started| -> PartitionBatches {
            match started {
                Err(e) => Box::new(std::iter::once(Err(to_df(e)))),
                Ok(blocks) => Box::new(blocks.map(|block| block.and_then(|b| b.batch()).map_err(to_df))),
            }
        });
        Box::new(blocks)
    }
}
