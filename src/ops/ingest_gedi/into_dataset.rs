//! Into a dataset: each granule pair's shots written as one `shots/` file with its `granules/`
//! record, skipped when its inputs are unchanged, replacing an earlier version of it.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow::array::RecordBatch;
use rayon::prelude::*;

use super::join::ShotOwners;
use super::pairs::{expand_granule_inputs, pair_granules};
use super::{granule_key, read_granule};
use super::{BeamPart, BeamReport, GediOptions, GranulePair, IngestReport, ShotChoice};
use crate::dataset::shots::{self, granules_col, granules_schema, shots_schema, VERTICAL_DATUM};
use crate::error::{Error, Result};
use crate::kernels::geo::area::ShotArea;
use crate::ops::progress::{Progress, Step};

/// What happened to one granule in [`ingest_into_dataset`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum GranuleOutcome {
    /// Shots written (replacing an earlier version of the granule, if any).
    Ingested { granule: String, shots: usize },
    /// The same files (by content hash) were ingested before.
    AlreadyIngested { granule: String },
}

/// What `gedisim ingest gedi` (and `run`) is asked beyond the files.
#[derive(Debug, Clone, Default)]
pub struct IngestRequest {
    /// Projected CRS of `x`, `y` (`None`: the dataset's ALS CRS, else [`DEFAULT_EPSG`], said in a note).
    pub epsg: Option<u32>,
    /// Geoid offset N (m) for every shot instead of each shot's L1B geoid.
    pub geoid_offset: Option<f64>,
    /// Fail on a shot in only one of a paired L1B/L2A.
    pub strict_join: bool,
    /// The shots kept.
    pub shots: ShotChoice,
    /// ALS files about to be ingested (`run`): their header extents join the dataset's coverage.
    pub als_inputs: Vec<PathBuf>,
    /// Margin (m) around each tile extent: the collocation's search and the footprint's reach
    /// ([`crate::ops::ingest_als::run_window_half`]).
    pub margin_m: f64,
    /// Where granules are read: here, or a partition each on a cluster (`run --cluster`).
    pub engine: crate::sql::Engine,
}

/// `gedisim ingest gedi`: the granules of `l1b` and `l2a` (files, or folders expanded) into
/// `dataset`, the shots of `request.shots` kept, as one [`Step::IngestGedi`] counted in granules.
pub fn ingest(
    dataset: &crate::dataset::Dataset,
    l1b: &[PathBuf],
    l2a: &[PathBuf],
    request: &IngestRequest,
    progress: &dyn Progress,
) -> Result<(Vec<GranuleOutcome>, IngestReport)> {
    let dataset = &dataset.as_writer()?;
    let l1b = expand_granule_inputs(l1b, "GEDI01_B")?;
    let l2a = expand_granule_inputs(l2a, "GEDI02_A")?;
    if l1b.is_empty() && l2a.is_empty() {
        return Err(Error::Usage("--l1b/--l2a: no GEDI01_B or GEDI02_A .h5 file found in the inputs".into()));
    }
    let existing = crate::dataset::dataset_epsg(dataset)?;
    let (given, had_crs) = (request.epsg.is_some(), existing.is_some());
    let epsg = match (request.epsg, existing) {
        (Some(given), Some(ds)) if given != ds => {
            return Err(Error::field(
                dataset.root(),
                "CRS",
                format!("--epsg {given} differs from the dataset's EPSG:{ds} (one CRS per dataset)"),
            ))
        }
        (Some(e), _) | (None, Some(e)) => e,
        (None, None) => DEFAULT_EPSG,
    };
    let (area, called) = request.shots.area(dataset, &request.als_inputs, request.margin_m)?;
    let opts = GediOptions { epsg, geoid_offset: request.geoid_offset, strict_join: request.strict_join, area };
    progress.start(Step::IngestGedi, pair_granules(&l1b, &l2a)?.0.len() as u64);
    let r = ingest_into_dataset(dataset, &l1b, &l2a, &opts, &request.engine, progress);
    progress.finish();
    let (outcomes, mut report) = r?;
    if let Some(called) = called {
        report.area = called;
    }
    if !given && !had_crs {
        // Never a silent default: the shots took a CRS nobody named.
        report.notes.push(format!(
            "shots projected to EPSG:{DEFAULT_EPSG} (Lambert-93, LiDAR HD's): neither --epsg nor ALS tiles in the \
             dataset name a CRS; the dataset's tiles must be in it too"
        ));
    }
    Ok((outcomes, report))
}

/// The CRS of the shots' x, y when neither `--epsg` nor the dataset's tiles name one.
pub const DEFAULT_EPSG: u32 = 2154;

/// Ingest L1B/L2A files into `<dataset>/shots/` (one file per granule, `<granule_key>.parquet`)
/// and `<dataset>/granules/`. A granule whose files have the same content hashes as at its last
/// ingest is skipped; one whose files changed (e.g. its L2A arrived later) is rewritten.
/// Granules are read in parallel here, or a partition each on a cluster (`engine`: each executor
/// writes a granule's shots under a temporary name, this process checks and commits them);
/// `progress` advances by one after each.
pub fn ingest_into_dataset(
    dataset: &crate::dataset::Dataset,
    l1b: &[PathBuf],
    l2a: &[PathBuf],
    opts: &GediOptions,
    engine: &crate::sql::Engine,
    progress: &dyn Progress,
) -> Result<(Vec<GranuleOutcome>, IngestReport)> {
    use crate::dataset::{self, tables};

    let dataset = &dataset.as_writer()?;
    let (pairs, notes) = pair_granules(l1b, l2a)?;
    let shots_dir = dataset.table_dir(tables::SHOTS)?;
    let granules_dir = dataset.table_dir(tables::GRANULES)?;
    // Content first: copies of a granule under other names are found before anything is written.
    let hash = |p: &Option<PathBuf>| p.as_deref().map(dataset::granule_hash).transpose();
    let keyed = pairs
        .par_iter()
        .map(|pair| {
            let key = granule_key(pair.l1b.as_deref().or(pair.l2a.as_deref()).expect("a pair has a file"));
            Ok((key, hash(&pair.l1b)?, hash(&pair.l2a)?))
        })
        .collect::<Result<Vec<_>>>()?;
    // What each granule's record says, read once: (L1B hash, L2A hash) by granule key.
    let (mut recorded, mut recorded_area) = (HashMap::new(), HashMap::new());
    for record in dataset::table_files(&granules_dir).map_err(|e| Error::file(&granules_dir, e))? {
        let key = record.file_stem().and_then(|s| s.to_str()).unwrap_or_default().to_string();
        if let Some((hashes, area)) = previous_record(&record)? {
            recorded.insert(key.clone(), hashes);
            recorded_area.insert(key, area);
        }
    }
    let duplicate = copies_of_other_granules(&pairs, &keyed, &recorded)?;
    // Each pair skipped (already ingested) or a job to read.
    let mut outcomes: Vec<Option<GranuleOutcome>> = Vec::with_capacity(pairs.len());
    let mut jobs = Vec::new();
    for ((pair, (key, h1, h2)), duplicate) in pairs.into_iter().zip(keyed).zip(duplicate) {
        let previous = recorded.get(&key).cloned();
        // A side the granule had and this call lacks would be lost by a rewrite: unchanged
        // given sides are nothing new; changed ones need both files.
        let same = |new: &Option<String>, old: &Option<String>| new.is_none() || new == old;
        let mut skip = duplicate;
        if let Some((p1, p2)) = &previous {
            if (p1.is_some() && h1.is_none()) || (p2.is_some() && h2.is_none()) {
                if !(same(&h1, p1) && same(&h2, p2)) {
                    let (given, missing) = if h1.is_none() { ("L2A", "L1B") } else { ("L1B", "L2A") };
                    let file = pair.l1b.as_ref().or(pair.l2a.as_ref()).expect("a pair has a file");
                    return Err(Error::file(
                        file,
                        format!(
                            "a changed {given} of granule {key}, which the dataset holds with its {missing}: \
                             give both files to replace it"
                        ),
                    ));
                }
                skip = true;
            }
        }
        // Read again with another area; but a granule read whole holds every shot the default
        // (the tiles' coverage) asks for.
        let area_read = recorded_area.get(&key).map(String::as_str);
        let whole_for_tiles = matches!(opts.area, ShotArea::Tiles { .. }) && area_read == Some("all");
        let same_area = area_read == Some(opts.area.key().as_str()) || whole_for_tiles;
        if skip || (previous == Some((h1.clone(), h2.clone())) && same_area) {
            progress.advance(1);
            outcomes.push(Some(GranuleOutcome::AlreadyIngested { granule: pair.granule.clone() }));
        } else {
            outcomes.push(None);
            jobs.push(GranuleJob { pair, key, l1b_hash: h1, l2a_hash: h2 });
        }
    }
    let owners = ShotOwners::read(&shots_dir)?;
    let commit = |job: &GranuleJob, staged: &Path, beams: &[BeamReport]| -> Result<GranuleOutcome> {
        commit_granule(&shots_dir, &granules_dir, job, staged, beams, opts)
    };
    let read: Vec<(GranuleOutcome, Vec<BeamReport>)> = match engine {
        crate::sql::Engine::Local => jobs
            .par_iter()
            .map(|job| {
                let owner: Arc<str> = Arc::from(job.key.as_str());
                let (staged, beams) =
                    write_granule_shots(&shots_dir, job, opts, jobs.len(), &|b| owners.claim(&job.pair, &owner, b))?;
                let outcome = commit(job, &staged, &beams)?;
                progress.advance(1);
                Ok((outcome, beams))
            })
            .collect::<Result<_>>()?,
        crate::sql::Engine::Cluster(_) => {
            super::on_cluster::ingest_granules(engine, dataset, &jobs, opts, &owners, &commit, progress)?
        }
    };
    let mut report = IngestReport { beams: Vec::new(), notes, area: opts.area.describe() };
    let mut read = read.into_iter();
    let outcomes = outcomes
        .into_iter()
        .map(|o| {
            o.unwrap_or_else(|| {
                let (outcome, beams) = read.next().expect("one result per job");
                report.beams.extend(beams);
                outcome
            })
        })
        .collect();
    Ok((outcomes, report))
}

/// A granule an ingest reads: its files, key and content hashes.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GranuleJob {
    pub pair: GranulePair,
    pub key: String,
    pub l1b_hash: Option<String>,
    pub l2a_hash: Option<String>,
}

/// The shots of `job` read (while `at_once` granules are read together: [`BeamPart::parts_for`])
/// and written beside `shots/<key>.parquet` under a temporary name (complete, synced, not yet in
/// place: [`commit_granule`] puts it there), each batch given to `check` before it is written.
/// What a local ingest does per granule, and a cluster's executor.
pub fn write_granule_shots(
    shots_dir: &Path,
    job: &GranuleJob,
    opts: &GediOptions,
    at_once: usize,
    check: &(dyn Fn(&RecordBatch) -> Result<()> + Sync),
) -> Result<(PathBuf, Vec<BeamReport>)> {
    let props = crate::dataset::writer_properties(&shots_metadata(opts), 1 << 16);
    let dest = shots_dir.join(format!("{}.parquet", job.key));
    let mut writer = crate::dataset::AtomicParquet::create(&dest, shots_schema(opts.epsg), props)?;
    let beams = read_granule(&job.pair, opts, BeamPart::parts_for(&job.pair, at_once), &mut |b| {
        check(&b)?;
        writer.write(&b)
    })?;
    Ok((writer.finish_staged()?, beams))
}

/// The key-value metadata of a `shots/` file.
fn shots_metadata(opts: &GediOptions) -> HashMap<String, String> {
    HashMap::from([
        (shots::meta::EPSG.to_string(), opts.epsg.to_string()),
        (shots::meta::VERTICAL.to_string(), VERTICAL_DATUM.to_string()),
    ])
}

/// Put a granule's shots, written at `staged` by [`write_granule_shots`], in place as
/// `shots/<key>.parquet`, then write its record `granules/<key>.parquet`.
fn commit_granule(
    shots_dir: &Path,
    granules_dir: &Path,
    job: &GranuleJob,
    staged: &Path,
    beams: &[BeamReport],
    opts: &GediOptions,
) -> Result<GranuleOutcome> {
    use arrow::array::{StringArray, UInt64Array};
    let (pair, key) = (&job.pair, &job.key);
    crate::dataset::place_staged(staged, &shots_dir.join(format!("{key}.parquet")))?;
    let record = granules_dir.join(format!("{key}.parquet"));
    let shots: usize = beams.iter().map(BeamReport::rows).sum();
    let path = |p: &Option<PathBuf>| p.as_ref().map(|p| p.display().to_string());
    let cols: Vec<arrow::array::ArrayRef> = vec![
        Arc::new(StringArray::from(vec![pair.granule.clone()])),
        Arc::new(StringArray::from(vec![key.clone()])),
        Arc::new(StringArray::from(vec![path(&pair.l1b)])),
        Arc::new(StringArray::from(vec![job.l1b_hash.clone()])),
        Arc::new(StringArray::from(vec![path(&pair.l2a)])),
        Arc::new(StringArray::from(vec![job.l2a_hash.clone()])),
        Arc::new(UInt64Array::from(vec![shots as u64])),
        Arc::new(StringArray::from(vec![opts.area.key()])),
        Arc::new(UInt64Array::from(vec![beams.iter().map(|b| b.outside_area as u64).sum::<u64>()])),
    ];
    let batch = RecordBatch::try_new(granules_schema(), cols).map_err(|e| Error::table(&record, e))?;
    crate::dataset::write_parquet(&record, granules_schema(), &[batch], &shots_metadata(opts))?;
    Ok(GranuleOutcome::Ingested { granule: pair.granule.clone(), shots })
}

/// The content hashes of a granule's L1B and L2A files (either may be absent).
pub(super) type Hashes = (Option<String>, Option<String>);

/// A pair's granule key and the content hashes of its L1B and L2A files.
pub(super) type Keyed = (String, Option<String>, Option<String>);

/// Which pairs are copies of granules the dataset (or an earlier pair of the call) already holds
/// under another key: a file's content belongs to one granule key, whatever the file is called, so
/// a renamed copy must not double the shots. A copy paired with other files is an error.
pub(super) fn copies_of_other_granules(
    pairs: &[GranulePair],
    keyed: &[Keyed],
    recorded: &HashMap<String, Hashes>,
) -> Result<Vec<bool>> {
    // content hash → granule key
    let mut owner: HashMap<String, String> = recorded
        .iter()
        .flat_map(|(key, (h1, h2))| [h1, h2].into_iter().flatten().map(move |h| (h.clone(), key.clone())))
        .collect();
    let mut duplicate = vec![false; pairs.len()];
    for (i, ((key, h1, h2), pair)) in keyed.iter().zip(pairs).enumerate() {
        let present: Vec<(&String, &PathBuf)> = [(h1, &pair.l1b), (h2, &pair.l2a)]
            .into_iter()
            .filter_map(|(h, f)| Some((h.as_ref()?, f.as_ref()?)))
            .collect();
        let others: Vec<&String> = present.iter().filter_map(|(h, _)| owner.get(*h)).filter(|o| *o != key).collect();
        match others.first() {
            None => owner.extend(present.iter().map(|(h, _)| ((*h).clone(), key.clone()))),
            // Every file is a copy of the same other granule: nothing new.
            Some(other) if others.len() == present.len() && others.iter().all(|o| o == other) => duplicate[i] = true,
            Some(other) => {
                let file = present.iter().find(|(h, _)| owner.get(*h) == Some(*other)).map(|(_, f)| *f).expect("owned");
                return Err(Error::file(
                    file,
                    format!(
                        "same content as granule {other} of the dataset, paired here with other files: \
                         ingest it under its original name to replace that granule"
                    ),
                ));
            }
        }
    }
    Ok(duplicate)
}

/// What an earlier ingest of a granule recorded (its `granules/<key>.parquet`), if anything: the
/// (L1B, L2A) content hashes and the [`ShotArea::key`] its shots were kept by (`all` in a record
/// written before areas, when every shot was kept).
pub fn previous_record(record: &Path) -> Result<Option<(Hashes, String)>> {
    if !record.exists() {
        return Ok(None);
    }
    let mut out = None;
    crate::dataset::read::for_each_batch(record, None, None, |c| {
        if out.is_none() && c.num_rows() > 0 {
            let has_area = c.batch().schema().column_with_name(granules_col::SHOT_AREA).is_some();
            let area = if has_area { c.string(granules_col::SHOT_AREA, 0)? } else { None };
            let hashes = (c.string(granules_col::L1B_HASH, 0)?, c.string(granules_col::L2A_HASH, 0)?);
            out = Some((hashes, area.unwrap_or_else(|| ShotArea::All.key())));
        }
        Ok(())
    })?;
    Ok(out)
}
