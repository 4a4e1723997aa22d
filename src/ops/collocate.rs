//! `collocate`: granules of a dataset's `shots/` collocated ([`crate::sql::collocation`]), here or
//! as one plan on a cluster (a partition per granule, [`crate::sql::collocate`]), into
//! `<dataset>/offsets/offsets.parquet`. Each run of `gedisim collocate` replaces the table (the level
//! is in every row); `gedisim run` merges the granules it collocates into it.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;

use arrow::array::RecordBatch;
use futures::StreamExt;

use crate::dataset::offsets::{offsets_batch, offsets_metadata, offsets_schema};
use crate::dataset::{self, tables, Dataset};
use crate::error::{Error, Result};
use crate::ops::progress::{Progress, Step};
use crate::sql::collocate::{granule_results, shots_file_name, CollocatedGranules};
pub use crate::sql::collocation::{CollocateOptions, CollocateReport, Collocation};
pub use crate::sql::Engine;

/// `gedisim collocate`: every granule of the dataset collocated here and written to `offsets/`.
pub fn collocate(ds: &Dataset, opts: &CollocateOptions, progress: &dyn Progress) -> Result<CollocateReport> {
    collocate_on(&Engine::Local, ds, opts, progress)
}

/// [`collocate`] on `engine`.
pub fn collocate_on(
    engine: &Engine,
    ds: &Dataset,
    opts: &CollocateOptions,
    progress: &dyn Progress,
) -> Result<CollocateReport> {
    let ds = &ds.as_writer()?;
    let (batches, mut report) = solve(engine, Collocation::plan(ds, opts)?, ds, opts, progress)?;
    let dest = ds.table_file(tables::OFFSETS, "offsets")?;
    let metadata = offsets_metadata(opts.level.name(), opts.max_shift, opts.step);
    dataset::write_parquet(&dest, offsets_schema(), &batches, &metadata)?;
    report.table = dest;
    Ok(report)
}

/// The offset rows (granule after granule, in the order of `files`) and the report of the granules of
/// `files` (files of `shots/`), collocated on `engine`, as one [`Step::Collocate`] counting the shots
/// correlated. The same rows and report on either engine.
pub fn solve_granules(
    engine: &Engine,
    ds: &Dataset,
    opts: &CollocateOptions,
    files: Vec<PathBuf>,
    progress: &dyn Progress,
) -> Result<(Vec<RecordBatch>, CollocateReport)> {
    solve(engine, Collocation::plan_files(ds, opts, files)?, ds, opts, progress)
}

/// Pass B of `plan` on `engine`. Pass A was done here in either case: it checked the options and gives
/// the progress its total.
fn solve(
    engine: &Engine,
    plan: Collocation,
    ds: &Dataset,
    opts: &CollocateOptions,
    progress: &dyn Progress,
) -> Result<(Vec<RecordBatch>, CollocateReport)> {
    progress.start(Step::Collocate, plan.shots_to_process() as u64);
    let solved = match engine {
        Engine::Local => {
            plan.solve(&|| progress.advance(1)).and_then(|(rows, report)| Ok((vec![offsets_batch(&rows)?], report)))
        }
        Engine::Cluster(_) => solve_on_cluster(engine, ds, opts, &plan.files(), progress),
    };
    progress.finish();
    solved
}

/// [`solve_granules`] as one plan on a cluster, a partition per granule.
fn solve_on_cluster(
    engine: &Engine,
    ds: &Dataset,
    opts: &CollocateOptions,
    files: &[PathBuf],
    progress: &dyn Progress,
) -> Result<(Vec<RecordBatch>, CollocateReport)> {
    let names = files.iter().map(|f| shots_file_name(f)).collect::<Result<Vec<_>>>()?;
    let mut report =
        CollocateReport { table: ds.root().join(tables::OFFSETS).join("offsets.parquet"), ..Default::default() };
    if names.is_empty() {
        return Ok((Vec::new(), report));
    }
    let failed = |e: datafusion::error::DataFusionError| {
        Error::Usage(format!("collocation on the cluster: {}", crate::error::one_line(&e.to_string())))
    };
    let mut done = HashMap::new();
    crate::sql::runtime()?.block_on(async {
        let ctx = crate::sql::session_on(ds, &Default::default(), engine).await?;
        let granules = CollocatedGranules::new(ds.clone(), opts.clone(), names.clone());
        let mut stream = ctx.read_table(Arc::new(granules)).map_err(failed)?.execute_stream().await.map_err(failed)?;
        while let Some(batch) = stream.next().await {
            for g in granule_results(ds.root(), &batch.map_err(failed)?)? {
                progress.advance(g.shots_correlated);
                done.insert(g.file.clone(), g);
            }
        }
        Ok::<_, Error>(())
    })?;
    let mut batches = Vec::new();
    for name in names {
        let g = done
            .remove(&name)
            .ok_or_else(|| Error::Usage(format!("collocation on the cluster: granule {name} did not come back")))?;
        report.merge(g.report);
        batches.extend(g.offsets);
    }
    Ok((batches, report))
}
