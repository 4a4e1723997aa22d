//! The `shots/` and `granules/` tables (docs/schemas.md): their schemas (`ops::ingest_gedi`
//! writes them), and the shots read back: positions in the ALS CRS, moved by their collocation
//! offsets, and WGS84 positions.

use std::sync::Arc;

use arrow::array::{Array, AsArray};
use arrow::datatypes::{DataType, Field, Float64Type, Schema, SchemaRef};

use super::list_f32;
use super::offsets::{read_offsets, AppliedOffset};
use super::read::{self, value};
use super::{tables, Dataset};
use crate::error::{Error, Result};
use crate::kernels::gedi::N_ALGORITHMS;
use crate::kernels::sim::Footprint;
use crate::kernels::study::classes::ShotPosition;

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
        read::for_each_batch(&f, Some(&["shot_number", "x", "y"]), None, |c| {
            let (sn, x, y) = (c.u64s("shot_number")?, c.f64s("x")?, c.f64s("y")?);
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
        read::for_each_batch(&file, Some(&["shot_number", "tx_waveform"]), None, |c| {
            let sn = c.u64s("shot_number")?;
            for i in 0..c.num_rows() {
                let Some(sn) = value(sn, i) else { continue };
                f(sn, c.f32_list("tx_waveform", i)?);
            }
            Ok(())
        })?;
    }
    Ok(())
}

/// Each shot's number and WGS84 position (lon, lat): the lowest mode when valid, else the mean of
/// the L1B bin0 and last bin; `None` when neither exists.
pub fn shot_positions(ds: &Dataset) -> Result<Vec<ShotPosition>> {
    const COLUMNS: [&str; 7] =
        ["shot_number", "lat_lowestmode", "lon_lowestmode", "lat_bin0", "lon_bin0", "lat_lastbin", "lon_lastbin"];
    let mut out = Vec::new();
    for f in shot_files(ds)? {
        read::for_each_batch(&f, Some(&COLUMNS), None, |c| {
            let sn = c.u64s("shot_number")?;
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
        f("granule", Utf8, false),
        f("shot_number", UInt64, false),
        f("beam", Utf8, false),
        f("beam_type", Utf8, false),
        f("in_l1b", Boolean, false),
        f("in_l2a", Boolean, false),
        f("delta_time", Float64, true),
        f("lat_bin0", Float64, true),
        f("lon_bin0", Float64, true),
        f("lat_lastbin", Float64, true),
        f("lon_lastbin", Float64, true),
        f("lat_lowestmode", Float64, true),
        f("lon_lowestmode", Float64, true),
        f("x", Float64, true),
        f("y", Float64, true),
        f("xy_source", Utf8, true),
        f("elevation_bin0", Float64, true),
        f("elevation_lastbin", Float64, true),
        f("rx_waveform", list_f32(), true),
        f("rx_sample_count", UInt32, true),
        f("tx_waveform", list_f32(), true),
        f("noise_mean_corrected", Float64, true),
        f("noise_stddev_corrected", Float64, true),
        f("stale_return_flag", UInt8, true),
        f("degrade", Int8, true),
        f("geoid", Float64, true),
        f("geoid_offset_used", Float64, true),
        f("vertical_datum", Utf8, false),
        f("quality_flag", UInt8, true),
        f("degrade_flag", UInt8, true),
        f("sensitivity", Float64, true),
        f("selected_algorithm", UInt8, true),
        f("elev_lowestmode", Float64, true),
        f("rh", list_f32(), true),
        f("energy_total", Float64, true),
    ];
    for n in 1..=N_ALGORITHMS {
        fields.extend([
            f(&format!("elev_lowestmode_a{n}"), Float64, true),
            f(&format!("rh_a{n}"), list_f32(), true),
            f(&format!("sensitivity_a{n}"), Float64, true),
            f(&format!("quality_flag_a{n}"), UInt8, true),
            f(&format!("toploc_a{n}"), Float64, true),
            f(&format!("botloc_a{n}"), Float64, true),
            f(&format!("zcross_a{n}"), Float64, true),
        ]);
    }
    fields.extend([
        f("leaf_off_flag", UInt8, true),
        f("leaf_off_doy", Int16, true),
        f("leaf_on_doy", Int16, true),
        f("pft_class", UInt8, true),
        f("region_class", UInt8, true),
        f("urban_proportion", UInt8, true),
        f("landsat_water_persistence", UInt8, true),
    ]);
    let metadata = [
        ("gedisim:crs_epsg".to_string(), epsg.to_string()),
        ("gedisim:vertical_reference".to_string(), VERTICAL_DATUM.to_string()),
    ];
    Arc::new(Schema::new(fields).with_metadata(metadata.into_iter().collect()))
}

/// Schema of the `granules/` table: one row per ingested granule and the content hashes that key it.
pub fn granules_schema() -> SchemaRef {
    Arc::new(arrow::datatypes::Schema::new(vec![
        Field::new("granule", DataType::Utf8, false),
        Field::new("granule_key", DataType::Utf8, false),
        Field::new("l1b_path", DataType::Utf8, true),
        Field::new("l1b_hash", DataType::Utf8, true),
        Field::new("l2a_path", DataType::Utf8, true),
        Field::new("l2a_hash", DataType::Utf8, true),
        Field::new("n_shots", DataType::UInt64, false),
        Field::new("shot_area", DataType::Utf8, true),
        Field::new("shots_outside_area", DataType::UInt64, true),
    ]))
}

/// Value of the `vertical_datum` column: every GEDI height stays WGS84-ellipsoidal.
pub const VERTICAL_DATUM: &str = "WGS84 ellipsoid";
