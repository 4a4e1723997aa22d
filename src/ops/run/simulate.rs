//! Compute: the covered shots of every granule whose simulation is not current, here or on a
//! cluster, into `sim/<granule key>.parquet`.

use std::collections::HashMap;

use super::plan::{GranulePlan, StudyInputs};
use super::META_INPUT;
use crate::dataset::sim::{sim_metadata, sim_schema};
use crate::dataset::{self, Dataset};
use crate::error::Result;
use crate::kernels::sim::Profile;
use crate::ops::progress::{Progress, Step};
use crate::ops::simulate::{simulate_groups, status_counts};
use crate::sql::Engine;

/// Simulate the covered shots of every granule whose simulation is not current.
pub(super) fn simulate(
    ds: &Dataset,
    plans: &mut [GranulePlan],
    inputs: &StudyInputs,
    progress: &dyn Progress,
) -> Result<()> {
    let total: usize = plans.iter().filter(|p| p.needs_sim).map(|p| p.covered.len()).sum();
    if total == 0 {
        return Ok(());
    }
    progress.start(Step::Simulate, total as u64);
    for p in plans.iter_mut().filter(|p| p.needs_sim) {
        let footprints = p.covered.iter().map(|c| (c.footprint.clone(), c.offset.clone())).collect();
        let extra = HashMap::from([(META_INPUT.to_string(), p.sim_input.clone())]);
        let r = crate::ops::simulate::simulate_on_dataset_with(
            ds,
            footprints,
            &inputs.cfg,
            Profile::Default,
            &p.sim_path,
            &extra,
            progress,
        );
        if r.is_err() {
            progress.finish();
        }
        p.run.simulated = Some(r?);
    }
    progress.finish();
    Ok(())
}

/// Footprints per job a cluster run submits: the client holds one job's rows at a time.
pub(super) const CLUSTER_JOB_FOOTPRINTS: usize = 20_000;

/// [`simulate`] as plans on `engine`: each job covers whole granules, each of its partitions a run of
/// one granule's blocks ([`crate::ops::simulate::simulate_groups`]); every `sim/` file gets the rows
/// and metadata a local run writes.
pub(super) fn simulate_on(
    engine: &Engine,
    ds: &Dataset,
    plans: &mut [GranulePlan],
    progress: &dyn Progress,
) -> Result<()> {
    let total: usize = plans.iter().filter(|p| p.needs_sim).map(|p| p.covered.len()).sum();
    if total == 0 {
        return Ok(());
    }
    progress.start(Step::Simulate, total as u64);
    let rt = crate::sql::runtime()?;
    let r = rt.block_on(async {
        let ctx = crate::sql::session_on(ds, &Default::default(), engine).await?;
        // Jobs of whole granules, each closed once it holds CLUSTER_JOB_FOOTPRINTS footprints.
        let mut jobs: Vec<(usize, Vec<&mut GranulePlan>)> = Vec::new();
        for p in plans.iter_mut().filter(|p| p.needs_sim) {
            match jobs.last_mut() {
                Some((size, job)) if *size < CLUSTER_JOB_FOOTPRINTS => {
                    *size += p.covered.len();
                    job.push(p);
                }
                _ => jobs.push((p.covered.len(), vec![p])),
            }
        }
        for (_, job) in jobs {
            let groups =
                job.iter().map(|p| p.covered.iter().map(|c| (c.footprint.clone(), c.offset.clone())).collect());
            let batches = simulate_groups(&ctx, ds, groups.collect(), Profile::Default).await?;
            for (p, batch) in job.into_iter().zip(batches) {
                let mut metadata = sim_metadata(Profile::Default);
                metadata.insert(META_INPUT.to_string(), p.sim_input.clone());
                dataset::write_parquet(&p.sim_path, sim_schema(), std::slice::from_ref(&batch), &metadata)?;
                let (ok, skipped) = status_counts(&p.sim_path, &batch)?;
                p.run.simulated = Some((ok, skipped));
                progress.advance((ok + skipped) as u64);
            }
        }
        Ok(())
    });
    progress.finish();
    r
}
