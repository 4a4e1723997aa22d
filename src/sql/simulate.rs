//! `gedi_simulate([profile])`: the simulation as a SQL table function. It streams the `sim`
//! rows of every ingested shot, block by block ([`crate::dataset::blocks::BlockSimulation`]): each
//! block reads only the ALS row groups its footprints touch, then the simulation kernel. Shots are moved by
//! their collocation offsets when the dataset has an `offsets/` table.

use std::fmt;
use std::sync::Arc;

use arrow::datatypes::SchemaRef;
use async_trait::async_trait;
use datafusion::catalog::{Session, TableFunctionArgs, TableFunctionImpl, TableProvider};
use datafusion::common::{plan_err, Result as DfResult, ScalarValue};
use datafusion::datasource::TableType;
use datafusion::execution::TaskContext;
use datafusion::logical_expr::Expr;
use datafusion::physical_plan::stream::RecordBatchStreamAdapter;
use datafusion::physical_plan::streaming::{PartitionStream, StreamingTableExec};
use datafusion::physical_plan::{ExecutionPlan, SendableRecordBatchStream};

use crate::dataset::blocks::BlockSimulation;
use crate::dataset::shots::shot_footprints;
use crate::dataset::sim::sim_schema;
use crate::dataset::Dataset;
use crate::kernels::sim::{Profile, SimConfig};

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
            [Expr::Literal(ScalarValue::Utf8(Some(p)), _)] if p == "default" => Profile::Default,
            [Expr::Literal(ScalarValue::Utf8(Some(p)), _)] if p == "gedirat" => Profile::Gedirat,
            other => return plan_err!("gedi_simulate([profile]): profile is 'default' or 'gedirat', got {other:?}"),
        };
        Ok(Arc::new(SimulatedShots { dataset: self.dataset.clone(), profile }))
    }
}

/// The streamed `sim` rows of a dataset's shots.
#[derive(Clone)]
struct SimulatedShots {
    dataset: Dataset,
    profile: Profile,
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
        _state: &dyn Session,
        projection: Option<&Vec<usize>>,
        _filters: &[Expr],
        limit: Option<usize>,
    ) -> DfResult<Arc<dyn ExecutionPlan>> {
        let parts: Vec<Arc<dyn PartitionStream>> = vec![Arc::new(self.clone())];
        Ok(Arc::new(StreamingTableExec::try_new(sim_schema(), parts, projection, vec![], false, limit)?))
    }
}

impl PartitionStream for SimulatedShots {
    fn schema(&self) -> &SchemaRef {
        static SCHEMA: std::sync::OnceLock<SchemaRef> = std::sync::OnceLock::new();
        SCHEMA.get_or_init(sim_schema)
    }

    fn execute(&self, _ctx: Arc<TaskContext>) -> SendableRecordBatchStream {
        let this = self.clone();
        let batches =
            move || -> crate::Result<Box<dyn Iterator<Item = DfResult<arrow::record_batch::RecordBatch>> + Send>> {
                let shots = shot_footprints(&this.dataset)?;
                let blocks = BlockSimulation::new(&this.dataset, shots, SimConfig::new(this.profile))?;
                Ok(Box::new(blocks.map(|block| block.map_err(to_df)?.batch().map_err(to_df))))
            };
        let iter: Box<dyn Iterator<Item = DfResult<arrow::record_batch::RecordBatch>> + Send> = match batches() {
            Ok(it) => it,
            Err(e) => Box::new(std::iter::once(Err(to_df(e)))),
        };
        Box::pin(RecordBatchStreamAdapter::new(sim_schema(), futures::stream::iter(iter)))
    }
}

fn to_df(e: crate::Error) -> datafusion::error::DataFusionError {
    datafusion::error::DataFusionError::External(Box::new(e))
}
