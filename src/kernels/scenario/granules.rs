//! The granules of a world: one per tile and pass, dated on the tile's acquisition day (+7 days
//! per pass, so the season matches the ALS), with GEDI's orbit numbering and V2 file names
//! (docs/scenario.md, "The world"; docs/gedi-products.md §1 for the epoch).

use chrono::{DateTime, Datelike, Duration, TimeZone, Timelike, Utc};

use super::rng::Stream;
use crate::gedi::v2_file_name;

/// Ground speed of the ISS footprint (m/s), for the time between shots.
pub const GROUND_SPEED_M_S: f64 = 7000.0;
/// GEDI epoch (`delta_time` = 0).
const GEDI_EPOCH_UNIX_S: i64 = 1_514_764_800; // 2018-01-01T00:00:00Z
/// A GEDI orbit (s) and one orbit's reference time (orbit 1964 started ≈ 2019-04-18 08:03 UTC).
const ORBIT_S: f64 = 5554.0;
const ORBIT_1964_DELTA_TIME: f64 = 40_809_818.0;

/// The identity of one granule of a world.
#[derive(Debug, Clone, PartialEq)]
pub struct GranuleId {
    pub tile: usize,
    pub pass: usize,
    pub start: DateTime<Utc>,
    pub orbit: u32,
    pub sub_orbit: u8,
    /// GEDI's reference ground track number (the file name's `T` field).
    pub reference_track: u32,
    /// File names.
    pub l1b: String,
    pub l2a: String,
}

/// The granules of `passes_per_tile` passes over each tile (whose acquisition dates are
/// `acquired`; 2022-07-01 when unknown), tile by tile, drawn from `seed`.
pub fn granule_ids(seed: u64, acquired: &[Option<DateTime<Utc>>], passes_per_tile: usize) -> Vec<GranuleId> {
    let fallback = Utc.with_ymd_and_hms(2022, 7, 1, 10, 0, 0).single().expect("valid date");
    let mut granules = Vec::new();
    for (t, acquired) in acquired.iter().enumerate() {
        for pass in 0..passes_per_tile {
            let mut g = Stream::new(seed, &["granule", &t.to_string(), &pass.to_string()]);
            let day = acquired.unwrap_or(fallback).date_naive().and_hms_opt(0, 0, 0).expect("midnight").and_utc();
            let start =
                day + Duration::days(7 * pass as i64) + Duration::seconds(3600 * 6 + (g.uniform() * 43_200.0) as i64);
            let orbit = (1964.0 + ((delta_time(start) - ORBIT_1964_DELTA_TIME) / ORBIT_S).floor()).max(1.0) as u32;
            let sub_orbit = 1 + (g.next_u64() % 4) as u8;
            let reference_track = 1 + (g.next_u64() % 4470) as u32;
            let s = gedi_start(start);
            granules.push(GranuleId {
                tile: t,
                pass,
                start,
                orbit,
                sub_orbit,
                reference_track,
                l1b: v2_file_name("01_B", &s, orbit, sub_orbit, reference_track),
                l2a: v2_file_name("02_A", &s, orbit, sub_orbit, reference_track),
            });
        }
    }
    granules
}

/// Month rule of tests/data/als/PROVENANCE.md: May–October leaf-on, November–April leaf-off.
pub fn is_leaf_off(date: Option<DateTime<Utc>>) -> bool {
    date.map(|d| !(5..=10).contains(&d.month())).unwrap_or(false)
}

/// `YYYYDDDHHMMSS` of a time.
fn gedi_start(t: DateTime<Utc>) -> String {
    format!("{:04}{:03}{:02}{:02}{:02}", t.year(), t.ordinal(), t.hour(), t.minute(), t.second())
}

/// GEDI `delta_time` (s since 2018-01-01T00:00:00 UTC) of a time.
pub fn delta_time(t: DateTime<Utc>) -> f64 {
    (t.timestamp() - GEDI_EPOCH_UNIX_S) as f64 + f64::from(t.timestamp_subsec_micros()) * 1e-6
}
