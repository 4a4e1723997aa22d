//! GEDI L1B and L2A HDF5 granules (V1 and V2 layouts, docs/gedi-products.md §2–§3) read beam by
//! beam: the datasets `ops::ingest_gedi` joins into the `shots` table. Facts relied on:
//! `shot_number` is uint64 (int64 in some old subsets; never float); `rx_sample_start_index` is
//! **1-based**; L2A `geolocation/rh_aN` is integer centimetres while root `rh` is metres; V1 has no
//! `land_cover_data/leaf_off_flag`.

use std::ops::Range;
use std::path::Path;

use hdf5::types::{FixedAscii, FixedUnicode, H5Type, TypeDescriptor, VarLenAscii, VarLenUnicode};
use hdf5::{Dataset, File, Group, Location};

use crate::error::{one_line, Error, Result};
use crate::kernels::gedi::{is_beam_group, N_ALGORITHMS, RH_LEN};

// ---------------------------------------------------------------------------------------------
// HDF5 access
// ---------------------------------------------------------------------------------------------

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Product {
    L1b,
    L2a,
}

impl Product {
    pub fn short_name(self) -> &'static str {
        match self {
            Product::L1b => "GEDI_L1B",
            Product::L2a => "GEDI_L2A",
        }
    }
}

/// An open granule file.
pub struct Granule<'a> {
    pub path: &'a Path,
    pub file: File,
}

/// Open or create HDF5 files without HDF5's advisory file locks. gedisim reads granules and writes
/// only new ones nobody else has open, so the locks add nothing; and they fail — `unable to lock
/// file, errno = 11` — on NFS/Lustre, or when a child process (a `gedisim` started by the same
/// program, a notebook's subprocess) inherited the file's descriptor. `HDF5_USE_FILE_LOCKING`,
/// when the user sets it, still wins over this (HDF5 reads it at each open). HDF5 refuses to open
/// a file twice in one process with different locking ("file locking flag values don't match"):
/// code beside gedisim's that opens the same granules (the tests) opens them through this too.
pub fn without_locks() -> hdf5::FileBuilder {
    let mut builder = File::with_options();
    builder.with_fapl(|p| p.file_locking(false));
    builder
}

/// HDF5's raw-data chunk cache of each dataset while a granule is read (bytes, hash slots). NASA
/// stores a beam's per-shot dataset as one gzip chunk of up to 554,085 rows: once a beam holds more
/// than 131,072 shots, a float64 chunk is above HDF5's default cache of 1 MiB, and HDF5 inflates it
/// again for every run of selected shots read from it (a track crossing plots far apart,
/// `--within`). Measured with h5py on the same library: 10 datasets of 200,000 rows, 50 runs of 3
/// rows each, 3.21 s with 1 MiB, 0.075 s with 32 MiB (docs/benchmarks.md). Held only while a
/// dataset is open.
const CHUNK_CACHE: (usize, usize) = (32 << 20, 10_007);

pub fn open_product(path: &Path, product: Product) -> Result<Granule<'_>> {
    let mut builder = without_locks();
    builder.with_fapl(|p| p.chunk_cache(CHUNK_CACHE.1, CHUNK_CACHE.0, 0.75));
    let file = builder.open(path).map_err(|e| Error::file(path, format!("cannot open as HDF5: {e}")))?;
    // A swapped --l1b/--l2a would otherwise fail later with a confusing "missing dataset".
    if let Some(name) = read_str_attr(&file, "short_name") {
        let other = if product == Product::L1b { Product::L2a } else { Product::L1b };
        if name.trim() == other.short_name() {
            return Err(Error::field(
                path,
                "short_name",
                format!("file is {name} but was given as {}", product.short_name()),
            ));
        }
    }
    Ok(Granule { path, file })
}

/// Read a scalar string attribute of any HDF5 string flavour; `None` if absent or not a string.
pub fn read_str_attr(loc: &Location, name: &str) -> Option<String> {
    let attr = loc.attr(name).ok()?;
    let r = attr.as_reader();
    let s = match attr.dtype().ok()?.to_descriptor().ok()? {
        TypeDescriptor::VarLenUnicode => r.read_raw::<VarLenUnicode>().ok()?.first()?.to_string(),
        TypeDescriptor::VarLenAscii => r.read_raw::<VarLenAscii>().ok()?.first()?.to_string(),
        TypeDescriptor::FixedAscii(_) => r.read_raw::<FixedAscii<256>>().ok()?.first()?.to_string(),
        TypeDescriptor::FixedUnicode(_) => r.read_raw::<FixedUnicode<256>>().ok()?.first()?.to_string(),
        _ => return None,
    };
    Some(s)
}

impl<'a> Granule<'a> {
    pub fn beams(&self) -> Result<Vec<String>> {
        let names = self.file.member_names().map_err(|e| Error::file(self.path, format!("cannot list groups: {e}")))?;
        Ok(names.into_iter().filter(|n| is_beam_group(n)).collect())
    }

    pub fn beam(&self, name: &str) -> Result<Option<BeamGroup<'a>>> {
        if !self.file.link_exists(name) {
            return Ok(None);
        }
        let group = self.file.group(name).map_err(|e| Error::field(self.path, name, e))?;
        let mut g =
            BeamGroup { path: self.path, beam: name.to_string(), group, n: 0, runs: None, placed: Default::default() };
        g.n = g.shot_numbers_len()?;
        Ok(Some(g))
    }
}

/// Numeric element types a dataset can be read into (HDF5 converts from the file's dtype).
pub trait Numeric: H5Type + Copy {
    /// Whether the target is a float (integer targets refuse float sources: no silent truncation).
    const FLOAT: bool;
}
macro_rules! numeric {
    ($($t:ty => $float:expr),*) => { $(impl Numeric for $t { const FLOAT: bool = $float; })* };
}
numeric!(u8 => false, i8 => false, i16 => false, u64 => false, i64 => false, f32 => true, f64 => true);

/// Expected shape of a dataset in a beam group with `n` shots.
#[derive(Clone, Copy)]
pub enum Shape {
    /// `(n,)`.
    PerShot,
    /// `(n, k)`.
    Rows(usize),
    /// Any 1-D length (flat waveform arrays).
    Flat,
}

/// Runs of consecutive shot indices of a beam, in order and disjoint: the shots a read keeps.
pub type Runs = Vec<Range<usize>>;

/// The runs of consecutive indices among sorted, distinct `indices`.
pub fn runs_of(indices: &[usize]) -> Runs {
    let mut runs: Runs = Vec::new();
    for &i in indices {
        match runs.last_mut() {
            Some(r) if r.end == i => r.end += 1,
            _ => runs.push(i..i + 1),
        }
    }
    runs
}

/// The per-shot datasets that place a beam's shots (`ops::ingest_gedi::select`), read whole then
/// again for the shots kept.
const PLACING: [&str; 7] = [
    "shot_number",
    "lat_lowestmode",
    "lon_lowestmode",
    "geolocation/latitude_bin0",
    "geolocation/longitude_bin0",
    "geolocation/latitude_lastbin",
    "geolocation/longitude_lastbin",
];

/// One beam group of one file, with its shot count.
pub struct BeamGroup<'a> {
    pub path: &'a Path,
    pub beam: String,
    pub group: Group,
    /// Shots in the file's beam (the length of its per-shot datasets).
    pub n: usize,
    /// The shots every per-shot read takes (`None`: all), read by hyperslab selections.
    runs: Option<Runs>,
    /// The datasets of [`PLACING`] once opened, kept open with the beam: an ingest by area reads
    /// them whole to place every shot, then again for the shots kept, which HDF5's chunk cache
    /// then serves without inflating them again.
    placed: std::cell::RefCell<std::collections::HashMap<String, Dataset>>,
}

impl BeamGroup<'_> {
    /// Take only the shots of `runs` (sorted, disjoint, non-empty ranges below [`Self::n`]) in every
    /// later read of a per-shot dataset, waveforms included: their values come back in order, as
    /// if the beam held only them.
    pub fn select(&mut self, runs: Runs) {
        debug_assert!(runs.iter().all(|r| r.start < r.end && r.end <= self.n));
        self.runs = Some(runs);
    }

    pub fn field(&self, rel: &str) -> String {
        format!("{}/{rel}", self.beam)
    }

    pub fn err(&self, rel: &str, msg: impl std::fmt::Display) -> Error {
        Error::field(self.path, self.field(rel), one_line(&msg.to_string()))
    }

    /// The dataset at `rel` (e.g. `geolocation/elevation_bin0`), or `None` if any component is absent.
    pub fn dataset(&self, rel: &str) -> Result<Option<Dataset>> {
        if let Some(ds) = self.placed.borrow().get(rel) {
            return Ok(Some(ds.clone()));
        }
        let ds = self.open_dataset(rel)?;
        if let Some(ds) = ds.as_ref().filter(|_| PLACING.contains(&rel)) {
            self.placed.borrow_mut().insert(rel.to_string(), ds.clone());
        }
        Ok(ds)
    }

    fn open_dataset(&self, rel: &str) -> Result<Option<Dataset>> {
        let (dirs, name) = rel.rsplit_once('/').unwrap_or(("", rel));
        let mut g = self.group.clone();
        for part in dirs.split('/').filter(|p| !p.is_empty()) {
            if !g.link_exists(part) {
                return Ok(None);
            }
            g = g.group(part).map_err(|e| self.err(rel, e))?;
        }
        if !g.link_exists(name) {
            return Ok(None);
        }
        g.dataset(name).map(Some).map_err(|e| self.err(rel, e))
    }

    pub fn require_dataset(&self, rel: &str) -> Result<Dataset> {
        self.dataset(rel)?.ok_or_else(|| self.err(rel, "missing"))
    }

    /// Check the dataset's shape against the beam's shot count.
    pub fn check_shape(&self, rel: &str, ds: &Dataset, shape: Shape) -> Result<()> {
        let dims = ds.shape();
        let ok = match shape {
            Shape::PerShot => dims == [self.n],
            Shape::Rows(k) => dims == [self.n, k],
            Shape::Flat => dims.len() == 1,
        };
        if ok {
            return Ok(());
        }
        let expected = match shape {
            Shape::PerShot => format!("({},)", self.n),
            Shape::Rows(k) => format!("({}, {k})", self.n),
            Shape::Flat => "1-D".to_string(),
        };
        Err(self.err(
            rel,
            format!("shape {dims:?} does not match {expected} ({}/shot_number has {} shots)", self.beam, self.n),
        ))
    }

    /// Refuse a dataset whose dtype `T` cannot hold without loss (a float read as an integer).
    fn check_dtype<T: Numeric>(&self, rel: &str, ds: &Dataset) -> Result<()> {
        let desc = ds.dtype().and_then(|t| t.to_descriptor()).map_err(|e| self.err(rel, e))?;
        match desc {
            TypeDescriptor::Float(_) if !T::FLOAT => {
                Err(self.err(rel, format!("expected an integer dtype, found {desc}")))
            }
            TypeDescriptor::Integer(_) | TypeDescriptor::Unsigned(_) | TypeDescriptor::Float(_) => Ok(()),
            _ => Err(self.err(rel, format!("expected a numeric dtype, found {desc}"))),
        }
    }

    /// Elements `range` of a 1-D numeric dataset (one hyperslab).
    pub fn read_range<T: Numeric>(&self, rel: &str, ds: &Dataset, range: Range<usize>) -> Result<Vec<T>> {
        self.check_dtype::<T>(rel, ds)?;
        ds.read_slice_1d::<T, _>(range).map(|a| a.into_raw_vec_and_offset().0).map_err(|e| self.err(rel, e))
    }

    /// Read a numeric dataset into `Vec<T>` (row-major), converting from the file's dtype; of a
    /// per-shot dataset only the selected shots ([`Self::select`]).
    pub fn read_ds<T: Numeric>(&self, rel: &str, ds: &Dataset, shape: Shape) -> Result<Vec<T>> {
        self.check_shape(rel, ds, shape)?;
        self.check_dtype::<T>(rel, ds)?;
        let runs = match (&self.runs, shape) {
            (Some(runs), Shape::PerShot | Shape::Rows(_)) => runs,
            _ => return ds.read_raw::<T>().map_err(|e| self.err(rel, e)),
        };
        let mut out = Vec::new();
        for r in runs {
            // Row-major either way: a 2-D slice of whole rows is in standard layout.
            out.extend(match shape {
                Shape::Rows(_) => ds
                    .read_slice_2d::<T, _>((r.clone(), ..))
                    .map(|a| a.into_raw_vec_and_offset().0)
                    .map_err(|e| self.err(rel, e))?,
                _ => self.read_range(rel, ds, r.clone())?,
            });
        }
        Ok(out)
    }

    /// A required dataset: missing ⇒ `<file>: BEAMxxxx/<rel>: missing`.
    pub fn require<T: Numeric>(&self, rel: &str, shape: Shape) -> Result<Vec<T>> {
        let ds = self.require_dataset(rel)?;
        self.read_ds(rel, &ds, shape)
    }

    /// An optional dataset: `None` when absent, an error when present but malformed.
    pub fn optional<T: Numeric>(&self, rel: &str, shape: Shape) -> Result<Option<Vec<T>>> {
        self.dataset(rel)?.map(|ds| self.read_ds(rel, &ds, shape)).transpose()
    }

    pub fn shot_numbers_len(&self) -> Result<usize> {
        let ds = self.require_dataset("shot_number")?;
        match ds.shape().as_slice() {
            [n] => Ok(*n),
            dims => Err(self.err("shot_number", format!("shape {dims:?} is not 1-D"))),
        }
    }

    /// `shot_number` as u64, never through a float (values exceed 2^53); int64 is accepted and cast.
    pub fn shot_numbers(&self) -> Result<Vec<u64>> {
        let rel = "shot_number";
        let ds = self.require_dataset(rel)?;
        self.check_shape(rel, &ds, Shape::PerShot)?;
        let desc = ds.dtype().and_then(|t| t.to_descriptor()).map_err(|e| self.err(rel, e))?;
        match desc {
            TypeDescriptor::Unsigned(_) => self.read_ds::<u64>(rel, &ds, Shape::PerShot),
            TypeDescriptor::Integer(_) => {
                let v = self.read_ds::<i64>(rel, &ds, Shape::PerShot)?;
                v.into_iter()
                    .map(|s| u64::try_from(s).map_err(|_| self.err(rel, format!("negative shot number {s}"))))
                    .collect()
            }
            _ => {
                Err(self
                    .err(rel, format!("expected an integer dtype (a float cannot hold shot numbers), found {desc}")))
            }
        }
    }

    /// A required coordinate (degrees): NaN or a value beyond `limit` is an error naming the shot.
    pub fn coordinates(&self, rel: &str, limit: f64, shot_number: &[u64]) -> Result<Vec<f64>> {
        let v = self.require::<f64>(rel, Shape::PerShot)?;
        self.check_coordinates(rel, &v, limit, |i| shot_number[i])?;
        Ok(v)
    }

    /// Refuse a NaN or a value beyond `limit` in coordinates `v`, naming the shot (`shot(i)`).
    fn check_coordinates(&self, rel: &str, v: &[f64], limit: f64, shot: impl Fn(usize) -> u64) -> Result<()> {
        match v.iter().enumerate().find(|(_, x)| !(x.is_finite() && x.abs() <= limit)) {
            Some((i, x)) => Err(self.err(rel, format!("shot {}: invalid coordinate {x}", shot(i)))),
            None => Ok(()),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Beam contents
// ---------------------------------------------------------------------------------------------

/// A flat waveform array with each shot's (0-based start, count), validated against its length.
pub struct Waveforms {
    pub samples: Vec<f32>,
    pub spans: Vec<(usize, usize)>,
    /// Shots whose record holds a NaN or infinite sample (their waveform reads as `None`).
    pub non_finite: Vec<u64>,
    /// Per shot: whether its record is usable (non-empty and every sample finite).
    usable: Vec<bool>,
}

impl Waveforms {
    /// Shot `i`'s record; `None` when it is empty or holds a NaN or infinite sample.
    pub fn get(&self, i: usize) -> Option<&[f32]> {
        let (s, c) = self.spans[i];
        self.usable[i].then(|| &self.samples[s..s + c])
    }
}

/// Read `<wave>`, `<prefix>_sample_start_index` (1-based) and `<prefix>_sample_count` of the shots
/// the group reads (`shots`, all or the selected ones); `None` when any of the three is absent (the
/// caller decides whether that is an error). A negative count, a start index below 1 or a record
/// past the end of `<wave>` is an error naming the shot.
///
/// Of `<wave>` only the samples of those shots are read: per run of selected shots, one hyperslab
/// from its first record's start to its last record's end (GEDI stores records in shot order, so a
/// run's records are contiguous); every sample when the group reads every shot.
pub fn read_waveforms(g: &BeamGroup, shots: &[u64], wave: &str, prefix: &str) -> Result<Option<Waveforms>> {
    let start_rel = format!("{prefix}_sample_start_index");
    let count_rel = format!("{prefix}_sample_count");
    let (w, s, c) = match (g.dataset(wave)?, g.dataset(&start_rel)?, g.dataset(&count_rel)?) {
        (Some(w), Some(s), Some(c)) => (w, s, c),
        _ => return Ok(None),
    };
    g.check_shape(wave, &w, Shape::Flat)?;
    // Signed reads: a negative value in a signed dataset must not convert to 0 or wrap.
    let start = g.read_ds::<i64>(&start_rel, &s, Shape::PerShot)?;
    let count = g.read_ds::<i64>(&count_rel, &c, Shape::PerShot)?;
    let len = w.shape()[0] as u64;
    // Each shot's record [first, first + n) in the file's flat array.
    let mut records = Vec::with_capacity(shots.len());
    for ((&shot, &s), &c) in shots.iter().zip(&start).zip(&count) {
        if s < 1 {
            return Err(g.err(&start_rel, format!("shot {shot}: index {s}, but GEDI's start index is 1-based")));
        }
        let c = u64::try_from(c).map_err(|_| g.err(&count_rel, format!("shot {shot}: negative count {c}")))?;
        let s = s as u64;
        // 1-based: the shot's samples are [s-1, s-1+c).
        let end = (s - 1).checked_add(c).filter(|&e| e <= len).ok_or_else(|| {
            g.err(&start_rel, format!("shot {shot}: start {s} + {count_rel} {c} - 1 exceeds the {wave} length {len}"))
        })?;
        records.push(((s - 1) as usize, (end - (s - 1)) as usize));
    }
    // The sample ranges to read: everything, or one per run of selected shots.
    let groups: Vec<Range<usize>> = match &g.runs {
        None => std::iter::once(0..records.len()).collect(),
        Some(runs) => {
            let mut at = 0;
            runs.iter()
                .map(|r| {
                    at += r.len();
                    at - r.len()..at
                })
                .collect()
        }
    };
    let mut samples: Vec<f32> = Vec::new();
    let mut spans = vec![(0, 0); records.len()];
    for rows in groups {
        let recs = &records[rows.clone()];
        let lo = recs.iter().filter(|r| r.1 > 0).map(|r| r.0).min();
        let hi = recs.iter().filter(|r| r.1 > 0).map(|r| r.0 + r.1).max();
        let (Some(lo), Some(hi)) = (lo, hi) else { continue };
        let base = samples.len();
        samples.extend(g.read_range::<f32>(wave, &w, lo..hi)?);
        for (span, &(first, n)) in spans[rows].iter_mut().zip(recs) {
            *span = if n > 0 { (base + first - lo, n) } else { (base, 0) };
        }
    }
    let (mut usable, mut non_finite) = (Vec::with_capacity(shots.len()), Vec::new());
    for (&shot, &(first, n)) in shots.iter().zip(&spans) {
        let finite = samples[first..first + n].iter().all(|v| v.is_finite());
        if !finite {
            non_finite.push(shot);
        }
        usable.push(finite && n > 0);
    }
    Ok(Some(Waveforms { samples, spans, non_finite, usable }))
}

/// The L1B datasets of one beam that the shots table uses.
pub struct L1bBeam {
    pub shot_number: Vec<u64>,
    pub delta_time: Option<Vec<f64>>,
    pub rx: Waveforms,
    pub tx: Option<Waveforms>,
    pub elevation_bin0: Vec<f64>,
    pub elevation_lastbin: Vec<f64>,
    pub lat_bin0: Vec<f64>,
    pub lon_bin0: Vec<f64>,
    pub lat_lastbin: Vec<f64>,
    pub lon_lastbin: Vec<f64>,
    pub noise_mean: Option<Vec<f64>>,
    pub noise_stddev: Option<Vec<f64>>,
    pub stale_return_flag: Option<Vec<u8>>,
    pub degrade: Option<Vec<i8>>,
    pub geoid: Option<Vec<f64>>,
}

pub fn read_l1b(g: &BeamGroup) -> Result<L1bBeam> {
    use Shape::PerShot;
    let shot_number = g.shot_numbers()?;
    // Name the first missing waveform dataset (read_waveforms only says "not all present").
    for rel in ["rxwaveform", "rx_sample_start_index", "rx_sample_count"] {
        g.require_dataset(rel)?;
    }
    // The coordinates are required: NaN or out-of-range values are an error naming the field.
    let coord = |rel: &str, limit: f64| g.coordinates(rel, limit, &shot_number);
    Ok(L1bBeam {
        delta_time: g.optional("delta_time", PerShot)?,
        rx: read_waveforms(g, &shot_number, "rxwaveform", "rx")?.ok_or_else(|| g.err("rxwaveform", "missing"))?,
        tx: read_waveforms(g, &shot_number, "txwaveform", "tx")?,
        elevation_bin0: g.require("geolocation/elevation_bin0", PerShot)?,
        elevation_lastbin: g.require("geolocation/elevation_lastbin", PerShot)?,
        lat_bin0: coord("geolocation/latitude_bin0", 90.0)?,
        lon_bin0: coord("geolocation/longitude_bin0", 360.0)?,
        lat_lastbin: coord("geolocation/latitude_lastbin", 90.0)?,
        lon_lastbin: coord("geolocation/longitude_lastbin", 360.0)?,
        noise_mean: g.optional("noise_mean_corrected", PerShot)?,
        noise_stddev: g.optional("noise_stddev_corrected", PerShot)?,
        stale_return_flag: g.optional("stale_return_flag", PerShot)?,
        degrade: g.optional("geolocation/degrade", PerShot)?,
        geoid: g.optional("geophys_corr/geoid", PerShot)?,
        shot_number,
    })
}

/// The bin0 and lastbin coordinates (`[lat_bin0, lon_bin0, lat_lastbin, lon_lastbin]`) of the L1B
/// rows `rows` (sorted, distinct), in their order: the place of a shot without a valid L2A lowest
/// mode. Only the chunks that hold those rows are inflated, so a beam whose shots L2A places
/// costs none of these four datasets (`shot_number`: the beam's, to name a bad shot).
pub fn read_l1b_bins(g: &BeamGroup, rows: &[usize], shot_number: &[u64]) -> Result<Vec<[f64; 4]>> {
    let runs = runs_of(rows);
    let read = |rel: &str, limit: f64| -> Result<Vec<f64>> {
        let ds = g.require_dataset(rel)?;
        g.check_shape(rel, &ds, Shape::PerShot)?;
        let mut v = Vec::with_capacity(rows.len());
        for r in &runs {
            v.extend(g.read_range::<f64>(rel, &ds, r.clone())?);
        }
        g.check_coordinates(rel, &v, limit, |k| shot_number[rows[k]])?;
        Ok(v)
    };
    let lat0 = read("geolocation/latitude_bin0", 90.0)?;
    let lon0 = read("geolocation/longitude_bin0", 360.0)?;
    let lat1 = read("geolocation/latitude_lastbin", 90.0)?;
    let lon1 = read("geolocation/longitude_lastbin", 360.0)?;
    Ok((0..rows.len()).map(|k| [lat0[k], lon0[k], lat1[k], lon1[k]]).collect())
}

/// The cheap per-shot datasets that place the shots of an L2A beam: shot numbers and the lowest
/// mode's coordinates (optional).
pub struct L2aPlaces {
    pub shot_number: Vec<u64>,
    pub lat_lowestmode: Option<Vec<f64>>,
    pub lon_lowestmode: Option<Vec<f64>>,
}

pub fn read_l2a_places(g: &BeamGroup) -> Result<L2aPlaces> {
    use Shape::PerShot;
    Ok(L2aPlaces {
        shot_number: g.shot_numbers()?,
        lat_lowestmode: g.optional("lat_lowestmode", PerShot)?,
        lon_lowestmode: g.optional("lon_lowestmode", PerShot)?,
    })
}

/// The lowest mode (lat, lon) of a shot when both are valid coordinates.
pub fn valid_lowestmode(lat: Option<f64>, lon: Option<f64>) -> Option<(f64, f64)> {
    let (lat, lon) = (lat?, lon?);
    let valid = lat.is_finite() && lon.is_finite() && lat.abs() <= 90.0 && lon.abs() <= 360.0;
    valid.then_some((lat, lon))
}

/// One algorithm's per-shot outputs (each optional).
pub struct L2aAlgorithm {
    pub elev_lowestmode: Option<Vec<f64>>,
    /// RH in metres (converted from the stored centimetres), row-major N×101.
    pub rh: Option<Vec<f32>>,
    pub sensitivity: Option<Vec<f64>>,
    pub quality_flag: Option<Vec<u8>>,
    pub toploc: Option<Vec<f64>>,
    pub botloc: Option<Vec<f64>>,
    pub zcross: Option<Vec<f64>>,
}

/// The L2A datasets of one beam that the shots table uses.
pub struct L2aBeam {
    pub shot_number: Vec<u64>,
    pub delta_time: Option<Vec<f64>>,
    pub quality_flag: Vec<u8>,
    pub degrade_flag: Vec<u8>,
    pub sensitivity: Vec<f64>,
    pub selected_algorithm: Vec<u8>,
    pub elev_lowestmode: Vec<f64>,
    pub lat_lowestmode: Option<Vec<f64>>,
    pub lon_lowestmode: Option<Vec<f64>>,
    /// Metres, row-major N×101.
    pub rh: Vec<f32>,
    pub energy_total: Option<Vec<f64>>,
    pub algorithms: Vec<L2aAlgorithm>,
    pub leaf_off_flag: Option<Vec<u8>>,
    pub leaf_off_doy: Option<Vec<i16>>,
    pub leaf_on_doy: Option<Vec<i16>>,
    pub pft_class: Option<Vec<u8>>,
    pub region_class: Option<Vec<u8>>,
    pub urban_proportion: Option<Vec<u8>>,
    pub landsat_water_persistence: Option<Vec<u8>>,
}

pub fn read_l2a(g: &BeamGroup) -> Result<L2aBeam> {
    use Shape::{PerShot, Rows};
    let algorithms = (1..=N_ALGORITHMS)
        .map(|n| {
            let geo = |name: &str| format!("geolocation/{name}_a{n}");
            let rxp = |name: &str| format!("rx_processing_a{n}/{name}");
            // rh_aN is integer centimetres (int32 in V1, int16 in V2); f64 holds either exactly.
            let rh_cm = g.optional::<f64>(&geo("rh"), Rows(RH_LEN))?;
            Ok(L2aAlgorithm {
                elev_lowestmode: g.optional(&geo("elev_lowestmode"), PerShot)?,
                rh: rh_cm.map(|v| v.into_iter().map(|cm| (cm / 100.0) as f32).collect()),
                sensitivity: g.optional(&geo("sensitivity"), PerShot)?,
                quality_flag: g.optional(&geo("quality_flag"), PerShot)?,
                toploc: g.optional(&rxp("toploc"), PerShot)?,
                botloc: g.optional(&rxp("botloc"), PerShot)?,
                zcross: g.optional(&rxp("zcross"), PerShot)?,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    let lc = |name: &str| format!("land_cover_data/{name}");
    Ok(L2aBeam {
        shot_number: g.shot_numbers()?,
        delta_time: g.optional("delta_time", PerShot)?,
        quality_flag: g.require("quality_flag", PerShot)?,
        degrade_flag: g.require("degrade_flag", PerShot)?,
        sensitivity: g.require("sensitivity", PerShot)?,
        selected_algorithm: g.require("selected_algorithm", PerShot)?,
        elev_lowestmode: g.require("elev_lowestmode", PerShot)?,
        lat_lowestmode: g.optional("lat_lowestmode", PerShot)?,
        lon_lowestmode: g.optional("lon_lowestmode", PerShot)?,
        rh: g.require("rh", Rows(RH_LEN))?,
        energy_total: g.optional("energy_total", PerShot)?,
        algorithms,
        leaf_off_flag: g.optional(&lc("leaf_off_flag"), PerShot)?,
        leaf_off_doy: g.optional(&lc("leaf_off_doy"), PerShot)?,
        leaf_on_doy: g.optional(&lc("leaf_on_doy"), PerShot)?,
        pft_class: g.optional(&lc("pft_class"), PerShot)?,
        region_class: g.optional(&lc("region_class"), PerShot)?,
        urban_proportion: g.optional(&lc("urban_proportion"), PerShot)?,
        landsat_water_persistence: g.optional(&lc("landsat_water_persistence"), PerShot)?,
    })
}

impl L2aBeam {
    /// The lowest-mode (lat, lon) of shot `i` when both are valid coordinates.
    pub fn lowestmode(&self, i: usize) -> Option<(f64, f64)> {
        valid_lowestmode(self.lat_lowestmode.as_ref().map(|v| v[i]), self.lon_lowestmode.as_ref().map(|v| v[i]))
    }
}

/// Every shot's raw transmit record (`txwaveform`) of an L1B file, with its beam's type
/// (`true` = full power, from the beam name); beams without transmit records give none.
pub fn read_transmit_records(path: &Path) -> Result<Vec<(bool, Vec<f32>)>> {
    let g = open_product(path, Product::L1b)?;
    let mut out = Vec::new();
    for name in g.beams()? {
        let Some(b) = g.beam(&name)? else { continue };
        let shots = b.shot_numbers()?;
        let full_power =
            crate::kernels::gedi::BeamType::from_name(&name) == Some(crate::kernels::gedi::BeamType::FullPower);
        if let Some(tx) = read_waveforms(&b, &shots, "txwaveform", "tx")? {
            out.extend((0..shots.len()).filter_map(|i| Some((full_power, tx.get(i)?.to_vec()))));
        }
    }
    Ok(out)
}
