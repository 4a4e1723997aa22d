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
//!
//! By step: [`pairs`] (the granules paired), `select` (the shots of a beam inside the area), [`join`]
//! (L1B with L2A), [`batch`] (rows into batches), [`into_dataset`] (a granule's files in a dataset);
//! here, reading a granule beam by beam, in a child process when asked ([`child`]).

use std::path::{Path, PathBuf};

use arrow::array::RecordBatch;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::dataset::shots::shots_schema;
use crate::error::{Error, Result};
use crate::io::gedi::{open_product, read_l1b, read_l2a, Product};
use crate::kernels::gedi::BeamType;
use crate::kernels::geo::area::ShotArea;
use crate::kernels::geo::projection::Projector;

mod batch;
pub mod child;
pub(crate) mod coverage;
mod into_dataset;
mod join;
mod on_cluster;
mod pairs;
mod select;

/// Where granules are read (`IngestRequest::engine`).
pub use crate::sql::Engine;
use batch::BatchContext;
pub use coverage::ShotChoice;
pub use into_dataset::{
    ingest, ingest_into_dataset, previous_record, write_granule_shots, GranuleJob, GranuleOutcome, IngestRequest,
    DEFAULT_EPSG,
};
use join::join;
pub use on_cluster::write_from_json;
pub use pairs::{expand_granule_inputs, granule_key, pair_granules};

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
            let beams = read_granule(pair, opts, BeamPart::parts_for(pair, pairs.len()), &mut |b| {
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
        report.beams.extend(read_granule(pair, opts, BeamPart::parts_for(pair, 1), &mut sink)?);
    }
    Ok(report)
}

/// Read one granule, beam by beam, handing each batch to `sink`; returns one report per beam.
/// In child processes when the command line asked for it (`ops::ingest_gedi::child`): `parts` of
/// its beams at once, each in its own child, the batches handed on in beam order.
pub fn read_granule(
    pair: &GranulePair,
    opts: &GediOptions,
    parts: usize,
    sink: &mut dyn FnMut(RecordBatch) -> Result<()>,
) -> Result<Vec<BeamReport>> {
    match child::reader() {
        Some(reader) => child::read_in_parts(reader, pair, opts, parts, sink),
        None => read_granule_in_process(pair, opts, BeamPart::WHOLE, sink),
    }
}

/// Some of a granule's beams: those of its sorted beam names in part `index` of `of` contiguous
/// parts. HDF5 reads (and inflates) one dataset at a time in a process; a large granule read alone
/// is read faster in parts, each in its own process.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct BeamPart {
    pub index: usize,
    pub of: usize,
}

impl Default for BeamPart {
    fn default() -> Self {
        BeamPart::WHOLE
    }
}

impl BeamPart {
    /// Every beam.
    pub const WHOLE: BeamPart = BeamPart { index: 0, of: 1 };

    /// Its beams of `beams` (sorted).
    fn of_beams(self, beams: Vec<String>) -> Vec<String> {
        let (n, of) = (beams.len(), self.of.max(1));
        let range = self.index * n / of..(self.index + 1) * n / of;
        beams.into_iter().take(range.end).skip(range.start).collect()
    }

    /// The parts to read `pair` in while `at_once` granules are read together: one for a granule
    /// below [`SPLIT_MIN_BYTES`] (a child process costs more than its beams), else the cores each
    /// granule has, at most one part a beam.
    pub fn parts_for(pair: &GranulePair, at_once: usize) -> usize {
        let size = |p: &Option<PathBuf>| p.as_deref().and_then(|p| std::fs::metadata(p).ok()).map_or(0, |m| m.len());
        if size(&pair.l1b) + size(&pair.l2a) < SPLIT_MIN_BYTES {
            return 1;
        }
        (rayon::current_num_threads() / at_once.max(1)).clamp(1, 8)
    }
}

/// A granule pair of at least this many bytes is read in parts ([`BeamPart::parts_for`]).
pub const SPLIT_MIN_BYTES: u64 = 256 << 20;

/// [`read_granule`] in this process: the beams of `part`.
pub fn read_granule_in_process(
    pair: &GranulePair,
    opts: &GediOptions,
    part: BeamPart,
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
    let beams = part.of_beams(beams);

    // The area's rectangles indexed once for the granule's beams.
    let area = opts.area.index();
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
            let kept = select::kept(pair, &beam, g1.as_ref(), g2.as_ref(), &area, &projector)?;
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
