//! Writer of GEDI **V2-layout** L1B and L2A HDF5 granules from in-memory shots.
//!
//! Used by the tests (small V2 fixtures, since no real V2 granule is shared) and by the scenario
//! generator (pseudo-real granules). Dataset names and dtypes follow docs/gedi-products.md §2–§3 for
//! V2: `rx_sample_start_index` is 1-based uint64, `rh` float32 metres, `geolocation/rh_aN` int16
//! centimetres, `land_cover_data/leaf_off_flag` uint8, and so on. Anything the typed shot structs
//! do not cover can be added per beam as an [`ExtraDataset`].

use std::path::Path;
use std::str::FromStr;

use hdf5::types::{H5Type, VarLenUnicode};
use hdf5::{File, Group, Location};

use crate::error::{Error, Result};
use crate::kernels::gedi::{beam_number, BeamType, L1bShot, L2aAlgorithm, L2aShot, LandCover, N_ALGORITHMS, RH_LEN};

/// GPS seconds of the GEDI epoch 2018-01-01T00:00:00 UTC (L1B `ancillary/master_time_epoch`).
pub const MASTER_TIME_EPOCH: f64 = 1_198_800_018.0;

/// Typed values of one dataset, flattened row-major.
#[derive(Debug, Clone, PartialEq)]
pub enum Values {
    U8(Vec<u8>),
    I8(Vec<i8>),
    U16(Vec<u16>),
    I16(Vec<i16>),
    U32(Vec<u32>),
    U64(Vec<u64>),
    I64(Vec<i64>),
    F32(Vec<f32>),
    F64(Vec<f64>),
}

impl Values {
    /// Number of scalar values.
    pub fn len(&self) -> usize {
        match self {
            Values::U8(v) => v.len(),
            Values::I8(v) => v.len(),
            Values::U16(v) => v.len(),
            Values::I16(v) => v.len(),
            Values::U32(v) => v.len(),
            Values::U64(v) => v.len(),
            Values::I64(v) => v.len(),
            Values::F32(v) => v.len(),
            Values::F64(v) => v.len(),
        }
    }

    /// Whether there are no values.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// A dataset to write in a beam group beyond the typed fields (e.g. `rx_processing_a1/rx_cumulative`).
#[derive(Debug, Clone, PartialEq)]
pub struct ExtraDataset {
    /// Path relative to the beam group, e.g. `geolocation/elev_highestreturn_a1`.
    pub path: String,
    /// The values, row-major.
    pub values: Values,
    /// Values per row: 1 for a 1-D dataset, 101 for an N×101 one. `values.len()` must be a multiple.
    pub row_len: usize,
}

impl ExtraDataset {
    /// A 1-D dataset.
    pub fn new(path: impl Into<String>, values: Values) -> Self {
        ExtraDataset { path: path.into(), values, row_len: 1 }
    }
}

/// One beam group to write: its name (`BEAM0101`…), shots in order, and extra datasets.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Beam<S> {
    /// Group name, one of [`super::BEAM_NAMES`].
    pub name: String,
    /// The shots, in acquisition order.
    pub shots: Vec<S>,
    /// Additional datasets written as given.
    pub extra: Vec<ExtraDataset>,
}

impl<S> Beam<S> {
    /// A beam with shots and no extra datasets.
    pub fn new(name: impl Into<String>, shots: Vec<S>) -> Self {
        Beam { name: name.into(), shots, extra: Vec::new() }
    }
}

/// Granule-level identification written to `METADATA/DatasetIdentification`, and how datasets are stored.
#[derive(Debug, Clone, PartialEq)]
pub struct GranuleMeta {
    /// `PGEVersion` attribute ("005" for V2 L1B).
    pub pge_version: String,
    /// `VersionID` attribute ("002" for V2).
    pub version_id: String,
    /// Contiguous (the default: small fixtures) or chunked and compressed as NASA's granules are.
    pub storage: Storage,
}

impl Default for GranuleMeta {
    fn default() -> Self {
        GranuleMeta { pge_version: "005".into(), version_id: "002".into(), storage: Storage::default() }
    }
}

/// How each dataset is stored: contiguous, or in chunks compressed by gzip (deflate).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Storage {
    /// Rows per chunk of a per-shot dataset (`None`: contiguous, no compression).
    pub shot_chunk: Option<usize>,
    /// Samples per chunk of a flat waveform array (`rxwaveform`, `txwaveform`).
    pub sample_chunk: usize,
    /// Rows and columns per chunk of an N×k dataset (`rh`, `geolocation/rh_aN`).
    pub row_chunk: usize,
    /// gzip level (0–9).
    pub gzip: u8,
}

impl Storage {
    /// The layout of the real V1 subsets (tests/data/gedi: h5py's `chunks`, `compression_opts`),
    /// whose subsetter kept NASA's chunk shapes: per-shot datasets in chunks of 554,085 rows (L1B;
    /// 100,000 in L2A), `rxwaveform` in chunks of 14,200 samples (12,800 for `txwaveform`; one size
    /// serves both here), N×101 datasets in chunks of 32 × 32 (`rh`; 46 × 46 for `rh_aN`), gzip 4.
    pub fn nasa() -> Storage {
        Storage { shot_chunk: Some(554_085), sample_chunk: 14_200, row_chunk: 32, gzip: 4 }
    }
}

/// Write a V2-layout L1B granule with the given beams.
pub fn write_l1b_v2(path: &Path, beams: &[Beam<L1bShot>], meta: &GranuleMeta) -> Result<()> {
    write_granule(path, "GEDI_L1B", beams, meta, l1b_datasets)
}

/// Write a V2-layout L2A granule with the given beams.
pub fn write_l2a_v2(path: &Path, beams: &[Beam<L2aShot>], meta: &GranuleMeta) -> Result<()> {
    write_granule(path, "GEDI_L2A", beams, meta, l2a_datasets)
}

/// Write a granule of product `short_name`: per beam, the product's datasets plus the beam's extras.
fn write_granule<S>(
    path: &Path,
    short_name: &str,
    beams: &[Beam<S>],
    meta: &GranuleMeta,
    datasets: fn(&Path, &Beam<S>) -> Result<Vec<ExtraDataset>>,
) -> Result<()> {
    let file = create_granule(path, short_name, meta)?;
    for beam in beams {
        let mut sets = datasets(path, beam)?;
        sets.extend(beam.extra.iter().cloned());
        write_beam(path, &file, &beam.name, &sets, meta.storage)?;
    }
    Ok(())
}

/// The per-shot time fields every beam carries, split as GEDI does.
fn time_datasets(prefix: &str, name: &str, delta_time: &[f64]) -> Vec<ExtraDataset> {
    let beam = beam_number(name).unwrap_or(0);
    vec![
        ExtraDataset::new(format!("{prefix}beam"), Values::U16(vec![beam; delta_time.len()])),
        ExtraDataset::new(format!("{prefix}channel"), Values::U8(vec![0; delta_time.len()])),
        ExtraDataset::new(format!("{prefix}delta_time"), Values::F64(delta_time.to_vec())),
        ExtraDataset::new(
            format!("{prefix}master_int"),
            Values::U32(delta_time.iter().map(|t| t.floor().max(0.0) as u32).collect()),
        ),
        ExtraDataset::new(
            format!("{prefix}master_frac"),
            Values::F64(delta_time.iter().map(|t| t - t.floor()).collect()),
        ),
    ]
}

/// Flatten waveforms into (samples, counts as uint16, 1-based start indices as uint64).
fn pack_waveforms(path: &Path, field: &str, waves: impl Iterator<Item = (u64, Vec<f32>)>) -> Result<[Values; 3]> {
    let (mut flat, mut count, mut start) = (Vec::new(), Vec::new(), Vec::new());
    for (shot, w) in waves {
        let n = u16::try_from(w.len()).map_err(|_| {
            Error::field(path, field, format!("shot {shot}: {} samples exceed the uint16 count", w.len()))
        })?;
        // GEDI's start index is 1-based (docs/gedi-products.md §1).
        start.push(flat.len() as u64 + 1);
        count.push(n);
        flat.extend_from_slice(&w);
    }
    Ok([Values::F32(flat), Values::U16(count), Values::U64(start)])
}

fn l1b_datasets(path: &Path, beam: &Beam<L1bShot>) -> Result<Vec<ExtraDataset>> {
    let s = &beam.shots;
    let f64s = |f: fn(&L1bShot) -> f64| Values::F64(s.iter().map(f).collect());
    let shot_number: Vec<u64> = s.iter().map(|x| x.shot_number).collect();
    let delta_time: Vec<f64> = s.iter().map(|x| x.delta_time).collect();

    let mut out = vec![ExtraDataset::new("shot_number", Values::U64(shot_number.clone()))];
    out.extend(time_datasets("", &beam.name, &delta_time));
    let field = format!("{}/rxwaveform", beam.name);
    let [rx, rx_count, rx_start] =
        pack_waveforms(path, &field, s.iter().map(|x| (x.shot_number, x.rx_waveform.clone())))?;
    let field = format!("{}/txwaveform", beam.name);
    let [tx, tx_count, tx_start] =
        pack_waveforms(path, &field, s.iter().map(|x| (x.shot_number, x.tx_waveform.clone())))?;
    out.extend([
        ExtraDataset::new("rxwaveform", rx),
        ExtraDataset::new("rx_sample_count", rx_count),
        ExtraDataset::new("rx_sample_start_index", rx_start),
        ExtraDataset::new("txwaveform", tx),
        ExtraDataset::new("tx_sample_count", tx_count),
        ExtraDataset::new("tx_sample_start_index", tx_start),
        ExtraDataset::new("noise_mean_corrected", f64s(|x| x.noise_mean_corrected)),
        ExtraDataset::new("noise_stddev_corrected", f64s(|x| x.noise_stddev_corrected)),
        ExtraDataset::new("stale_return_flag", Values::U8(s.iter().map(|x| x.stale_return_flag).collect())),
        ExtraDataset::new("ancillary/master_time_epoch", Values::F64(vec![MASTER_TIME_EPOCH])),
        ExtraDataset::new("geolocation/shot_number", Values::U64(shot_number)),
        ExtraDataset::new("geolocation/delta_time", Values::F64(delta_time.clone())),
        ExtraDataset::new("geolocation/elevation_bin0", f64s(|x| x.elevation_bin0)),
        ExtraDataset::new("geolocation/elevation_lastbin", f64s(|x| x.elevation_lastbin)),
        ExtraDataset::new("geolocation/latitude_bin0", f64s(|x| x.latitude_bin0)),
        ExtraDataset::new("geolocation/longitude_bin0", f64s(|x| x.longitude_bin0)),
        ExtraDataset::new("geolocation/latitude_lastbin", f64s(|x| x.latitude_lastbin)),
        ExtraDataset::new("geolocation/longitude_lastbin", f64s(|x| x.longitude_lastbin)),
        ExtraDataset::new("geolocation/degrade", Values::I8(s.iter().map(|x| x.degrade).collect())),
        ExtraDataset::new(
            "geolocation/digital_elevation_model",
            Values::F32(s.iter().map(|x| x.digital_elevation_model).collect()),
        ),
        ExtraDataset::new("geophys_corr/delta_time", Values::F64(delta_time)),
        ExtraDataset::new("geophys_corr/geoid", Values::F32(s.iter().map(|x| x.geoid).collect())),
    ]);
    Ok(out)
}

/// Check that every shot has `len` values in a list field, and flatten them.
fn flatten_rows<T: Copy>(
    path: &Path,
    field: &str,
    rows: impl Iterator<Item = (u64, Vec<T>)>,
    len: usize,
) -> Result<Vec<T>> {
    let mut flat = Vec::new();
    for (shot, row) in rows {
        if row.len() != len {
            return Err(Error::field(path, field, format!("shot {shot}: {} values, expected {len}", row.len())));
        }
        flat.extend_from_slice(&row);
    }
    Ok(flat)
}

fn l2a_datasets(path: &Path, beam: &Beam<L2aShot>) -> Result<Vec<ExtraDataset>> {
    let s = &beam.shots;
    let u8s = |f: fn(&L2aShot) -> u8| Values::U8(s.iter().map(f).collect());
    let delta_time: Vec<f64> = s.iter().map(|x| x.delta_time).collect();

    let mut out = vec![ExtraDataset::new("shot_number", Values::U64(s.iter().map(|x| x.shot_number).collect()))];
    out.extend(time_datasets("", &beam.name, &delta_time));
    let rh = flatten_rows(path, &format!("{}/rh", beam.name), s.iter().map(|x| (x.shot_number, x.rh.clone())), RH_LEN)?;
    out.extend([
        ExtraDataset::new("quality_flag", u8s(|x| x.quality_flag)),
        ExtraDataset::new("degrade_flag", u8s(|x| x.degrade_flag)),
        ExtraDataset::new("sensitivity", Values::F32(s.iter().map(|x| x.sensitivity).collect())),
        ExtraDataset::new("selected_algorithm", u8s(|x| x.selected_algorithm)),
        ExtraDataset::new("elev_lowestmode", Values::F32(s.iter().map(|x| x.elev_lowestmode).collect())),
        ExtraDataset::new("lat_lowestmode", Values::F64(s.iter().map(|x| x.lat_lowestmode).collect())),
        ExtraDataset::new("lon_lowestmode", Values::F64(s.iter().map(|x| x.lon_lowestmode).collect())),
        ExtraDataset { path: "rh".into(), values: Values::F32(rh), row_len: RH_LEN },
        ExtraDataset::new("energy_total", Values::F32(s.iter().map(|x| x.energy_total).collect())),
        ExtraDataset::new("ancillary/l2a_alg_count", Values::U8(vec![N_ALGORITHMS as u8])),
    ]);
    for a in 0..N_ALGORITHMS {
        let n = a + 1;
        let alg = |x: &L2aShot| x.algorithms[a].clone();
        let algs: Vec<L2aAlgorithm> = s.iter().map(alg).collect();
        let rh_cm = flatten_rows(
            path,
            &format!("{}/geolocation/rh_a{n}", beam.name),
            s.iter().zip(&algs).map(|(x, a)| (x.shot_number, a.rh_cm.clone())),
            RH_LEN,
        )?;
        let f32s = |f: fn(&L2aAlgorithm) -> f32| Values::F32(algs.iter().map(f).collect());
        let f64s = |f: fn(&L2aAlgorithm) -> f64| Values::F64(algs.iter().map(f).collect());
        out.extend([
            ExtraDataset::new(format!("geolocation/elev_lowestmode_a{n}"), f32s(|a| a.elev_lowestmode)),
            ExtraDataset::new(format!("geolocation/lat_lowestmode_a{n}"), f64s(|a| a.lat_lowestmode)),
            ExtraDataset::new(format!("geolocation/lon_lowestmode_a{n}"), f64s(|a| a.lon_lowestmode)),
            ExtraDataset { path: format!("geolocation/rh_a{n}"), values: Values::I16(rh_cm), row_len: RH_LEN },
            ExtraDataset::new(format!("geolocation/sensitivity_a{n}"), f32s(|a| a.sensitivity)),
            ExtraDataset::new(
                format!("geolocation/quality_flag_a{n}"),
                Values::U8(algs.iter().map(|a| a.quality_flag).collect()),
            ),
            ExtraDataset::new(format!("rx_processing_a{n}/toploc"), f32s(|a| a.toploc)),
            ExtraDataset::new(format!("rx_processing_a{n}/botloc"), f32s(|a| a.botloc)),
            ExtraDataset::new(format!("rx_processing_a{n}/zcross"), f32s(|a| a.zcross)),
        ]);
    }
    let lc = |f: fn(&LandCover) -> u8| Values::U8(s.iter().map(|x| f(&x.land_cover)).collect());
    let lc16 = |f: fn(&LandCover) -> i16| Values::I16(s.iter().map(|x| f(&x.land_cover)).collect());
    out.extend([
        ExtraDataset::new("land_cover_data/leaf_off_flag", lc(|l| l.leaf_off_flag)),
        ExtraDataset::new("land_cover_data/leaf_off_doy", lc16(|l| l.leaf_off_doy)),
        ExtraDataset::new("land_cover_data/leaf_on_doy", lc16(|l| l.leaf_on_doy)),
        ExtraDataset::new("land_cover_data/leaf_on_cycle", lc(|l| l.leaf_on_cycle)),
        ExtraDataset::new("land_cover_data/pft_class", lc(|l| l.pft_class)),
        ExtraDataset::new("land_cover_data/region_class", lc(|l| l.region_class)),
        ExtraDataset::new("land_cover_data/urban_proportion", lc(|l| l.urban_proportion)),
        ExtraDataset::new("land_cover_data/landsat_water_persistence", lc(|l| l.landsat_water_persistence)),
    ]);
    Ok(out)
}

fn h5err<'a>(path: &'a Path, what: &str) -> impl Fn(hdf5::Error) -> Error + 'a {
    let what = what.to_string();
    move |e| Error::file(path, format!("{what}: {e}"))
}

/// Create the file with the root `short_name` and `METADATA/DatasetIdentification` attributes.
fn create_granule(path: &Path, short_name: &str, meta: &GranuleMeta) -> Result<File> {
    let file = super::gedi::without_locks().create(path).map_err(h5err(path, "cannot create HDF5 file"))?;
    write_str_attr(&file, "short_name", short_name).map_err(h5err(path, "short_name"))?;
    let ident = file
        .create_group("METADATA")
        .and_then(|g| g.create_group("DatasetIdentification"))
        .map_err(h5err(path, "METADATA/DatasetIdentification"))?;
    let file_name = path.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    for (k, v) in [
        ("PGEVersion", meta.pge_version.as_str()),
        ("VersionID", meta.version_id.as_str()),
        ("fileName", file_name.as_str()),
        ("shortName", short_name),
    ] {
        write_str_attr(&ident, k, v).map_err(h5err(path, k))?;
    }
    Ok(file)
}

/// Write a scalar UTF-8 string attribute.
pub fn write_str_attr(loc: &Location, name: &str, value: &str) -> hdf5::Result<()> {
    let v = VarLenUnicode::from_str(value).map_err(|e| hdf5::Error::from(e.to_string().as_str()))?;
    loc.new_attr::<VarLenUnicode>().shape(()).create(name)?.write_scalar(&v)
}

fn write_beam(path: &Path, file: &File, name: &str, sets: &[ExtraDataset], storage: Storage) -> Result<()> {
    let beam_type = BeamType::from_name(name)
        .ok_or_else(|| Error::field(path, name, "not a GEDI beam name (BEAM0000..BEAM1011)"))?;
    let group = file.create_group(name).map_err(h5err(path, name))?;
    write_str_attr(&group, "description", beam_type.description()).map_err(h5err(path, name))?;
    for d in sets {
        let field = format!("{name}/{}", d.path);
        if d.row_len == 0 || d.values.len() % d.row_len != 0 {
            return Err(Error::field(path, &field, format!("{} values are not rows of {}", d.values.len(), d.row_len)));
        }
        // The flat waveform arrays are chunked by samples, every other dataset by shots.
        let flat = ["rxwaveform", "txwaveform"].contains(&d.path.as_str());
        let chunk = storage.shot_chunk.map(|c| match (flat, d.row_len) {
            (true, _) => [storage.sample_chunk, 1],
            (false, 1) => [c, 1],
            (false, _) => [storage.row_chunk, storage.row_chunk],
        });
        write_stored(&group, &d.path, &d.values, d.row_len, chunk.map(|c| (c, storage.gzip)))
            .map_err(|e| Error::field(path, &field, e))?;
    }
    Ok(())
}

/// Write one dataset (creating intermediate groups), 1-D when `row_len == 1`, else N×row_len;
/// contiguous.
pub fn write_values(root: &Group, rel: &str, values: &Values, row_len: usize) -> hdf5::Result<()> {
    write_stored(root, rel, values, row_len, None)
}

/// [`write_values`], in chunks of `([rows, columns], gzip level)` when given (a chunk is never
/// larger than the dataset; an empty dataset stays contiguous).
fn write_stored(
    root: &Group,
    rel: &str,
    values: &Values,
    row_len: usize,
    chunk: Option<([usize; 2], u8)>,
) -> hdf5::Result<()> {
    fn typed<T: H5Type>(
        parent: &Group,
        name: &str,
        data: &[T],
        row_len: usize,
        chunk: Option<([usize; 2], u8)>,
    ) -> hdf5::Result<()> {
        let rows = data.len() / row_len.max(1);
        let mut builder = parent.new_dataset::<T>();
        if let Some(([r, c], level)) = chunk.filter(|_| rows > 0) {
            builder = builder.chunk(if row_len == 1 { vec![r.min(rows)] } else { vec![r.min(rows), c.min(row_len)] });
            builder = builder.deflate(level);
        }
        let ds = if row_len == 1 {
            builder.shape(rows).create(name)?
        } else {
            builder.shape((rows, row_len)).create(name)?
        };
        if !data.is_empty() {
            ds.write_raw(data)?;
        }
        Ok(())
    }
    let (parent, name) = parent_group(root, rel)?;
    match values {
        Values::U8(v) => typed(&parent, name, v, row_len, chunk),
        Values::I8(v) => typed(&parent, name, v, row_len, chunk),
        Values::U16(v) => typed(&parent, name, v, row_len, chunk),
        Values::I16(v) => typed(&parent, name, v, row_len, chunk),
        Values::U32(v) => typed(&parent, name, v, row_len, chunk),
        Values::U64(v) => typed(&parent, name, v, row_len, chunk),
        Values::I64(v) => typed(&parent, name, v, row_len, chunk),
        Values::F32(v) => typed(&parent, name, v, row_len, chunk),
        Values::F64(v) => typed(&parent, name, v, row_len, chunk),
    }
}

/// The group holding `rel` (created if needed) and the last path component.
fn parent_group<'a>(root: &Group, rel: &'a str) -> hdf5::Result<(Group, &'a str)> {
    let (dirs, name) = rel.rsplit_once('/').unwrap_or(("", rel));
    let mut g = root.clone();
    for part in dirs.split('/').filter(|p| !p.is_empty()) {
        g = if g.link_exists(part) { g.group(part)? } else { g.create_group(part)? };
    }
    Ok((g, name))
}
