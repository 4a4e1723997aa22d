//! The ALS ingest on a cluster (`run --cluster`, `ingest als --cluster`): the tiles to read as one
//! plan, a partition per tile ([`crate::sql::ingest::IngestExec`]). Each executor keys its tile by
//! content, reads it — a COPC tile only in the cells its windows meet, which this process drew from
//! the tile's header — and writes its `als/` file and `tiles/` row under temporary names
//! ([`stage_from_json`], which executors run: `ops::cluster` installs it). This process only plans
//! and commits: it puts each tile's files in place in the input order; a tile whose content an
//! earlier tile of the call committed is discarded as ingested, as a local ingest skips it. Every
//! node must see the tiles (or their URLs) and the dataset at the same paths (docs/scale.md).

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::{content_key, stage_tile, AlsOptions, StagedTile, Target, TileOutcome};
use crate::dataset::als::MAX_WINDOW_CELLS;
use crate::dataset::{tables, Dataset};
use crate::error::{Error, Result};
use crate::io::las::TileHeader;
use crate::kernels::geo::cells::Cells;
use crate::ops::progress::{NoProgress, Progress};
use crate::sql::ingest::{run_ingest, Ingest, IngestKind, Ingested};

/// A tile an executor reads.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(super) struct TileJob {
    /// Where every node reads it: its absolute path, or its URL.
    path: PathBuf,
    /// As it was given (its name, and its `tiles/` row's `path`).
    given: PathBuf,
    epsg: u32,
    /// The cells of a COPC tile read in windows ([`Cells::to_text`]); `None`: the whole tile.
    cells: Option<String>,
    /// Its points (the progress).
    points: u64,
}

/// What every tile is read with.
#[derive(Serialize, Deserialize)]
struct TileRequest {
    keep_all_classes: bool,
}

/// The jobs of `files`, their headers, CRSs and wanted cells (files by absolute path or URL).
pub(super) fn jobs(
    files: &[PathBuf],
    headers: &[TileHeader],
    epsgs: &[u32],
    wanted: &[Option<Cells>],
) -> Result<Vec<TileJob>> {
    (0..files.len())
        .map(|i| {
            let f = &files[i];
            let path = match crate::io::source::remote(f)? {
                Some(_) => f.clone(),
                None => f.canonicalize().map_err(|e| Error::file(f, format!("cannot open: {e}")))?,
            };
            Ok(TileJob {
                path,
                given: f.clone(),
                epsg: epsgs[i],
                cells: wanted[i].as_ref().map(Cells::to_text),
                points: headers[i].number_of_points,
            })
        })
        .collect()
}

/// Read `jobs` on the cluster of `opts.engine` (`progress` advanced by a tile's points as it comes
/// back), then commit each in order; one outcome per job.
pub(super) fn ingest_tiles(
    dataset: &Dataset,
    jobs: &[TileJob],
    opts: &AlsOptions,
    progress: &dyn Progress,
) -> Result<Vec<TileOutcome>> {
    let json = |e: serde_json::Error| Error::file(dataset.root(), format!("a request gedisim cannot send: {e}"));
    let request = serde_json::to_string(&TileRequest { keep_all_classes: opts.keep_all_classes }).map_err(json)?;
    let wire_jobs = jobs
        .iter()
        .enumerate()
        .map(|(i, j)| Ok((i.to_string(), serde_json::to_string(j).map_err(json)?)))
        .collect::<Result<Vec<_>>>()?;
    let points = |row: &Ingested| row.key.parse::<usize>().ok().and_then(|i| jobs.get(i)).map_or(0, |j| j.points);
    let ingest = Ingest::new(IngestKind::Tiles, dataset.clone(), request, wire_jobs);
    let mut rows = run_ingest(&opts.engine, ingest, &|row| progress.advance(points(row)))?;
    let places = [dataset.root().join(tables::ALS), dataset.root().join(tables::TILES)];
    let mut committed: HashSet<PathBuf> = HashSet::new();
    let outcomes = (0..jobs.len())
        .map(|i| {
            let row = rows.remove(&i.to_string()).ok_or_else(|| {
                Error::Usage(format!("ALS ingest on the cluster: tile {} did not come back", jobs[i].given.display()))
            })?;
            let staged = staged_tile(&row, &places).inspect_err(|_| row.discard())?;
            if staged.files.iter().any(|(_, dest)| committed.contains(dest)) {
                // A copy of a tile committed just before: nothing new.
                staged.discard();
                return Ok(TileOutcome::AlreadyIngested { tile: super::tile_name(&jobs[i].given) });
            }
            committed.extend(staged.files.iter().map(|(_, dest)| dest.clone()));
            staged.commit()
        })
        .collect::<Result<Vec<_>>>();
    // A failure leaves nothing staged behind.
    rows.values().for_each(Ingested::discard);
    outcomes
}

/// The staged tile a row reports: files the row staged, each going into one of `places`.
fn staged_tile(row: &Ingested, places: &[PathBuf]) -> Result<StagedTile> {
    let staged: StagedTile =
        serde_json::from_str(&row.report).map_err(|e| Error::Usage(format!("ALS ingest on the cluster: {e}")))?;
    for (file, dest) in &staged.files {
        let in_place = dest.parent().is_some_and(|d| places.iter().any(|p| p == d));
        if !row.staged.contains(file) || !in_place || file.parent() != dest.parent() {
            return Err(Error::file(dest, "ALS ingest on the cluster: a tile's files outside the dataset's tables"));
        }
    }
    Ok(staged)
}

/// What a partition of the ingest runs (`sql::ingest`): the tile of `job` (JSON of a [`TileJob`])
/// read with `request` into the dataset's `als/` and `tiles/` under temporary names; its
/// [`StagedTile`] as JSON.
pub fn stage_from_json(dataset: &Dataset, request: &str, job: &str) -> Result<(Vec<PathBuf>, String)> {
    let bad = |what: &str, e: serde_json::Error| Error::Usage(format!("ALS ingest: a {what} gedisim cannot read: {e}"));
    let request: TileRequest = serde_json::from_str(request).map_err(|e| bad("request", e))?;
    let job: TileJob = serde_json::from_str(job).map_err(|e| bad("tile job", e))?;
    let wanted = job
        .cells
        .as_deref()
        .map(|text| {
            Cells::parse(text, MAX_WINDOW_CELLS).ok_or_else(|| Error::field(&job.path, "cells", "not a list of cells"))
        })
        .transpose()?;
    let hash = content_key(&job.path)?;
    let (als_dir, tiles_dir) = (dataset.root().join(tables::ALS), dataset.root().join(tables::TILES));
    let target = Target {
        path: &job.path,
        given: &job.given,
        hash: &hash,
        als_dir: &als_dir,
        tiles_dir: &tiles_dir,
        epsg: job.epsg,
    };
    let opts = AlsOptions { keep_all_classes: request.keep_all_classes, ..Default::default() };
    let staged = stage_tile(&target, &opts, wanted.as_ref(), true, &NoProgress)?;
    let files: Vec<PathBuf> = staged.files.iter().map(|(file, _)| file.clone()).collect();
    serde_json::to_string(&staged).map(|report| (files, report)).map_err(|e| {
        staged.discard();
        Error::file(Path::new(&job.given), format!("ALS ingest: {e}"))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What the plan carries comes back as sent, the tile by absolute path and as given, its cells
    /// whole; a file that is not there is one line naming it, before anything is sent.
    #[test]
    fn a_tile_job_travels_by_absolute_path_with_its_cells() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("sub")).unwrap();
        let tile = dir.path().join("t.copc.laz");
        std::fs::write(&tile, b"").unwrap();
        let given = dir.path().join("sub").join("..").join("t.copc.laz");
        let header = |n| TileHeader {
            path: PathBuf::new(),
            version: "1.4".into(),
            point_format: 6,
            compressed: true,
            number_of_points: n,
            bounds: [0.0; 6],
            epsg: None,
            crs_wkt: None,
            extra_bytes: Vec::new(),
            n_evlrs: 0,
            copc: true,
        };
        let cells = Cells::around([(652_001.5, 6_862_010.25), (-3.0, 12.0)], 28.4);
        let jobs = jobs(std::slice::from_ref(&given), &[header(7)], &[2154], &[Some(cells.clone())]).unwrap();
        let back: TileJob = serde_json::from_str(&serde_json::to_string(&jobs[0]).unwrap()).unwrap();
        assert_eq!(back.path, tile.canonicalize().unwrap());
        assert_eq!((back.given, back.epsg, back.points), (given, 2154, 7));
        assert_eq!(Cells::parse(back.cells.as_deref().unwrap(), MAX_WINDOW_CELLS), Some(cells));
        let gone = dir.path().join("gone.laz");
        let err = super::jobs(&[gone], &[header(0)], &[2154], &[None]).unwrap_err();
        assert!(err.to_string().contains("gone.laz"), "{err}");
    }
}
