//! The GEDI ingest on a cluster (`run --cluster`): the granules to read as one plan, a partition per
//! granule ([`crate::sql::ingest::IngestExec`]); each executor reads its granule and writes its
//! shots under a temporary name in the dataset's `shots/`. This process only plans and commits: it
//! checks every staged file's shot numbers against the dataset and the other granules (as a local
//! ingest checks each batch), then puts the files in place and writes their records, in the input
//! order. Every node must see the granule files and the dataset at the same paths (docs/scale.md):
//! the plan carries the files canonicalised, the request and each job as JSON ([`write_from_json`],
//! which executors run: `ops::cluster` installs it).

use std::path::Path;
use std::sync::Arc;

use super::into_dataset::{write_granule_shots, GranuleJob, GranuleOutcome};
use super::join::ShotOwners;
use super::{BeamReport, GediOptions};
use crate::dataset::shots::col;
use crate::dataset::{tables, Dataset};
use crate::error::{Error, Result};
use crate::ops::progress::Progress;
use crate::sql::ingest::{run_ingest, Ingest, IngestKind, Ingested};
use crate::sql::Engine;

/// What commits a granule: its job, staged shots and beams.
pub(super) type Commit<'a> = dyn Fn(&GranuleJob, &Path, &[BeamReport]) -> Result<GranuleOutcome> + Sync + 'a;

/// Read `jobs` on the cluster of `engine` (`progress` advanced as each comes back), then check and
/// commit each; one result per job, in order.
pub(super) fn ingest_granules(
    engine: &Engine,
    dataset: &Dataset,
    jobs: &[GranuleJob],
    opts: &GediOptions,
    owners: &ShotOwners,
    commit: &Commit,
    progress: &dyn Progress,
) -> Result<Vec<(GranuleOutcome, Vec<BeamReport>)>> {
    if jobs.is_empty() {
        return Ok(Vec::new());
    }
    let json = |e: serde_json::Error| Error::file(dataset.root(), format!("a request gedisim cannot send: {e}"));
    let request = serde_json::to_string(opts).map_err(json)?;
    let wire_jobs = jobs
        .iter()
        .map(|j| Ok((j.key.clone(), serde_json::to_string(&shared(j)?).map_err(json)?)))
        .collect::<Result<Vec<_>>>()?;
    let ingest = Ingest::new(IngestKind::Granules, dataset.clone(), request, wire_jobs);
    let mut staged = run_ingest(engine, ingest, &|_| progress.advance(1))?;
    let committed = jobs
        .iter()
        .map(|job| {
            let g = staged.remove(&job.key).ok_or_else(|| {
                Error::Usage(format!("GEDI ingest on the cluster: granule {} did not come back", job.key))
            })?;
            check_and_commit(job, g, owners, commit)
        })
        .collect::<Result<Vec<_>>>();
    // A failure leaves nothing staged behind.
    staged.values().for_each(Ingested::discard);
    committed
}

/// `job` with its files by absolute path, as every node must see them.
fn shared(job: &GranuleJob) -> Result<GranuleJob> {
    let absolute = |p: &Option<std::path::PathBuf>| {
        p.as_deref().map(|p| p.canonicalize().map_err(|e| Error::file(p, format!("cannot open: {e}")))).transpose()
    };
    let mut job = job.clone();
    (job.pair.l1b, job.pair.l2a) = (absolute(&job.pair.l1b)?, absolute(&job.pair.l2a)?);
    Ok(job)
}

/// What a partition of the ingest runs (`sql::ingest`): the granule of `job` (JSON of a
/// [`GranuleJob`]) read with `request` (JSON of [`GediOptions`]) into the dataset's `shots/` under a
/// temporary name; its beam reports as JSON.
pub fn write_from_json(dataset: &Dataset, request: &str, job: &str) -> Result<(Vec<std::path::PathBuf>, String)> {
    let bad =
        |what: &str, e: serde_json::Error| Error::Usage(format!("GEDI ingest: a {what} gedisim cannot read: {e}"));
    let opts: GediOptions = serde_json::from_str(request).map_err(|e| bad("request", e))?;
    let job: GranuleJob = serde_json::from_str(job).map_err(|e| bad("granule job", e))?;
    let (staged, beams) = write_granule_shots(&dataset.root().join(tables::SHOTS), &job, &opts, 1, &|_| Ok(()))?;
    serde_json::to_string(&beams).map(|r| (vec![staged.clone()], r)).map_err(|e| {
        let _ = std::fs::remove_file(&staged);
        Error::table(&staged, e)
    })
}

/// Claim the staged shots of one granule (a shot number held by another granule or beam is refused,
/// as in a local ingest), then commit it with this process's paths in its beam reports.
fn check_and_commit(
    job: &GranuleJob,
    g: Ingested,
    owners: &ShotOwners,
    commit: &Commit,
) -> Result<(GranuleOutcome, Vec<BeamReport>)> {
    let checked = (|| {
        let [staged] = g.staged.as_slice() else {
            return Err(Error::Usage(format!(
                "GEDI ingest on the cluster: granule {} came back without its shots",
                job.key
            )));
        };
        let owner: Arc<str> = Arc::from(job.key.as_str());
        crate::dataset::read::for_each_batch(staged, Some(&[col::SHOT_NUMBER, col::BEAM]), None, |c| {
            owners.claim(&job.pair, &owner, c.batch())
        })?;
        let beams: Vec<BeamReport> = serde_json::from_str(&g.report).map_err(|e| Error::field(staged, "report", e))?;
        Ok((staged, beams))
    })();
    let (staged, mut beams) = checked.inspect_err(|_| g.discard())?;
    for b in &mut beams {
        b.l1b_file = job.pair.l1b.clone();
        b.l2a_file = job.pair.l2a.clone();
    }
    let outcome = commit(job, staged, &beams)?;
    Ok((outcome, beams))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernels::geo::area::ShotArea;
    use crate::ops::ingest_gedi::GranulePair;

    /// What the plan carries (the request and a job, JSON) comes back bit for bit on an executor,
    /// with the granule files by absolute path.
    #[test]
    fn a_job_and_its_request_travel_by_absolute_path_and_bit_for_bit() {
        let dir = tempfile::tempdir().unwrap();
        let l1b = dir.path().join("GEDI01_B_x.h5");
        std::fs::write(&l1b, b"").unwrap();
        std::fs::create_dir(dir.path().join("sub")).unwrap();
        let roundabout = dir.path().join("sub").join("..").join("GEDI01_B_x.h5");
        let job = GranuleJob {
            pair: GranulePair { granule: "GEDI01_B_x".into(), l1b: Some(roundabout), l2a: None },
            key: "k1".into(),
            l1b_hash: Some("sampled:ab".into()),
            l2a_hash: None,
        };
        let awkward = [0.1 + 0.2, 1.0 / 3.0, 652_000.123_456_789_1, -1e-300];
        let opts = GediOptions {
            epsg: 2154,
            geoid_offset: Some(0.1 + 0.2),
            strict_join: true,
            area: ShotArea::Tiles { extents: vec![awkward], margin_m: 28.400_000_000_000_002 },
        };
        let sent = serde_json::to_string(&shared(&job).unwrap()).unwrap();
        let back: GranuleJob = serde_json::from_str(&sent).unwrap();
        assert_eq!(back.pair.l1b.as_deref(), Some(l1b.canonicalize().unwrap().as_path()));
        assert_eq!((back.key.as_str(), &back.l1b_hash), ("k1", &job.l1b_hash));
        let back: GediOptions = serde_json::from_str(&serde_json::to_string(&opts).unwrap()).unwrap();
        let ShotArea::Tiles { extents, margin_m } = &back.area else { panic!("area lost") };
        assert_eq!(extents[0].map(f64::to_bits), awkward.map(f64::to_bits));
        assert_eq!(margin_m.to_bits(), 28.400_000_000_000_002f64.to_bits());
        assert_eq!(back.geoid_offset.map(f64::to_bits), opts.geoid_offset.map(f64::to_bits));
        // A file that is not there is one line naming it, before anything is sent.
        let gone = GranuleJob { pair: GranulePair { l1b: Some(dir.path().join("gone.h5")), ..job.pair }, ..job };
        assert!(shared(&gone).unwrap_err().to_string().contains("gone.h5"));
    }
}
