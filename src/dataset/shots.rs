//! The `shots/` and `granules/` tables (docs/schemas.md): their schemas (`ops::ingest_gedi`
//! writes them), and the shots read back: positions in the ALS CRS, moved by their collocation
//! offsets, and WGS84 positions.

use std::sync::Arc;

use arrow::array::{Array, AsArray, Float64Array, UInt8Array};
use arrow::datatypes::{DataType, Field, Float64Type, Schema, SchemaRef};

use super::list_f32;
use super::offsets::{read_offsets, AppliedOffset};
use super::read::{self, value};
use super::{tables, Dataset};
use crate::error::{Error, Result};
use crate::kernels::gedi::{BeamType, N_ALGORITHMS};
use crate::kernels::sim::Footprint;
use crate::kernels::study::classes::ShotPosition;

/// The names of the `shots/` columns (docs/schemas.md), one constant each; the per-algorithm
/// columns are [`SELECTED`] and [`ALGORITHMS`]. Readers and the writer name columns only through
/// these, so renaming one is a compile error wherever it is used.
pub mod col {
    pub const GRANULE: &str = "granule";
    pub const SHOT_NUMBER: &str = "shot_number";
    pub const BEAM: &str = "beam";
    pub const BEAM_TYPE: &str = "beam_type";
    pub const IN_L1B: &str = "in_l1b";
    pub const IN_L2A: &str = "in_l2a";
    pub const DELTA_TIME: &str = "delta_time";
    pub const LAT_BIN0: &str = "lat_bin0";
    pub const LON_BIN0: &str = "lon_bin0";
    pub const LAT_LASTBIN: &str = "lat_lastbin";
    pub const LON_LASTBIN: &str = "lon_lastbin";
    pub const LAT_LOWESTMODE: &str = "lat_lowestmode";
    pub const LON_LOWESTMODE: &str = "lon_lowestmode";
    pub const X: &str = "x";
    pub const Y: &str = "y";
    pub const XY_SOURCE: &str = "xy_source";
    pub const ELEVATION_BIN0: &str = "elevation_bin0";
    pub const ELEVATION_LASTBIN: &str = "elevation_lastbin";
    pub const RX_WAVEFORM: &str = "rx_waveform";
    pub const RX_SAMPLE_COUNT: &str = "rx_sample_count";
    pub const TX_WAVEFORM: &str = "tx_waveform";
    pub const NOISE_MEAN_CORRECTED: &str = "noise_mean_corrected";
    pub const NOISE_STDDEV_CORRECTED: &str = "noise_stddev_corrected";
    pub const STALE_RETURN_FLAG: &str = "stale_return_flag";
    pub const DEGRADE: &str = "degrade";
    pub const GEOID: &str = "geoid";
    pub const GEOID_OFFSET_USED: &str = "geoid_offset_used";
    pub const VERTICAL_DATUM: &str = "vertical_datum";
    pub const QUALITY_FLAG: &str = "quality_flag";
    pub const DEGRADE_FLAG: &str = "degrade_flag";
    pub const SENSITIVITY: &str = "sensitivity";
    pub const SELECTED_ALGORITHM: &str = "selected_algorithm";
    pub const ELEV_LOWESTMODE: &str = "elev_lowestmode";
    pub const RH: &str = "rh";
    pub const ENERGY_TOTAL: &str = "energy_total";
    pub const LEAF_OFF_FLAG: &str = "leaf_off_flag";
    pub const LEAF_OFF_DOY: &str = "leaf_off_doy";
    pub const LEAF_ON_DOY: &str = "leaf_on_doy";
    pub const PFT_CLASS: &str = "pft_class";
    pub const REGION_CLASS: &str = "region_class";
    pub const URBAN_PROPORTION: &str = "urban_proportion";
    pub const LANDSAT_WATER_PERSISTENCE: &str = "landsat_water_persistence";
}

/// The columns of one L2A algorithm's ground and RH in the `shots/` table.
#[derive(Debug, Clone, Copy)]
pub struct AlgorithmColumns {
    pub elev_lowestmode: &'static str,
    pub rh: &'static str,
    pub sensitivity: &'static str,
    pub quality_flag: &'static str,
}

/// The waveform window columns of one L2A algorithm (`a1`…`a6` only).
#[derive(Debug, Clone, Copy)]
pub struct WindowColumns {
    pub toploc: &'static str,
    pub botloc: &'static str,
    pub zcross: &'static str,
}

/// The selected algorithm's columns (the L2A product's own `elev_lowestmode`, `rh`, …).
pub const SELECTED: AlgorithmColumns = AlgorithmColumns {
    elev_lowestmode: col::ELEV_LOWESTMODE,
    rh: col::RH,
    sensitivity: col::SENSITIVITY,
    quality_flag: col::QUALITY_FLAG,
};

macro_rules! algorithm {
    ($n:literal) => {
        (
            AlgorithmColumns {
                elev_lowestmode: concat!("elev_lowestmode_a", $n),
                rh: concat!("rh_a", $n),
                sensitivity: concat!("sensitivity_a", $n),
                quality_flag: concat!("quality_flag_a", $n),
            },
            WindowColumns {
                toploc: concat!("toploc_a", $n),
                botloc: concat!("botloc_a", $n),
                zcross: concat!("zcross_a", $n),
            },
        )
    };
}

/// Algorithm `a<k>`'s columns at index `k - 1`: one entry per GEDI algorithm, so a change of
/// [`N_ALGORITHMS`] is a compile error here.
pub const ALGORITHMS: [(AlgorithmColumns, WindowColumns); N_ALGORITHMS] =
    [algorithm!(1), algorithm!(2), algorithm!(3), algorithm!(4), algorithm!(5), algorithm!(6)];

/// Typed access to a batch of the `shots/` table: each column by its constant, through
/// [`read::Columns`] (errors name the file and the column), and the table's one policy for the
/// values every reader derives (the beam type, the geoid offset, an algorithm's columns).
#[derive(Clone, Copy)]
pub struct ShotColumns<'a>(pub read::Columns<'a>);

/// One algorithm's per-shot values of a batch ([`AlgorithmColumns`]; its RH list is read by row,
/// `read::Columns::f32_list`).
#[derive(Clone, Copy)]
pub struct AlgorithmArrays<'a> {
    pub elev_lowestmode: &'a Float64Array,
    pub sensitivity: &'a Float64Array,
    pub quality_flag: &'a UInt8Array,
}

impl<'a> ShotColumns<'a> {
    /// The columns to project for [`Self::geoid_offset`].
    pub const GEOID_COLUMNS: [&'static str; 2] = [col::GEOID_OFFSET_USED, col::GEOID];

    /// Row `i`'s beam type: the `beam_type` column, else the beam's name; `None` when neither is
    /// a GEDI beam's.
    pub fn beam_type(&self, i: usize) -> Result<Option<BeamType>> {
        let from_column = read::text(self.0.strings(col::BEAM_TYPE)?, i).and_then(|t| BeamType::from_label(&t));
        Ok(from_column.or_else(|| read::text(self.0.strings(col::BEAM).ok()?, i).and_then(|b| BeamType::from_name(&b))))
    }

    /// Row `i`'s geoid offset (m): `geoid_offset_used`, the one ingest applied (the L1B `geoid`
    /// unless `--geoid-offset` replaced it), else `geoid`; `None` when neither is there.
    pub fn geoid_offset(&self, i: usize) -> Result<Option<f64>> {
        Ok(self.0.f64(col::GEOID_OFFSET_USED, i)?.or(self.0.f64(col::GEOID, i)?))
    }

    /// The columns of one algorithm (`SELECTED` or an entry of `ALGORITHMS`).
    pub fn algorithm(&self, a: &AlgorithmColumns) -> Result<AlgorithmArrays<'a>> {
        Ok(AlgorithmArrays {
            elev_lowestmode: self.0.f64s(a.elev_lowestmode)?,
            sensitivity: self.0.f64s(a.sensitivity)?,
            quality_flag: self.0.u8s(a.quality_flag)?,
        })
    }
}

/// The files of the `shots/` table; an error naming the folder when there is none.
fn shot_files(ds: &Dataset) -> Result<Vec<std::path::PathBuf>> {
    let dir = ds.root().join(tables::SHOTS);
    let files = super::table_files(&dir)
        .map_err(|e| Error::file(&dir, format!("no shots table ({e}): run `gedisim ingest gedi` first")))?;
    if files.is_empty() {
        return Err(Error::file(&dir, "no shots table: run `gedisim ingest gedi` first"));
    }
    Ok(files)
}

/// The shots' ids and positions (`shot_number`, `x`, `y`) from the `shots/` table, each moved by
/// its collocation offset when `<dataset>/offsets/` has one (position + (dx, dy)), with the
/// offset applied.
pub fn shot_footprints(ds: &Dataset) -> Result<Vec<(Footprint, Option<AppliedOffset>)>> {
    let offsets = read_offsets(ds)?;
    let mut out = Vec::new();
    for f in shot_files(ds)? {
        read::for_each_batch(&f, Some(&[col::SHOT_NUMBER, col::X, col::Y]), None, |c| {
            let (sn, x, y) = (c.u64s(col::SHOT_NUMBER)?, c.f64s(col::X)?, c.f64s(col::Y)?);
            for i in 0..c.num_rows() {
                let (Some(sn), Some(x), Some(y)) = (value(sn, i), value(x, i), value(y, i)) else { continue };
                let off = offsets.get(&sn).cloned();
                let (dx, dy) = off.as_ref().map_or((0.0, 0.0), |o| (o.dx, o.dy));
                out.push((Footprint::at(sn.to_string(), x + dx, y + dy), off));
            }
            Ok(())
        })?;
    }
    Ok(out)
}

/// Call `f` with every shot's number and its recorded transmit waveform (`tx_waveform`; `None`
/// when the shot has none).
pub fn for_each_transmit_record(ds: &Dataset, mut f: impl FnMut(u64, Option<Vec<f32>>)) -> Result<()> {
    for file in shot_files(ds)? {
        read::for_each_batch(&file, Some(&[col::SHOT_NUMBER, col::TX_WAVEFORM]), None, |c| {
            let sn = c.u64s(col::SHOT_NUMBER)?;
            for i in 0..c.num_rows() {
                let Some(sn) = value(sn, i) else { continue };
                f(sn, c.f32_list(col::TX_WAVEFORM, i)?);
            }
            Ok(())
        })?;
    }
    Ok(())
}

/// Each shot's number and WGS84 position (lon, lat): the lowest mode when valid, else the mean of
/// the L1B bin0 and last bin; `None` when neither exists.
pub fn shot_positions(ds: &Dataset) -> Result<Vec<ShotPosition>> {
    const COLUMNS: [&str; 7] = [
        col::SHOT_NUMBER,
        col::LAT_LOWESTMODE,
        col::LON_LOWESTMODE,
        col::LAT_BIN0,
        col::LON_BIN0,
        col::LAT_LASTBIN,
        col::LON_LASTBIN,
    ];
    let mut out = Vec::new();
    for f in shot_files(ds)? {
        read::for_each_batch(&f, Some(&COLUMNS), None, |c| {
            let sn = c.u64s(col::SHOT_NUMBER)?;
            let mut cols = Vec::new();
            for n in &COLUMNS[1..] {
                cols.push(arrow::compute::cast(c.column(n)?, &DataType::Float64).map_err(|e| Error::field(&f, *n, e))?);
            }
            let v = |k: usize, i: usize| {
                let a = cols[k].as_primitive::<Float64Type>();
                (a.is_valid(i) && a.value(i).is_finite()).then(|| a.value(i))
            };
            for i in 0..c.num_rows() {
                let lowest = v(0, i).zip(v(1, i)).map(|(lat, lon)| (lon, lat));
                let mean = match (v(2, i), v(3, i), v(4, i), v(5, i)) {
                    (Some(a), Some(b), Some(c), Some(d)) => Some(((b + d) / 2.0, (a + c) / 2.0)),
                    _ => None,
                };
                out.push((sn.value(i), lowest.or(mean)));
            }
            Ok(())
        })?;
    }
    Ok(out)
}

/// The schema of the `shots` table; `epsg` is recorded in its metadata (`gedisim:crs_epsg`).
///
/// Every column is documented in `docs/schemas.md`. Columns from one product are nullable,
/// because a shot may come from the other product only.
pub fn shots_schema(epsg: u32) -> SchemaRef {
    use DataType::*;
    let f = |name: &str, t: DataType, nullable: bool| Field::new(name, t, nullable);
    let mut fields = vec![
        f(col::GRANULE, Utf8, false),
        f(col::SHOT_NUMBER, UInt64, false),
        f(col::BEAM, Utf8, false),
        f(col::BEAM_TYPE, Utf8, false),
        f(col::IN_L1B, Boolean, false),
        f(col::IN_L2A, Boolean, false),
        f(col::DELTA_TIME, Float64, true),
        f(col::LAT_BIN0, Float64, true),
        f(col::LON_BIN0, Float64, true),
        f(col::LAT_LASTBIN, Float64, true),
        f(col::LON_LASTBIN, Float64, true),
        f(col::LAT_LOWESTMODE, Float64, true),
        f(col::LON_LOWESTMODE, Float64, true),
        f(col::X, Float64, true),
        f(col::Y, Float64, true),
        f(col::XY_SOURCE, Utf8, true),
        f(col::ELEVATION_BIN0, Float64, true),
        f(col::ELEVATION_LASTBIN, Float64, true),
        f(col::RX_WAVEFORM, list_f32(), true),
        f(col::RX_SAMPLE_COUNT, UInt32, true),
        f(col::TX_WAVEFORM, list_f32(), true),
        f(col::NOISE_MEAN_CORRECTED, Float64, true),
        f(col::NOISE_STDDEV_CORRECTED, Float64, true),
        f(col::STALE_RETURN_FLAG, UInt8, true),
        f(col::DEGRADE, Int8, true),
        f(col::GEOID, Float64, true),
        f(col::GEOID_OFFSET_USED, Float64, true),
        f(col::VERTICAL_DATUM, Utf8, false),
        f(col::QUALITY_FLAG, UInt8, true),
        f(col::DEGRADE_FLAG, UInt8, true),
        f(col::SENSITIVITY, Float64, true),
        f(col::SELECTED_ALGORITHM, UInt8, true),
        f(col::ELEV_LOWESTMODE, Float64, true),
        f(col::RH, list_f32(), true),
        f(col::ENERGY_TOTAL, Float64, true),
    ];
    for (a, w) in &ALGORITHMS {
        fields.extend([
            f(a.elev_lowestmode, Float64, true),
            f(a.rh, list_f32(), true),
            f(a.sensitivity, Float64, true),
            f(a.quality_flag, UInt8, true),
            f(w.toploc, Float64, true),
            f(w.botloc, Float64, true),
            f(w.zcross, Float64, true),
        ]);
    }
    fields.extend([
        f(col::LEAF_OFF_FLAG, UInt8, true),
        f(col::LEAF_OFF_DOY, Int16, true),
        f(col::LEAF_ON_DOY, Int16, true),
        f(col::PFT_CLASS, UInt8, true),
        f(col::REGION_CLASS, UInt8, true),
        f(col::URBAN_PROPORTION, UInt8, true),
        f(col::LANDSAT_WATER_PERSISTENCE, UInt8, true),
    ]);
    let metadata =
        [(meta::EPSG.to_string(), epsg.to_string()), (meta::VERTICAL.to_string(), VERTICAL_DATUM.to_string())];
    Arc::new(Schema::new(fields).with_metadata(metadata.into_iter().collect()))
}

/// The names of the `granules/` columns (docs/schemas.md), one constant each.
pub mod granules_col {
    pub const GRANULE: &str = "granule";
    pub const GRANULE_KEY: &str = "granule_key";
    pub const L1B_PATH: &str = "l1b_path";
    pub const L1B_HASH: &str = "l1b_hash";
    pub const L2A_PATH: &str = "l2a_path";
    pub const L2A_HASH: &str = "l2a_hash";
    pub const N_SHOTS: &str = "n_shots";
    pub const SHOT_AREA: &str = "shot_area";
    pub const SHOTS_OUTSIDE_AREA: &str = "shots_outside_area";
}

/// Schema of the `granules/` table: one row per ingested granule and the content hashes that key it.
pub fn granules_schema() -> SchemaRef {
    Arc::new(arrow::datatypes::Schema::new(vec![
        Field::new(granules_col::GRANULE, DataType::Utf8, false),
        Field::new(granules_col::GRANULE_KEY, DataType::Utf8, false),
        Field::new(granules_col::L1B_PATH, DataType::Utf8, true),
        Field::new(granules_col::L1B_HASH, DataType::Utf8, true),
        Field::new(granules_col::L2A_PATH, DataType::Utf8, true),
        Field::new(granules_col::L2A_HASH, DataType::Utf8, true),
        Field::new(granules_col::N_SHOTS, DataType::UInt64, false),
        Field::new(granules_col::SHOT_AREA, DataType::Utf8, true),
        Field::new(granules_col::SHOTS_OUTSIDE_AREA, DataType::UInt64, true),
    ]))
}

/// Parquet key-value metadata keys of a `shots/` file.
pub mod meta {
    /// The horizontal CRS of `x`, `y` (the ALS tiles').
    pub const EPSG: &str = "gedisim:crs_epsg";
    /// The vertical reference of every GEDI height ([`super::VERTICAL_DATUM`]).
    pub const VERTICAL: &str = "gedisim:vertical_reference";
}

/// Value of the `vertical_datum` column: every GEDI height stays WGS84-ellipsoidal.
pub const VERTICAL_DATUM: &str = "WGS84 ellipsoid";
