//! How a cluster ships `gedi_simulate` (feature `cluster`): the logical and physical extension codecs
//! Ballista's client, scheduler and executors are given. They encode [`SimulatedShots`] (a table in a
//! logical plan) and [`SimulateExec`] (its execution plan) and hand every other node to Ballista's own
//! codecs. What they carry is the dataset's path (a location every node sees, docs/scale.md), the
//! profile and the footprints of each partition; coordinates travel as bit patterns, so an executor
//! simulates exactly the positions the client planned.

use std::path::PathBuf;
use std::sync::Arc;

use arrow::datatypes::SchemaRef;
use ballista_core::serde::{BallistaLogicalExtensionCodec, BallistaPhysicalExtensionCodec};
use datafusion::catalog::TableProvider;
use datafusion::common::{exec_err, Result as DfResult, TableReference};
use datafusion::execution::TaskContext;
use datafusion::logical_expr::{Extension, LogicalPlan};
use datafusion::physical_plan::ExecutionPlan;
use datafusion_proto::logical_plan::LogicalExtensionCodec;
use datafusion_proto::physical_plan::{PhysicalExtensionCodec, PhysicalProtoConverterExtension};
use serde::{Deserialize, Serialize};

use crate::dataset::offsets::AppliedOffset;
use crate::dataset::Dataset;
use crate::kernels::sim::{Footprint, Profile};
use crate::sql::simulate::{FootprintPartition, Footprints, SimulateExec, SimulatedShots};

/// What starts an encoded gedisim node (Ballista's own nodes are protobuf messages, which never
/// start with this byte string).
const MAGIC: &[u8] = b"gedisim/simulate/1\n";

/// A [`SimulatedShots`] (and, for a plan, its partition count and projection) as sent.
#[derive(Serialize, Deserialize)]
struct Wire {
    dataset: PathBuf,
    profile: String,
    /// `None`: every ingested shot.
    partitions: Option<Vec<Vec<WireFootprint>>>,
    exec: Option<WireExec>,
}

#[derive(Serialize, Deserialize)]
struct WireExec {
    partitions: usize,
    projection: Option<Vec<usize>>,
}

#[derive(Serialize, Deserialize)]
struct WireFootprint {
    id: String,
    /// `f64::to_bits` of x and y.
    x: u64,
    y: u64,
    offset: Option<WireOffset>,
}

#[derive(Serialize, Deserialize)]
struct WireOffset {
    segment_id: String,
    dx: u64,
    dy: u64,
    dz: u64,
}

fn encode(shots: &SimulatedShots, exec: Option<WireExec>, buf: &mut Vec<u8>) -> DfResult<()> {
    let root = shots.dataset.root();
    let dataset = root
        .canonicalize()
        .map_err(|e| datafusion::error::DataFusionError::Execution(format!("{}: {e}", root.display())))?;
    let partitions = match &shots.footprints {
        Footprints::EveryShot => None,
        Footprints::Partitions(parts) => Some(
            parts
                .iter()
                .map(|p| p.iter().map(wire_footprint).collect::<DfResult<Vec<_>>>())
                .collect::<DfResult<_>>()?,
        ),
    };
    let wire = Wire { dataset, profile: shots.profile.name().to_string(), partitions, exec };
    buf.extend_from_slice(MAGIC);
    serde_json::to_writer(buf, &wire).map_err(|e| datafusion::error::DataFusionError::External(Box::new(e)))
}

fn wire_footprint((f, offset): &(Footprint, Option<AppliedOffset>)) -> DfResult<WireFootprint> {
    if f.pulse.is_some() {
        return exec_err!("gedi_simulate: footprint {} has its own pulse, which a cluster does not ship", f.id);
    }
    Ok(WireFootprint {
        id: f.id.clone(),
        x: f.x.to_bits(),
        y: f.y.to_bits(),
        offset: offset.as_ref().map(|o| WireOffset {
            segment_id: o.segment_id.clone(),
            dx: o.dx.to_bits(),
            dy: o.dy.to_bits(),
            dz: o.dz.to_bits(),
        }),
    })
}

/// The [`SimulatedShots`] and plan details of `buf`, if it is a gedisim node.
fn decode(buf: &[u8]) -> Option<DfResult<(SimulatedShots, Option<WireExec>)>> {
    let body = buf.strip_prefix(MAGIC)?;
    Some((|| {
        let wire: Wire =
            serde_json::from_slice(body).map_err(|e| datafusion::error::DataFusionError::External(Box::new(e)))?;
        let dataset = Dataset::open(&wire.dataset).map_err(|e| {
            datafusion::error::DataFusionError::Execution(format!(
                "gedi_simulate on this node: {e} (every node must see the dataset at the same path)"
            ))
        })?;
        let Some(profile) = Profile::from_name(&wire.profile) else {
            return exec_err!("gedi_simulate: unknown profile {:?}", wire.profile);
        };
        let footprints = match wire.partitions {
            None => Footprints::EveryShot,
            Some(parts) => Footprints::Partitions(parts.into_iter().map(footprint_partition).collect()),
        };
        Ok((SimulatedShots { dataset, profile, footprints }, wire.exec))
    })())
}

fn footprint_partition(p: Vec<WireFootprint>) -> FootprintPartition {
    p.into_iter()
        .map(|w| {
            let f = Footprint::at(w.id, f64::from_bits(w.x), f64::from_bits(w.y));
            let offset = w.offset.map(|o| AppliedOffset {
                segment_id: o.segment_id,
                dx: f64::from_bits(o.dx),
                dy: f64::from_bits(o.dy),
                dz: f64::from_bits(o.dz),
            });
            (f, offset)
        })
        .collect()
}

/// Ballista's logical codec, and `gedi_simulate`'s tables.
#[derive(Debug, Default)]
pub struct LogicalCodec(BallistaLogicalExtensionCodec);

impl LogicalExtensionCodec for LogicalCodec {
    fn try_decode(&self, buf: &[u8], inputs: &[LogicalPlan], ctx: &TaskContext) -> DfResult<Extension> {
        self.0.try_decode(buf, inputs, ctx)
    }

    fn try_encode(&self, node: &Extension, buf: &mut Vec<u8>) -> DfResult<()> {
        self.0.try_encode(node, buf)
    }

    fn try_decode_table_provider(
        &self,
        buf: &[u8],
        table_ref: &TableReference,
        schema: SchemaRef,
        ctx: &TaskContext,
    ) -> DfResult<Arc<dyn TableProvider>> {
        match decode(buf) {
            Some(shots) => Ok(Arc::new(shots?.0)),
            None => self.0.try_decode_table_provider(buf, table_ref, schema, ctx),
        }
    }

    fn try_encode_table_provider(
        &self,
        table_ref: &TableReference,
        node: Arc<dyn TableProvider>,
        buf: &mut Vec<u8>,
    ) -> DfResult<()> {
        match node.downcast_ref::<SimulatedShots>() {
            Some(shots) => encode(shots, None, buf),
            None => self.0.try_encode_table_provider(table_ref, node, buf),
        }
    }
}

/// Ballista's physical codec, and `gedi_simulate`'s plan.
#[derive(Debug, Default)]
pub struct PhysicalCodec(BallistaPhysicalExtensionCodec);

impl PhysicalExtensionCodec for PhysicalCodec {
    fn try_decode(
        &self,
        buf: &[u8],
        inputs: &[Arc<dyn ExecutionPlan>],
        ctx: &TaskContext,
        proto_converter: &dyn PhysicalProtoConverterExtension,
    ) -> DfResult<Arc<dyn ExecutionPlan>> {
        match decode(buf) {
            Some(decoded) => {
                let (shots, exec) = decoded?;
                let (Some(exec), [input]) = (exec, inputs) else {
                    return exec_err!("gedi_simulate: a plan without its partitions or their numbers");
                };
                Ok(Arc::new(SimulateExec::with_input(shots, exec.partitions, exec.projection, input.clone())?))
            }
            None => self.0.try_decode(buf, inputs, ctx, proto_converter),
        }
    }

    fn try_encode(
        &self,
        node: Arc<dyn ExecutionPlan>,
        buf: &mut Vec<u8>,
        proto_converter: &dyn PhysicalProtoConverterExtension,
    ) -> DfResult<()> {
        match node.downcast_ref::<SimulateExec>() {
            Some(exec) => {
                let wire = WireExec { partitions: exec.partitions, projection: exec.projection.clone() };
                encode(&exec.shots, Some(wire), buf)
            }
            None => self.0.try_encode(node, buf, proto_converter),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn footprints_round_trip_bit_for_bit() {
        let dir = tempfile::tempdir().unwrap();
        let ds = Dataset::create(dir.path()).unwrap();
        let offset = AppliedOffset { segment_id: "s1".into(), dx: 0.1 + 0.2, dy: -1e-300, dz: f64::MIN_POSITIVE };
        let parts = vec![
            vec![(Footprint::at("1", 652_000.123_456_789_1, 6_862_000.987_654_321), Some(offset))],
            vec![(Footprint::at("2", f64::NAN, -0.0), None)],
        ];
        let shots = SimulatedShots::partitioned(ds, Profile::Gedirat, parts.clone());
        let mut buf = Vec::new();
        encode(&shots, Some(WireExec { partitions: 2, projection: Some(vec![0, 3]) }), &mut buf).unwrap();
        let (back, exec) = decode(&buf).unwrap().unwrap();
        assert_eq!(back.profile, Profile::Gedirat);
        assert_eq!(exec.map(|e| (e.partitions, e.projection)), Some((2, Some(vec![0, 3]))));
        let Footprints::Partitions(got) = back.footprints else { panic!("partitions lost") };
        assert_eq!(got.len(), 2);
        for (g, p) in got.iter().flatten().zip(parts.iter().flatten()) {
            assert_eq!(
                (g.0.id.as_str(), g.0.x.to_bits(), g.0.y.to_bits()),
                (p.0.id.as_str(), p.0.x.to_bits(), p.0.y.to_bits())
            );
            let bits = |o: &Option<AppliedOffset>| {
                o.as_ref().map(|o| (o.segment_id.clone(), o.dx.to_bits(), o.dy.to_bits(), o.dz.to_bits()))
            };
            assert_eq!(bits(&g.1), bits(&p.1));
        }
    }

    #[test]
    fn other_nodes_are_not_taken_for_gedisim_ones() {
        assert!(decode(b"\x0a\x04gedi").is_none());
        let mut buf = MAGIC.to_vec();
        buf.extend_from_slice(b"{\"dataset\": 1}");
        assert!(decode(&buf).unwrap().is_err());
    }

    #[test]
    fn a_footprint_with_its_own_pulse_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let ds = Dataset::create(dir.path()).unwrap();
        let mut f = Footprint::at("7", 1.0, 2.0);
        f.pulse = Some(Arc::new(crate::kernels::sim::pulse::Pulse::dirac()));
        let shots = SimulatedShots::partitioned(ds, Profile::Default, vec![vec![(f, None)]]);
        let err = encode(&shots, None, &mut Vec::new()).unwrap_err().to_string();
        assert!(err.contains("footprint 7") && err.contains("pulse"), "{err}");
    }
}
