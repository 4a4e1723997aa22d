//! GEDI L1B and L2A HDF5 granules (V1 and V2 layouts) into one Arrow table of shots.
//!
//! One row per shot. L1B and L2A are joined on `shot_number` within a beam; a shot present on
//! one side only is **kept** with nulls for the other side's columns and reported (or rejected
//! with [`GediOptions::strict_join`]). Files are read one beam at a time, so memory is bounded by
//! the largest beam, and batches of at most [`BATCH_ROWS`] rows are handed to a sink. The
//! columns, their units and the policies are documented in `docs/schemas.md` ("shots/").
//!
//! Facts relied on (docs/gedi-products.md §1–§3): `shot_number` is uint64 (int64 in some old subsets;
//! never float); `rx_sample_start_index` is **1-based**; L2A `geolocation/rh_aN` is integer
//! centimetres while root `rh` is metres; V1 has no `land_cover_data/leaf_off_flag`.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use arrow::array::{ArrayRef, BooleanArray, Float32Builder, ListBuilder, PrimitiveArray, RecordBatch, StringArray};
use arrow::datatypes::{
    ArrowPrimitiveType, Float64Type, Int16Type, Int8Type, SchemaRef, UInt32Type, UInt64Type, UInt8Type,
};
use rayon::prelude::*;

use crate::dataset::shots::{granules_schema, shots_schema, VERTICAL_DATUM};
use crate::error::{Error, Result};
use crate::io::gedi::{open_product, read_l1b, read_l2a, L1bBeam, L2aBeam, Product};
use crate::kernels::gedi::{BeamType, N_ALGORITHMS, RH_LEN};
use crate::kernels::geo::area::ShotArea;
use crate::kernels::geo::projection::Projector;
use crate::ops::progress::{Progress, Step};

pub mod child;
pub(crate) mod coverage;
mod select;

pub use coverage::ShotChoice;

/// Maximum rows per emitted batch (a beam larger than this is split).
pub const BATCH_ROWS: usize = 8192;

/// Options of the GEDI ingest.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GediOptions {
    /// Target projected CRS of the `x`, `y` columns (default 2154, Lambert-93).
    pub epsg: u32,
    /// Geoid offset N (m, ellipsoid − orthometric) for every shot; `None` uses each shot's L1B
    /// `geophys_corr/geoid`.
    pub geoid_offset: Option<f64>,
    /// Reject (error) a shot present in only one of a paired L1B/L2A granule instead of keeping it.
    pub strict_join: bool,
    /// The shots kept; the others are counted, not read ([`select`]).
    #[serde(default)]
    pub area: ShotArea,
}

impl Default for GediOptions {
    fn default() -> Self {
        GediOptions { epsg: 2154, geoid_offset: None, strict_join: false, area: ShotArea::All }
    }
}

/// One granule to read: an L1B file, an L2A file, or both.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct GranulePair {
    /// The `granule` column: the L1B file stem, or the L2A file stem when there is no L1B file.
    pub granule: String,
    /// The L1B file, if any.
    pub l1b: Option<PathBuf>,
    /// The L2A file, if any.
    pub l2a: Option<PathBuf>,
}

/// Shot counts of one beam of one granule, and the shots found on one side only.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct BeamReport {
    /// The `granule` value.
    pub granule: String,
    /// Beam group name.
    pub beam: String,
    /// L1B file read (if any).
    pub l1b_file: Option<PathBuf>,
    /// L2A file read (if any).
    pub l2a_file: Option<PathBuf>,
    /// Shots in the L1B beam.
    pub l1b_shots: usize,
    /// Shots in the L2A beam.
    pub l2a_shots: usize,
    /// Shots present in both.
    pub joined: usize,
    /// L1B shots without an L2A partner although an L2A file was given.
    pub l1b_only: Vec<u64>,
    /// L2A shots without an L1B partner although an L1B file was given.
    pub l2a_only: Vec<u64>,
    /// L2A shots whose `lat/lon_lowestmode` are not valid coordinates (kept null).
    pub invalid_lowestmode: Vec<u64>,
    /// L1B shots whose `rxwaveform` or `txwaveform` record holds NaN or infinite samples (that
    /// waveform kept null).
    pub non_finite_waveform: Vec<u64>,
    /// Shots left out: outside the ingest's [`ShotArea`] (not read beyond their position).
    pub outside_area: usize,
}

impl BeamReport {
    /// Rows written for this beam.
    pub fn rows(&self) -> usize {
        self.joined + (self.l1b_shots - self.joined) + (self.l2a_shots - self.joined)
    }

    /// One line per anomaly, naming the file, the beam and the shot count.
    pub fn warnings(&self) -> Vec<String> {
        let name = |p: &Option<PathBuf>| p.as_deref().map(|p| p.display().to_string()).unwrap_or_default();
        let mut out = Vec::new();
        if let Some(&first) = self.l1b_only.first() {
            out.push(format!(
                "{}: {}: {} L1B shot(s) have no L2A partner in {} (first {first}); kept with null L2A columns",
                name(&self.l1b_file),
                self.beam,
                self.l1b_only.len(),
                name(&self.l2a_file)
            ));
        }
        if let Some(&first) = self.l2a_only.first() {
            out.push(format!(
                "{}: {}: {} L2A shot(s) have no L1B partner in {} (first {first}); kept with null L1B columns",
                name(&self.l2a_file),
                self.beam,
                self.l2a_only.len(),
                name(&self.l1b_file)
            ));
        }
        if let Some(&first) = self.non_finite_waveform.first() {
            out.push(format!(
                "{}: {}/rxwaveform: {} shot(s) with NaN or infinite samples in rxwaveform or txwaveform \
                 (first {first}); that waveform kept null",
                name(&self.l1b_file),
                self.beam,
                self.non_finite_waveform.len()
            ));
        }
        if let Some(&first) = self.invalid_lowestmode.first() {
            out.push(format!(
                "{}: {}/lat_lowestmode: {} shot(s) with invalid lowest-mode coordinates (first {first}); kept null",
                name(&self.l2a_file),
                self.beam,
                self.invalid_lowestmode.len()
            ));
        }
        out
    }
}

/// What an ingest read: per-beam counts and file-level notes.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct IngestReport {
    /// One entry per (granule, beam), in the order read.
    pub beams: Vec<BeamReport>,
    /// File-level notes, e.g. an L1B file with no L2A partner file.
    pub notes: Vec<String>,
    /// What the shots kept are ([`ShotArea::describe`]).
    pub area: String,
}

impl IngestReport {
    /// Total rows written.
    pub fn rows(&self) -> usize {
        self.beams.iter().map(BeamReport::rows).sum()
    }

    /// Shots left out, outside the area.
    pub fn outside_area(&self) -> usize {
        self.beams.iter().map(|b| b.outside_area).sum()
    }

    /// What was kept and what left out, in one line (`None` when every shot was kept by choice).
    pub fn kept_line(&self) -> Option<String> {
        let (rows, outside, all) = (self.rows(), self.outside_area(), ShotArea::All.describe());
        match (outside, self.area.strip_prefix(&all)) {
            (0, Some("")) => None,
            (0, Some(why)) => Some(format!("{rows} shot(s) kept: every shot{why}")),
            _ => Some(format!(
                "{rows} shot(s) kept within {}; {outside} outside it left out (read for their position only; \
                 --all-shots keeps every shot)",
                self.area
            )),
        }
    }

    /// Every warning line (file-level notes first).
    pub fn warnings(&self) -> Vec<String> {
        self.notes.iter().cloned().chain(self.beams.iter().flat_map(BeamReport::warnings)).collect()
    }
}

// ---------------------------------------------------------------------------------------------
// Entry points
// ---------------------------------------------------------------------------------------------

/// Read L1B and/or L2A files (either list may be empty) into batches of the [`shots_schema`].
///
/// Granules are read in parallel (rayon) and the batches returned in input order. For large
/// inputs prefer [`ingest_gedi`], which hands batches to a sink one beam at a time.
pub fn read_gedi(l1b: &[PathBuf], l2a: &[PathBuf], opts: &GediOptions) -> Result<(Vec<RecordBatch>, IngestReport)> {
    let (pairs, notes) = pair_granules(l1b, l2a)?;
    let parts = pairs
        .par_iter()
        .map(|pair| {
            let mut batches = Vec::new();
            let beams = read_granule(pair, opts, &mut |b| {
                batches.push(b);
                Ok(())
            })?;
            Ok((batches, beams))
        })
        .collect::<Result<Vec<_>>>()?;
    let mut report = IngestReport { beams: Vec::new(), notes, area: opts.area.describe() };
    let mut all = Vec::new();
    for (batches, beams) in parts {
        all.extend(batches);
        report.beams.extend(beams);
    }
    Ok((all, report))
}

/// Stream L1B and/or L2A files into `sink`, one beam at a time (at most [`BATCH_ROWS`] rows per batch).
pub fn ingest_gedi(
    l1b: &[PathBuf],
    l2a: &[PathBuf],
    opts: &GediOptions,
    mut sink: impl FnMut(RecordBatch) -> Result<()>,
) -> Result<IngestReport> {
    let (pairs, notes) = pair_granules(l1b, l2a)?;
    let mut report = IngestReport { beams: Vec::new(), notes, area: opts.area.describe() };
    for pair in &pairs {
        report.beams.extend(read_granule(pair, opts, &mut sink)?);
    }
    Ok(report)
}

/// The part of a GEDI file name shared by the L1B and L2A files of one granule.
///
/// `GEDI01_B_2019108080338_O01964_T05337_02_003_01_sub` and
/// `GEDI02_A_2019108080338_O01964_T05337_02_001_01_sub` both give
/// `2019108080338_O01964_T05337_02` (V2 names keep their sub-orbit field). A name that does not
/// follow the convention is its own key.
pub fn granule_key(path: &Path) -> String {
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let tokens: Vec<&str> = stem.split('_').collect();
    let is_product = tokens.len() > 2 && tokens[0].starts_with("GEDI0") && tokens[1].len() == 1;
    if is_product {
        let track =
            tokens.iter().position(|t| t.len() > 1 && t.starts_with('T') && t[1..].bytes().all(|b| b.is_ascii_digit()));
        if let Some(t) = track.filter(|&t| t > 2 && t + 1 < tokens.len()) {
            return tokens[2..=t + 1].join("_");
        }
    }
    stem
}

/// Files as given; folders expanded to the `.h5` files they hold whose name starts with
/// `product` (GEDI's naming: `GEDI01_B…` for L1B, `GEDI02_A…` for L2A).
pub fn expand_granule_inputs(inputs: &[PathBuf], product: &str) -> Result<Vec<PathBuf>> {
    crate::io::expand_inputs(inputs, |f| {
        crate::io::has_extension(f, "h5")
            && f.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.starts_with(product))
    })
}

/// Pair L1B and L2A files by [`granule_key`]; a file without a partner becomes a one-sided pair.
///
/// Returns the pairs (in the order the files were given, L1B first) and one note per file left
/// without a partner when both lists are non-empty.
pub fn pair_granules(l1b: &[PathBuf], l2a: &[PathBuf]) -> Result<(Vec<GranulePair>, Vec<String>)> {
    let mut l2a_by_key: BTreeMap<String, &PathBuf> = BTreeMap::new();
    for p in l2a {
        if let Some(other) = l2a_by_key.insert(granule_key(p), p) {
            return Err(Error::Usage(format!("{} and {} are the same L2A granule", other.display(), p.display())));
        }
    }
    let mut seen = BTreeMap::new();
    let mut pairs = Vec::new();
    let mut notes = Vec::new();
    let stem = |p: &Path| p.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    for p in l1b {
        let key = granule_key(p);
        if let Some(other) = seen.insert(key.clone(), p) {
            return Err(Error::Usage(format!("{} and {} are the same L1B granule", other.display(), p.display())));
        }
        let partner = l2a_by_key.remove(&key).cloned();
        if partner.is_none() && !l2a.is_empty() {
            notes.push(format!(
                "{}: no L2A file of granule {key} was given; its shots have null L2A columns",
                p.display()
            ));
        }
        pairs.push(GranulePair { granule: stem(p), l1b: Some(p.clone()), l2a: partner });
    }
    for p in l2a.iter().filter(|p| l2a_by_key.contains_key(&granule_key(p))) {
        if !l1b.is_empty() {
            notes.push(format!(
                "{}: no L1B file of granule {} was given; its shots have null L1B columns",
                p.display(),
                granule_key(p)
            ));
        }
        pairs.push(GranulePair { granule: stem(p), l1b: None, l2a: Some(p.clone()) });
    }
    Ok((pairs, notes))
}

/// Read one granule, beam by beam, handing each batch to `sink`; returns one report per beam.
/// In a child process when the command line asked for it (`ops::ingest_gedi::child`).
pub fn read_granule(
    pair: &GranulePair,
    opts: &GediOptions,
    sink: &mut dyn FnMut(RecordBatch) -> Result<()>,
) -> Result<Vec<BeamReport>> {
    match child::reader() {
        Some(reader) => child::read(reader, pair, opts, sink),
        None => read_granule_in_process(pair, opts, sink),
    }
}

/// [`read_granule`] in this process.
pub fn read_granule_in_process(
    pair: &GranulePair,
    opts: &GediOptions,
    sink: &mut dyn FnMut(RecordBatch) -> Result<()>,
) -> Result<Vec<BeamReport>> {
    let projector = Projector::new(opts.epsg)?;
    let schema = shots_schema(opts.epsg);
    let l1b = pair.l1b.as_deref().map(|p| open_product(p, Product::L1b)).transpose()?;
    let l2a = pair.l2a.as_deref().map(|p| open_product(p, Product::L2a)).transpose()?;

    let mut beams: Vec<String> = Vec::new();
    for f in l1b.iter().chain(l2a.iter()) {
        beams.extend(f.beams()?);
    }
    beams.sort();
    beams.dedup();

    let mut reports = Vec::new();
    for beam in beams {
        let beam_type = BeamType::from_name(&beam).ok_or_else(|| {
            let path = l1b.as_ref().or(l2a.as_ref()).map(|f| f.path).unwrap_or(Path::new(""));
            Error::field(path, &beam, "not one of the eight GEDI beams (BEAM0000..BEAM1011)")
        })?;
        let mut report = BeamReport {
            granule: pair.granule.clone(),
            beam: beam.clone(),
            l1b_file: pair.l1b.clone(),
            l2a_file: pair.l2a.clone(),
            ..Default::default()
        };
        let mut g1 = l1b.as_ref().map(|f| f.beam(&beam)).transpose()?.flatten();
        let mut g2 = l2a.as_ref().map(|f| f.beam(&beam)).transpose()?.flatten();
        if !opts.area.is_all() {
            // Every shot placed from its cheap datasets; the rest read for the shots kept only.
            let kept = select::kept(pair, &beam, g1.as_ref(), g2.as_ref(), &opts.area, &projector)?;
            report.outside_area = kept.outside;
            if kept.inside == 0 {
                reports.push(report);
                continue;
            }
            g1.iter_mut().for_each(|g| g.select(kept.l1b.clone()));
            g2.iter_mut().for_each(|g| g.select(kept.l2a.clone()));
        }
        // Read one side, then the other: only this beam's shots (kept) are in memory.
        let l1b_beam = g1.as_ref().map(read_l1b).transpose()?;
        let l2a_beam = g2.as_ref().map(read_l2a).transpose()?;
        if let Some(b) = &l1b_beam {
            report.non_finite_waveform =
                b.rx.non_finite.iter().chain(b.tx.iter().flat_map(|t| &t.non_finite)).copied().collect();
            report.non_finite_waveform.sort_unstable();
            report.non_finite_waveform.dedup();
        }
        let rows = join(pair, &beam, l1b_beam.as_ref(), l2a_beam.as_ref(), opts, &projector, &mut report)?;
        let ctx = BatchContext {
            schema: &schema,
            granule: &pair.granule,
            beam: &beam,
            beam_type,
            l1b: l1b_beam.as_ref(),
            l2a: l2a_beam.as_ref(),
            geoid_offset: opts.geoid_offset,
        };
        for chunk in rows.chunks(BATCH_ROWS) {
            sink(ctx.batch(chunk)?)?;
        }
        reports.push(report);
    }
    Ok(reports)
}

// ---------------------------------------------------------------------------------------------
// Join and batches
// ---------------------------------------------------------------------------------------------

/// Where the `x`, `y` of a row come from.
#[derive(Clone, Copy)]
enum XySource {
    /// L2A `lat/lon_lowestmode` (the footprint as L2A reports it).
    LowestMode,
    /// Mean of L1B bin0 and lastbin (the reference simulator's convention), for rows without a
    /// valid L2A lowest mode.
    BinMean,
}

impl XySource {
    fn as_str(self) -> &'static str {
        match self {
            XySource::LowestMode => "lowestmode",
            XySource::BinMean => "bin_mean",
        }
    }
}

/// Where a shot is (lat, lon, source): its valid L2A lowest mode, else the mean of its L1B bin0 and
/// lastbin (`[lat_bin0, lon_bin0, lat_lastbin, lon_lastbin]`); the same rule places rows and
/// chooses the shots kept ([`select`]).
fn position(lowest: Option<(f64, f64)>, bins: Option<[f64; 4]>) -> Option<(f64, f64, XySource)> {
    match (lowest, bins) {
        (Some((lat, lon)), _) => Some((lat, lon, XySource::LowestMode)),
        (None, Some([lat0, lon0, lat1, lon1])) => Some(((lat0 + lat1) / 2.0, (lon0 + lon1) / 2.0, XySource::BinMean)),
        (None, None) => None,
    }
}

/// One output row: the shot's index on each side and its projected position.
struct Row {
    shot_number: u64,
    l1b: Option<usize>,
    l2a: Option<usize>,
    xy: Option<(f64, f64, XySource)>,
}

/// The shot numbers of the dataset's granules and of those this call writes: a shot number is
/// unique across GEDI (it encodes the orbit, beam and shot, docs/gedi-products.md §1), so one
/// seen in two beams of a granule, or in two granules (a copy under another name), is a broken
/// file, and would put one shot in two collocation segments, which `run` cannot write
/// (docs/robustness.md).
struct ShotOwners {
    /// (shot number, index in `keys`) of every shot the dataset holds, sorted.
    stored: Vec<(u64, usize)>,
    keys: Vec<String>,
    /// Shots written by this call so far: their granule key and beam.
    claimed: std::sync::Mutex<HashMap<u64, Owner>>,
}

/// The granule key and beam of a shot.
type Owner = (Arc<str>, Arc<str>);

impl ShotOwners {
    /// The shots of every file of the dataset's `shots/` table (one per granule key).
    fn read(shots_dir: &Path) -> Result<ShotOwners> {
        let mut stored = Vec::new();
        let mut keys = Vec::new();
        for f in crate::dataset::table_files(shots_dir).map_err(|e| Error::file(shots_dir, e))? {
            let k = keys.len();
            keys.push(f.file_stem().and_then(|s| s.to_str()).unwrap_or_default().to_string());
            crate::dataset::read::for_each_batch(&f, Some(&["shot_number"]), None, |c| {
                stored.extend(c.u64s("shot_number")?.values().iter().map(|&s| (s, k)));
                Ok(())
            })?;
        }
        stored.sort_unstable();
        Ok(ShotOwners { stored, keys, claimed: Default::default() })
    }

    /// Claim the shots of a batch of granule `key`'s rows; refuse one that another beam of the
    /// granule or another granule holds (the granule's own earlier rows are replaced by this
    /// ingest).
    fn claim(&self, pair: &GranulePair, key: &Arc<str>, batch: &RecordBatch) -> Result<()> {
        let (Some(sn), Some(beams)) = (batch.column_by_name("shot_number"), batch.column_by_name("beam")) else {
            return Ok(());
        };
        use arrow::array::AsArray;
        let (sn, beams) = (sn.as_primitive::<arrow::datatypes::UInt64Type>(), beams.as_string::<i32>());
        let path = pair.l1b.as_deref().or(pair.l2a.as_deref()).unwrap_or(Path::new(&pair.granule));
        let refuse = |why: String| Err(Error::field(path, "shot_number", why));
        let in_granule = |shot: u64, other: &str| {
            refuse(format!(
                "shot {shot} is also in granule {other}: a shot number is unique across GEDI (a copy of that \
                 granule, or a broken file)"
            ))
        };
        let mut claimed = self.claimed.lock().unwrap_or_else(|e| e.into_inner());
        let mut beam: Arc<str> = Arc::from("");
        for (i, &shot) in sn.values().iter().enumerate() {
            if *beam != *beams.value(i) {
                beam = Arc::from(beams.value(i));
            }
            let from = self.stored.partition_point(|&(s, _)| s < shot);
            if let Some(&(_, k)) =
                self.stored[from..].iter().take_while(|(s, _)| *s == shot).find(|(_, k)| *self.keys[*k] != **key)
            {
                return in_granule(shot, &self.keys[k]);
            }
            match claimed.get(&shot) {
                Some((other, _)) if other != key => return in_granule(shot, other),
                Some((_, first)) if *first != beam => {
                    return refuse(format!(
                        "shot {shot} is in {first} and in {beam}: a shot number is unique in a granule"
                    ))
                }
                Some(_) => {}
                None => {
                    claimed.insert(shot, (key.clone(), beam.clone()));
                }
            }
        }
        Ok(())
    }
}

fn duplicate_check(path: Option<&Path>, beam: &str, shots: &[u64]) -> Result<()> {
    let mut sorted = shots.to_vec();
    sorted.sort_unstable();
    if let Some(w) = sorted.windows(2).find(|w| w[0] == w[1]) {
        return Err(Error::field(
            path.unwrap_or(Path::new("")),
            format!("{beam}/shot_number"),
            format!("duplicate shot {}", w[0]),
        ));
    }
    Ok(())
}

/// Join the two sides on shot_number (rows sorted by shot number) and project every row.
fn join(
    pair: &GranulePair,
    beam: &str,
    l1b: Option<&L1bBeam>,
    l2a: Option<&L2aBeam>,
    opts: &GediOptions,
    projector: &Projector,
    report: &mut BeamReport,
) -> Result<Vec<Row>> {
    let mut by_shot: BTreeMap<u64, (Option<usize>, Option<usize>)> = BTreeMap::new();
    if let Some(b) = l1b {
        duplicate_check(pair.l1b.as_deref(), beam, &b.shot_number)?;
        for (i, &s) in b.shot_number.iter().enumerate() {
            by_shot.entry(s).or_default().0 = Some(i);
        }
        report.l1b_shots = b.shot_number.len();
    }
    if let Some(b) = l2a {
        duplicate_check(pair.l2a.as_deref(), beam, &b.shot_number)?;
        for (i, &s) in b.shot_number.iter().enumerate() {
            by_shot.entry(s).or_default().1 = Some(i);
        }
        report.l2a_shots = b.shot_number.len();
    }

    let mut rows = Vec::with_capacity(by_shot.len());
    for (shot_number, (i1, i2)) in by_shot {
        match (i1, i2) {
            (Some(_), Some(_)) => report.joined += 1,
            // A one-sided shot is an anomaly only when the other product's file was given.
            (Some(_), None) if pair.l2a.is_some() => report.l1b_only.push(shot_number),
            (None, Some(_)) if pair.l1b.is_some() => report.l2a_only.push(shot_number),
            _ => {}
        }
        let lowest = match (l2a, i2) {
            (Some(b), Some(i)) => {
                let v = b.lowestmode(i);
                if v.is_none() {
                    report.invalid_lowestmode.push(shot_number);
                }
                v
            }
            _ => None,
        };
        let bins = l1b.zip(i1).map(|(b, i)| [b.lat_bin0[i], b.lon_bin0[i], b.lat_lastbin[i], b.lon_lastbin[i]]);
        let Some((lat, lon, source)) = position(lowest, bins) else {
            rows.push(Row { shot_number, l1b: i1, l2a: i2, xy: None });
            continue;
        };
        let field = match source {
            XySource::LowestMode => "lat_lowestmode",
            XySource::BinMean => "geolocation/latitude_bin0",
        };
        let (x, y) = projector.project(lon, lat).map_err(|e| {
            let path = if matches!(source, XySource::LowestMode) { pair.l2a.as_deref() } else { pair.l1b.as_deref() };
            Error::field(path.unwrap_or(Path::new("")), format!("{beam}/{field}"), format!("shot {shot_number}: {e}"))
        })?;
        rows.push(Row { shot_number, l1b: i1, l2a: i2, xy: Some((x, y, source)) });
    }

    if opts.strict_join {
        if let Some(&first) = report.l1b_only.first() {
            let path = pair.l1b.as_deref().unwrap_or(Path::new(""));
            return Err(Error::field(
                path,
                format!("{beam}/shot_number"),
                format!(
                    "{} shot(s) have no L2A partner (first {first}) and --strict-join is set",
                    report.l1b_only.len()
                ),
            ));
        }
        if let Some(&first) = report.l2a_only.first() {
            let path = pair.l2a.as_deref().unwrap_or(Path::new(""));
            return Err(Error::field(
                path,
                format!("{beam}/shot_number"),
                format!(
                    "{} shot(s) have no L1B partner (first {first}) and --strict-join is set",
                    report.l2a_only.len()
                ),
            ));
        }
    }
    Ok(rows)
}

/// Everything needed to turn rows of one beam into a batch.
struct BatchContext<'a> {
    schema: &'a SchemaRef,
    granule: &'a str,
    beam: &'a str,
    beam_type: BeamType,
    l1b: Option<&'a L1bBeam>,
    l2a: Option<&'a L2aBeam>,
    geoid_offset: Option<f64>,
}

/// `v[i]` when both the optional column and the row index are present.
fn at<T: Copy>(v: &Option<Vec<T>>, i: Option<usize>) -> Option<T> {
    Some(v.as_ref()?[i?])
}

/// Row `i` of a row-major N×101 RH array.
fn rh_row(v: &[f32], i: usize) -> &[f32] {
    &v[i * RH_LEN..(i + 1) * RH_LEN]
}

fn prim<T: ArrowPrimitiveType>(rows: &[Row], f: impl Fn(&Row) -> Option<T::Native>) -> ArrayRef {
    Arc::new(rows.iter().map(f).collect::<PrimitiveArray<T>>())
}

fn f64s(rows: &[Row], f: impl Fn(&Row) -> Option<f64>) -> ArrayRef {
    prim::<Float64Type>(rows, f)
}

fn lists<'r>(rows: &'r [Row], f: impl Fn(&'r Row) -> Option<&'r [f32]>) -> ArrayRef {
    let mut b = ListBuilder::new(Float32Builder::new());
    for r in rows {
        match f(r) {
            Some(v) => {
                b.values().append_slice(v);
                b.append(true);
            }
            None => b.append(false),
        }
    }
    Arc::new(b.finish())
}

fn strings<'r>(rows: &'r [Row], f: impl Fn(&'r Row) -> Option<&'r str>) -> ArrayRef {
    Arc::new(rows.iter().map(f).collect::<StringArray>())
}

impl BatchContext<'_> {
    fn batch(&self, rows: &[Row]) -> Result<RecordBatch> {
        let (l1, l2) = (self.l1b, self.l2a);
        // Accessors returning None when the row lacks that side.
        let a1 = |r: &Row| l1.zip(r.l1b);
        let a2 = |r: &Row| l2.zip(r.l2a);

        let mut cols: Vec<(String, ArrayRef)> = vec![
            ("granule".into(), strings(rows, |_| Some(self.granule))),
            ("shot_number".into(), prim::<UInt64Type>(rows, |r| Some(r.shot_number))),
            ("beam".into(), strings(rows, |_| Some(self.beam))),
            ("beam_type".into(), strings(rows, |_| Some(self.beam_type.as_str()))),
            ("in_l1b".into(), Arc::new(rows.iter().map(|r| Some(r.l1b.is_some())).collect::<BooleanArray>())),
            ("in_l2a".into(), Arc::new(rows.iter().map(|r| Some(r.l2a.is_some())).collect::<BooleanArray>())),
            (
                "delta_time".into(),
                f64s(rows, |r| {
                    a1(r)
                        .and_then(|(b, i)| at(&b.delta_time, Some(i)))
                        .or_else(|| a2(r).and_then(|(b, i)| at(&b.delta_time, Some(i))))
                }),
            ),
            ("lat_bin0".into(), f64s(rows, |r| a1(r).map(|(b, i)| b.lat_bin0[i]))),
            ("lon_bin0".into(), f64s(rows, |r| a1(r).map(|(b, i)| b.lon_bin0[i]))),
            ("lat_lastbin".into(), f64s(rows, |r| a1(r).map(|(b, i)| b.lat_lastbin[i]))),
            ("lon_lastbin".into(), f64s(rows, |r| a1(r).map(|(b, i)| b.lon_lastbin[i]))),
            ("lat_lowestmode".into(), f64s(rows, |r| a2(r).and_then(|(b, i)| b.lowestmode(i)).map(|p| p.0))),
            ("lon_lowestmode".into(), f64s(rows, |r| a2(r).and_then(|(b, i)| b.lowestmode(i)).map(|p| p.1))),
            ("x".into(), f64s(rows, |r| r.xy.map(|p| p.0))),
            ("y".into(), f64s(rows, |r| r.xy.map(|p| p.1))),
            ("xy_source".into(), strings(rows, |r| r.xy.map(|p| p.2.as_str()))),
            ("elevation_bin0".into(), f64s(rows, |r| a1(r).map(|(b, i)| b.elevation_bin0[i]))),
            ("elevation_lastbin".into(), f64s(rows, |r| a1(r).map(|(b, i)| b.elevation_lastbin[i]))),
            ("rx_waveform".into(), lists(rows, |r| a1(r).and_then(|(b, i)| b.rx.get(i)))),
            ("rx_sample_count".into(), prim::<UInt32Type>(rows, |r| a1(r).map(|(b, i)| b.rx.spans[i].1 as u32))),
            ("tx_waveform".into(), lists(rows, |r| a1(r).and_then(|(b, i)| b.tx.as_ref()?.get(i)))),
            ("noise_mean_corrected".into(), f64s(rows, |r| a1(r).and_then(|(b, i)| at(&b.noise_mean, Some(i))))),
            ("noise_stddev_corrected".into(), f64s(rows, |r| a1(r).and_then(|(b, i)| at(&b.noise_stddev, Some(i))))),
            (
                "stale_return_flag".into(),
                prim::<UInt8Type>(rows, |r| a1(r).and_then(|(b, i)| at(&b.stale_return_flag, Some(i)))),
            ),
            ("degrade".into(), prim::<Int8Type>(rows, |r| a1(r).and_then(|(b, i)| at(&b.degrade, Some(i))))),
            ("geoid".into(), f64s(rows, |r| a1(r).and_then(|(b, i)| at(&b.geoid, Some(i))))),
            (
                "geoid_offset_used".into(),
                f64s(rows, |r| self.geoid_offset.or_else(|| a1(r).and_then(|(b, i)| at(&b.geoid, Some(i))))),
            ),
            ("vertical_datum".into(), strings(rows, |_| Some(VERTICAL_DATUM))),
            ("quality_flag".into(), prim::<UInt8Type>(rows, |r| a2(r).map(|(b, i)| b.quality_flag[i]))),
            ("degrade_flag".into(), prim::<UInt8Type>(rows, |r| a2(r).map(|(b, i)| b.degrade_flag[i]))),
            ("sensitivity".into(), f64s(rows, |r| a2(r).map(|(b, i)| b.sensitivity[i]))),
            ("selected_algorithm".into(), prim::<UInt8Type>(rows, |r| a2(r).map(|(b, i)| b.selected_algorithm[i]))),
            ("elev_lowestmode".into(), f64s(rows, |r| a2(r).map(|(b, i)| b.elev_lowestmode[i]))),
            ("rh".into(), lists(rows, |r| a2(r).map(|(b, i)| rh_row(&b.rh, i)))),
            ("energy_total".into(), f64s(rows, |r| a2(r).and_then(|(b, i)| at(&b.energy_total, Some(i))))),
        ];
        for a in 0..N_ALGORITHMS {
            let n = a + 1;
            let alg = |r: &Row| a2(r).map(|(b, i)| (&b.algorithms[a], i));
            cols.extend([
                (
                    format!("elev_lowestmode_a{n}"),
                    f64s(rows, |r| alg(r).and_then(|(g, i)| at(&g.elev_lowestmode, Some(i)))),
                ),
                (format!("rh_a{n}"), lists(rows, |r| alg(r).and_then(|(g, i)| Some(rh_row(g.rh.as_ref()?, i))))),
                (format!("sensitivity_a{n}"), f64s(rows, |r| alg(r).and_then(|(g, i)| at(&g.sensitivity, Some(i))))),
                (
                    format!("quality_flag_a{n}"),
                    prim::<UInt8Type>(rows, |r| alg(r).and_then(|(g, i)| at(&g.quality_flag, Some(i)))),
                ),
                (format!("toploc_a{n}"), f64s(rows, |r| alg(r).and_then(|(g, i)| at(&g.toploc, Some(i))))),
                (format!("botloc_a{n}"), f64s(rows, |r| alg(r).and_then(|(g, i)| at(&g.botloc, Some(i))))),
                (format!("zcross_a{n}"), f64s(rows, |r| alg(r).and_then(|(g, i)| at(&g.zcross, Some(i))))),
            ]);
        }
        let u8_lc = |f: fn(&L2aBeam) -> &Option<Vec<u8>>| {
            prim::<UInt8Type>(rows, move |r| a2(r).and_then(|(b, i)| at(f(b), Some(i))))
        };
        let i16_lc = |f: fn(&L2aBeam) -> &Option<Vec<i16>>| {
            prim::<Int16Type>(rows, move |r| a2(r).and_then(|(b, i)| at(f(b), Some(i))))
        };
        cols.extend([
            ("leaf_off_flag".into(), u8_lc(|b| &b.leaf_off_flag)),
            ("leaf_off_doy".into(), i16_lc(|b| &b.leaf_off_doy)),
            ("leaf_on_doy".into(), i16_lc(|b| &b.leaf_on_doy)),
            ("pft_class".into(), u8_lc(|b| &b.pft_class)),
            ("region_class".into(), u8_lc(|b| &b.region_class)),
            ("urban_proportion".into(), u8_lc(|b| &b.urban_proportion)),
            ("landsat_water_persistence".into(), u8_lc(|b| &b.landsat_water_persistence)),
        ]);

        // Order the columns by the schema, so the schema stays the single definition of order.
        let mut by_name: std::collections::HashMap<String, ArrayRef> = cols.into_iter().collect();
        let arrays = self
            .schema
            .fields()
            .iter()
            .map(|f| by_name.remove(f.name()).ok_or_else(|| Error::Usage(format!("internal: no column {}", f.name()))))
            .collect::<Result<Vec<_>>>()?;
        RecordBatch::try_new(self.schema.clone(), arrays).map_err(|e| Error::table(self.granule, e))
    }
}

// ---------------------------------------------------------------------------------------------
// Into a dataset
// ---------------------------------------------------------------------------------------------

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
    let r = ingest_into_dataset(dataset, &l1b, &l2a, &opts, progress);
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
/// Granules are processed in parallel; `progress` advances by one after each.
pub fn ingest_into_dataset(
    dataset: &crate::dataset::Dataset,
    l1b: &[PathBuf],
    l2a: &[PathBuf],
    opts: &GediOptions,
    progress: &dyn Progress,
) -> Result<(Vec<GranuleOutcome>, IngestReport)> {
    use crate::dataset::{self, tables, AtomicParquet};
    use arrow::array::{StringArray, UInt64Array};

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
    let owners = ShotOwners::read(&shots_dir)?;
    let results = pairs
        .par_iter()
        .zip(keyed)
        .zip(duplicate)
        .map(|((pair, (key, h1, h2)), duplicate)| -> Result<(GranuleOutcome, Vec<BeamReport>)> {
            let record = granules_dir.join(format!("{key}.parquet"));
            let previous = recorded.get(&key).cloned();
            // A side the granule had and this call lacks would be lost by a rewrite: unchanged
            // given sides are nothing new; changed ones need both files.
            let same = |new: &Option<String>, old: &Option<String>| new.is_none() || new == old;
            if let Some((p1, p2)) = &previous {
                if (p1.is_some() && h1.is_none()) || (p2.is_some() && h2.is_none()) {
                    if same(&h1, p1) && same(&h2, p2) {
                        progress.advance(1);
                        return Ok((GranuleOutcome::AlreadyIngested { granule: pair.granule.clone() }, Vec::new()));
                    }
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
            }
            // Read again with another area; but a granule read whole holds every shot the default
            // (the tiles' coverage) asks for.
            let area_read = recorded_area.get(&key).map(String::as_str);
            let whole_for_tiles = matches!(opts.area, ShotArea::Tiles { .. }) && area_read == Some("all");
            let same_area = area_read == Some(opts.area.key().as_str()) || whole_for_tiles;
            if duplicate || (previous == Some((h1.clone(), h2.clone())) && same_area) {
                progress.advance(1);
                return Ok((GranuleOutcome::AlreadyIngested { granule: pair.granule.clone() }, Vec::new()));
            }
            let schema = shots_schema(opts.epsg);
            let mut metadata = std::collections::HashMap::new();
            metadata.insert("gedisim:crs_epsg".to_string(), opts.epsg.to_string());
            metadata.insert("gedisim:vertical_reference".to_string(), VERTICAL_DATUM.to_string());
            let props = dataset::writer_properties(&metadata, 1 << 16);
            let mut writer = AtomicParquet::create(&shots_dir.join(format!("{key}.parquet")), schema, props)?;
            let owner: Arc<str> = Arc::from(key.as_str());
            let beams = read_granule(pair, opts, &mut |b| {
                owners.claim(pair, &owner, &b)?;
                writer.write(&b)
            })?;
            writer.finish()?;
            let shots: usize = beams.iter().map(BeamReport::rows).sum();
            let path = |p: &Option<PathBuf>| p.as_ref().map(|p| p.display().to_string());
            let cols: Vec<arrow::array::ArrayRef> = vec![
                Arc::new(StringArray::from(vec![pair.granule.clone()])),
                Arc::new(StringArray::from(vec![key.clone()])),
                Arc::new(StringArray::from(vec![path(&pair.l1b)])),
                Arc::new(StringArray::from(vec![h1])),
                Arc::new(StringArray::from(vec![path(&pair.l2a)])),
                Arc::new(StringArray::from(vec![h2])),
                Arc::new(UInt64Array::from(vec![shots as u64])),
                Arc::new(StringArray::from(vec![opts.area.key()])),
                Arc::new(UInt64Array::from(vec![beams.iter().map(|b| b.outside_area as u64).sum::<u64>()])),
            ];
            let batch = RecordBatch::try_new(granules_schema(), cols).map_err(|e| Error::table(&record, e))?;
            dataset::write_parquet(&record, granules_schema(), &[batch], &metadata)?;
            progress.advance(1);
            Ok((GranuleOutcome::Ingested { granule: pair.granule.clone(), shots }, beams))
        })
        .collect::<Result<Vec<_>>>()?;
    let mut report = IngestReport { beams: Vec::new(), notes, area: opts.area.describe() };
    let mut outcomes = Vec::new();
    for (o, beams) in results {
        outcomes.push(o);
        report.beams.extend(beams);
    }
    Ok((outcomes, report))
}

/// The content hashes of a granule's L1B and L2A files (either may be absent).
type Hashes = (Option<String>, Option<String>);

/// A pair's granule key and the content hashes of its L1B and L2A files.
type Keyed = (String, Option<String>, Option<String>);

/// Which pairs are copies of granules the dataset (or an earlier pair of the call) already holds
/// under another key: a file's content belongs to one granule key, whatever the file is called, so
/// a renamed copy must not double the shots. A copy paired with other files is an error.
fn copies_of_other_granules(
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
            let has_area = c.batch().schema().column_with_name("shot_area").is_some();
            let area = if has_area { c.string("shot_area", 0)? } else { None };
            let hashes = (c.string("l1b_hash", 0)?, c.string("l2a_hash", 0)?);
            out = Some((hashes, area.unwrap_or_else(|| ShotArea::All.key())));
        }
        Ok(())
    })?;
    Ok(out)
}
