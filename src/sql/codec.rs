//! How a cluster ships gedisim's plans (feature `cluster`): the logical and physical extension codecs
//! Ballista's client, scheduler and executors are given. They encode `gedi_simulate`'s table
//! ([`SimulatedShots`]) and plan ([`SimulateExec`]) and the collocation's ([`CollocatedGranules`],
//! [`CollocateExec`]), and hand every other node to Ballista's own codecs. What they carry is the
//! dataset's path (a location every node sees, docs/scale.md) and the work of each partition: the
//! profile and footprints of a simulation, the granule files and options of a collocation. Numbers
//! travel as bit patterns, so an executor computes exactly what the client planned.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow::datatypes::SchemaRef;
use ballista_core::serde::{BallistaLogicalExtensionCodec, BallistaPhysicalExtensionCodec};
use datafusion::catalog::TableProvider;
use datafusion::common::{exec_err, Result as DfResult, TableReference};
use datafusion::error::DataFusionError;
use datafusion::execution::TaskContext;
use datafusion::logical_expr::{Extension, LogicalPlan};
use datafusion::physical_plan::ExecutionPlan;
use datafusion_proto::logical_plan::LogicalExtensionCodec;
use datafusion_proto::physical_plan::{PhysicalExtensionCodec, PhysicalProtoConverterExtension};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::dataset::offsets::AppliedOffset;
use crate::dataset::Dataset;
use crate::kernels::collocate::segments::Level;
use crate::kernels::sim::{Footprint, Profile, PulseModel, PulseReference};
use crate::sql::collocate::{CollocateExec, CollocatedGranules};
use crate::sql::collocation::CollocateOptions;
use crate::sql::ingest::{Ingest, IngestExec, IngestKind};
use crate::sql::simulate::{FootprintPartition, Footprints, SimulateExec, SimulateWork, SimulatedShots};

/// What starts an encoded simulation (Ballista's own nodes are protobuf messages, which never start
/// with these byte strings).
const SIMULATE: &[u8] = b"gedisim/simulate/1\n";
/// What starts an encoded collocation.
const COLLOCATE: &[u8] = b"gedisim/collocate/1\n";
/// What starts an encoded ingest.
const INGEST: &[u8] = b"gedisim/ingest/2\n";

/// A plan's partition count and projection, when the node is a plan rather than a table.
#[derive(Serialize, Deserialize)]
struct WireExec {
    partitions: usize,
    projection: Option<Vec<usize>>,
}

/// A [`SimulatedShots`] as sent.
#[derive(Serialize, Deserialize)]
struct WireSimulation {
    dataset: PathBuf,
    profile: String,
    /// `None`: every ingested shot.
    partitions: Option<Vec<Vec<WireFootprint>>>,
    exec: Option<WireExec>,
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

/// A [`CollocatedGranules`] as sent.
#[derive(Serialize, Deserialize)]
struct WireCollocation {
    dataset: PathBuf,
    files: Vec<String>,
    level: String,
    segment: usize,
    /// `f64::to_bits` of the largest shift and the grid step.
    max_shift: u64,
    step: u64,
    min_segment: usize,
    pulse: WirePulse,
    exec: Option<WireExec>,
}

/// An [`Ingest`] as sent (its request and jobs are the operations layer's JSON, which names the
/// granule and tile files by absolute path or URL: every node sees them there).
#[derive(Serialize, Deserialize)]
struct WireIngest {
    kind: IngestKind,
    dataset: PathBuf,
    request: String,
    jobs: Vec<(String, String)>,
    exec: Option<WireExec>,
}

#[derive(Serialize, Deserialize)]
enum WirePulse {
    /// `f32::to_bits` of σ.
    Gaussian(Option<u32>),
    Recorded(String),
    /// A pulse file every node sees at this path.
    File(PathBuf),
}

fn external(e: impl std::error::Error + Send + Sync + 'static) -> DataFusionError {
    DataFusionError::External(Box::new(e))
}

/// `magic` then `wire` as JSON.
fn frame(magic: &[u8], wire: &impl Serialize, buf: &mut Vec<u8>) -> DfResult<()> {
    buf.extend_from_slice(magic);
    serde_json::to_writer(buf, wire).map_err(external)
}

/// The message after `magic`, if `buf` starts with it.
fn unframe<T: DeserializeOwned>(magic: &[u8], buf: &[u8]) -> Option<DfResult<T>> {
    buf.strip_prefix(magic).map(|body| serde_json::from_slice(body).map_err(external))
}

/// The absolute path of a path every node must see.
fn shared_path(path: &Path) -> DfResult<PathBuf> {
    path.canonicalize().map_err(|e| DataFusionError::Execution(format!("{}: {e}", path.display())))
}

/// The dataset at `path` on this node.
fn open_dataset(path: &Path, what: &str) -> DfResult<Dataset> {
    Dataset::open(path).map_err(|e| {
        DataFusionError::Execution(format!(
            "{what} on this node: {e} (every node must see the dataset at the same path)"
        ))
    })
}

fn encode_simulation(shots: &SimulatedShots, exec: Option<WireExec>, buf: &mut Vec<u8>) -> DfResult<()> {
    let partitions = match &shots.footprints {
        Footprints::EveryShot => None,
        Footprints::Partitions(parts) => Some(
            parts
                .iter()
                .map(|p| p.iter().map(wire_footprint).collect::<DfResult<Vec<_>>>())
                .collect::<DfResult<_>>()?,
        ),
    };
    let dataset = shared_path(shots.dataset.root())?;
    let wire = WireSimulation { dataset, profile: shots.profile.name().to_string(), partitions, exec };
    frame(SIMULATE, &wire, buf)
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

/// The [`SimulatedShots`] and plan details of `buf`, if it is an encoded simulation.
fn decode_simulation(buf: &[u8]) -> Option<DfResult<(SimulatedShots, Option<WireExec>)>> {
    let wire = unframe::<WireSimulation>(SIMULATE, buf)?;
    Some(wire.and_then(|wire| {
        let dataset = open_dataset(&wire.dataset, "gedi_simulate")?;
        let Some(profile) = Profile::from_name(&wire.profile) else {
            return exec_err!("gedi_simulate: unknown profile {:?}", wire.profile);
        };
        let footprints = match wire.partitions {
            None => Footprints::EveryShot,
            Some(parts) => Footprints::Partitions(parts.into_iter().map(footprint_partition).collect()),
        };
        Ok((SimulatedShots { dataset, profile, footprints }, wire.exec))
    }))
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

fn encode_collocation(granules: &CollocatedGranules, exec: Option<WireExec>, buf: &mut Vec<u8>) -> DfResult<()> {
    let o = &granules.opts;
    let pulse = match &o.pulse {
        PulseModel::Gaussian(sigma) => WirePulse::Gaussian(sigma.map(f32::to_bits)),
        PulseModel::Recorded(r) => WirePulse::Recorded(r.name().to_string()),
        PulseModel::File(path) => WirePulse::File(shared_path(path)?),
    };
    let wire = WireCollocation {
        dataset: shared_path(granules.dataset.root())?,
        files: granules.files.clone(),
        level: o.level.name().to_string(),
        segment: o.segment,
        max_shift: o.max_shift.to_bits(),
        step: o.step.to_bits(),
        min_segment: o.min_segment,
        pulse,
        exec,
    };
    frame(COLLOCATE, &wire, buf)
}

/// The [`CollocatedGranules`] and plan details of `buf`, if it is an encoded collocation.
fn decode_collocation(buf: &[u8]) -> Option<DfResult<(CollocatedGranules, Option<WireExec>)>> {
    let wire = unframe::<WireCollocation>(COLLOCATE, buf)?;
    Some(wire.and_then(|w| {
        let dataset = open_dataset(&w.dataset, "collocation")?;
        let Some(level) = Level::from_name(&w.level) else {
            return exec_err!("collocation: unknown level {:?}", w.level);
        };
        let pulse = match w.pulse {
            WirePulse::Gaussian(sigma) => PulseModel::Gaussian(sigma.map(f32::from_bits)),
            WirePulse::Recorded(name) => match name.parse::<PulseReference>() {
                Ok(r) => PulseModel::Recorded(r),
                Err(e) => return exec_err!("collocation: {e}"),
            },
            WirePulse::File(path) => PulseModel::File(path),
        };
        let opts = CollocateOptions {
            level,
            segment: w.segment,
            max_shift: f64::from_bits(w.max_shift),
            step: f64::from_bits(w.step),
            min_segment: w.min_segment,
            pulse,
        };
        Ok((CollocatedGranules::new(dataset, opts, w.files), w.exec))
    }))
}

fn encode_ingest(ingest: &Ingest, exec: Option<WireExec>, buf: &mut Vec<u8>) -> DfResult<()> {
    let wire = WireIngest {
        kind: ingest.kind,
        dataset: shared_path(ingest.dataset.root())?,
        request: ingest.request.clone(),
        jobs: ingest.jobs.clone(),
        exec,
    };
    frame(INGEST, &wire, buf)
}

/// The [`Ingest`] and plan details of `buf`, if it is an encoded ingest.
fn decode_ingest(buf: &[u8]) -> Option<DfResult<(Ingest, Option<WireExec>)>> {
    let wire = unframe::<WireIngest>(INGEST, buf)?;
    Some(wire.and_then(|w| {
        let dataset = open_dataset(&w.dataset, "ingest")?;
        Ok((Ingest::new(w.kind, dataset, w.request, w.jobs), w.exec))
    }))
}

/// Ballista's logical codec, and gedisim's tables.
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
        if let Some(decoded) = decode_simulation(buf) {
            return Ok(Arc::new(decoded?.0));
        }
        if let Some(decoded) = decode_collocation(buf) {
            return Ok(Arc::new(decoded?.0));
        }
        if let Some(decoded) = decode_ingest(buf) {
            return Ok(Arc::new(decoded?.0));
        }
        self.0.try_decode_table_provider(buf, table_ref, schema, ctx)
    }

    fn try_encode_table_provider(
        &self,
        table_ref: &TableReference,
        node: Arc<dyn TableProvider>,
        buf: &mut Vec<u8>,
    ) -> DfResult<()> {
        if let Some(shots) = node.downcast_ref::<SimulatedShots>() {
            return encode_simulation(shots, None, buf);
        }
        if let Some(granules) = node.downcast_ref::<CollocatedGranules>() {
            return encode_collocation(granules, None, buf);
        }
        if let Some(ingest) = node.downcast_ref::<Ingest>() {
            return encode_ingest(ingest, None, buf);
        }
        self.0.try_encode_table_provider(table_ref, node, buf)
    }
}

/// Ballista's physical codec, and gedisim's plans.
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
        let plan = |exec: Option<WireExec>| match (exec, inputs) {
            (Some(exec), [input]) => Ok((exec, input.clone())),
            _ => exec_err!("a gedisim plan without its partitions or their numbers"),
        };
        if let Some(decoded) = decode_simulation(buf) {
            let (shots, exec) = decoded?;
            let (exec, input) = plan(exec)?;
            let work = SimulateWork::new(shots, exec.partitions)?;
            return Ok(Arc::new(SimulateExec::with_input(work, exec.projection, input)?));
        }
        if let Some(decoded) = decode_collocation(buf) {
            let (granules, exec) = decoded?;
            let (exec, input) = plan(exec)?;
            if exec.partitions != granules.files.len() {
                return exec_err!("collocation: {} partitions for {} granules", exec.partitions, granules.files.len());
            }
            return Ok(Arc::new(CollocateExec::with_input(granules, exec.projection, input)?));
        }
        if let Some(decoded) = decode_ingest(buf) {
            let (ingest, exec) = decoded?;
            let (exec, input) = plan(exec)?;
            if exec.partitions != ingest.jobs.len() {
                return exec_err!("ingest: {} partitions for {} jobs", exec.partitions, ingest.jobs.len());
            }
            return Ok(Arc::new(IngestExec::with_input(ingest, exec.projection, input)?));
        }
        self.0.try_decode(buf, inputs, ctx, proto_converter)
    }

    fn try_encode(
        &self,
        node: Arc<dyn ExecutionPlan>,
        buf: &mut Vec<u8>,
        proto_converter: &dyn PhysicalProtoConverterExtension,
    ) -> DfResult<()> {
        if let Some(exec) = node.downcast_ref::<SimulateExec>() {
            let wire = WireExec { partitions: exec.work.partitions, projection: exec.projection.clone() };
            return encode_simulation(&exec.work.shots, Some(wire), buf);
        }
        if let Some(exec) = node.downcast_ref::<CollocateExec>() {
            let wire = WireExec { partitions: exec.work.files.len(), projection: exec.projection.clone() };
            return encode_collocation(&exec.work, Some(wire), buf);
        }
        if let Some(exec) = node.downcast_ref::<IngestExec>() {
            let wire = WireExec { partitions: exec.work.jobs.len(), projection: exec.projection.clone() };
            return encode_ingest(&exec.work, Some(wire), buf);
        }
        self.0.try_encode(node, buf, proto_converter)
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
        encode_simulation(&shots, Some(WireExec { partitions: 2, projection: Some(vec![0, 3]) }), &mut buf).unwrap();
        let (back, exec) = decode_simulation(&buf).unwrap().unwrap();
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
    fn collocation_options_round_trip_bit_for_bit() {
        let dir = tempfile::tempdir().unwrap();
        let ds = Dataset::create(dir.path()).unwrap();
        let pulse_file = dir.path().join("pulse.txt");
        std::fs::write(&pulse_file, "0 1\n").unwrap();
        let pulses = [
            PulseModel::Gaussian(Some(0.1 + 0.2)),
            PulseModel::Gaussian(None),
            PulseModel::Recorded(PulseReference::Peak),
            PulseModel::File(pulse_file.clone()),
        ];
        for (level, pulse) in [Level::Granule, Level::Shot, Level::Beam, Level::Beam].into_iter().zip(pulses) {
            let opts = CollocateOptions {
                level,
                segment: 17,
                max_shift: 10.000_000_000_000_2,
                step: 1.0 / 3.0,
                min_segment: 3,
                pulse: pulse.clone(),
            };
            let granules =
                CollocatedGranules::new(ds.clone(), opts.clone(), vec!["a.parquet".into(), "b.parquet".into()]);
            let mut buf = Vec::new();
            encode_collocation(&granules, Some(WireExec { partitions: 2, projection: None }), &mut buf).unwrap();
            assert!(decode_simulation(&buf).is_none());
            let (back, exec) = decode_collocation(&buf).unwrap().unwrap();
            assert_eq!(exec.map(|e| e.partitions), Some(2));
            assert_eq!(back.files, granules.files);
            let expected = match pulse {
                PulseModel::File(p) => CollocateOptions { pulse: PulseModel::File(p.canonicalize().unwrap()), ..opts },
                _ => opts,
            };
            assert_eq!(back.opts, expected);
            assert_eq!(back.opts.step.to_bits(), (1.0f64 / 3.0).to_bits());
        }
    }

    #[test]
    fn an_ingest_travels_with_its_request_and_jobs_as_given() {
        let dir = tempfile::tempdir().unwrap();
        let ds = Dataset::create(&dir.path().join("ds")).unwrap();
        let jobs = vec![("k1".to_string(), "{\"a\": 0.30000000000000004}".to_string()), ("k2".into(), "{}".into())];
        let ingest = Ingest::new(IngestKind::Tiles, ds, "{\"epsg\": 2154}".into(), jobs.clone());
        let mut buf = Vec::new();
        encode_ingest(&ingest, Some(WireExec { partitions: 2, projection: None }), &mut buf).unwrap();
        assert!(decode_collocation(&buf).is_none() && decode_simulation(&buf).is_none());
        let (back, exec) = decode_ingest(&buf).unwrap().unwrap();
        assert_eq!(exec.map(|e| e.partitions), Some(2));
        assert_eq!((back.kind, back.request.as_str(), back.jobs), (IngestKind::Tiles, "{\"epsg\": 2154}", jobs));
    }

    #[test]
    fn other_nodes_are_not_taken_for_gedisim_ones() {
        assert!(decode_simulation(b"\x0a\x04gedi").is_none());
        assert!(decode_collocation(b"\x0a\x04gedi").is_none());
        assert!(decode_ingest(b"\x0a\x04gedi").is_none());
        let mut buf = SIMULATE.to_vec();
        buf.extend_from_slice(b"{\"dataset\": 1}");
        assert!(decode_simulation(&buf).unwrap().is_err());
    }

    #[test]
    fn a_footprint_with_its_own_pulse_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let ds = Dataset::create(dir.path()).unwrap();
        let mut f = Footprint::at("7", 1.0, 2.0);
        f.pulse = Some(Arc::new(crate::kernels::sim::pulse::Pulse::dirac()));
        let shots = SimulatedShots::partitioned(ds, Profile::Default, vec![vec![(f, None)]]);
        let err = encode_simulation(&shots, None, &mut Vec::new()).unwrap_err().to_string();
        assert!(err.contains("footprint 7") && err.contains("pulse"), "{err}");
    }
}
