//! GEDI L1B/L2A ingest: the real V1 subsets in tests/data/gedi (provenance there), V2 fixtures
//! written with `gedisim::io::granule`, and bad inputs derived from those fixtures.

use std::path::{Path, PathBuf};
use std::slice::from_ref;

use arrow::array::{Array, AsArray, RecordBatch};
use arrow::compute::concat_batches;
use arrow::datatypes::{DataType, Float64Type, Int16Type, Int8Type, UInt32Type, UInt64Type, UInt8Type};
use gedisim::dataset::shots::shots_schema;
use gedisim::io::granule::{write_l1b_v2, write_l2a_v2, write_values, Beam, GranuleMeta, Values};
use gedisim::kernels::gedi::v2_file_name;
use gedisim::kernels::gedi::{L1bShot, L2aShot};
use gedisim::kernels::geo::projection::Projector;
use gedisim::ops::ingest_gedi::{granule_key, ingest_gedi, read_gedi, GediOptions, IngestReport};
use hdf5::types::{IntSize, TypeDescriptor};

// ---------------------------------------------------------------------------------------------
// Helpers
// ---------------------------------------------------------------------------------------------

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/gedi").join(name)
}

fn v1_l1b() -> PathBuf {
    data("GEDI01_B_2019108080338_O01964_T05337_02_003_01_sub.h5")
}

fn v1_l2a() -> PathBuf {
    data("GEDI02_A_2019108080338_O01964_T05337_02_001_01_sub.h5")
}

/// The one L2A shot of the V1 subset without an L1B waveform (PROVENANCE.md).
const UNPAIRED_L2A_SHOT: u64 = 19640305900108398;

fn read(l1b: &[PathBuf], l2a: &[PathBuf], opts: &GediOptions) -> (RecordBatch, IngestReport) {
    let (batches, report) = read_gedi(l1b, l2a, opts).unwrap_or_else(|e| panic!("{e}"));
    let table = concat_batches(&shots_schema(opts.epsg), &batches).unwrap();
    (table, report)
}

/// The V1 pair read once with default options (the rGEDI files have oversized chunks: reads are slow).
fn v1_default() -> &'static (RecordBatch, IngestReport) {
    static V1: std::sync::OnceLock<(RecordBatch, IngestReport)> = std::sync::OnceLock::new();
    V1.get_or_init(|| read(&[v1_l1b()], &[v1_l2a()], &GediOptions::default()))
}

fn f64s(t: &RecordBatch, name: &str) -> Vec<Option<f64>> {
    t.column_by_name(name).unwrap().as_primitive::<Float64Type>().iter().collect()
}

fn u64s(t: &RecordBatch, name: &str) -> Vec<u64> {
    let a = t.column_by_name(name).unwrap().as_primitive::<UInt64Type>();
    assert_eq!(a.null_count(), 0);
    a.values().to_vec()
}

fn strs(t: &RecordBatch, name: &str) -> Vec<Option<String>> {
    t.column_by_name(name).unwrap().as_string::<i32>().iter().map(|s| s.map(str::to_string)).collect()
}

fn lists(t: &RecordBatch, name: &str) -> Vec<Option<Vec<f32>>> {
    let a = t.column_by_name(name).unwrap().as_list::<i32>();
    (0..a.len())
        .map(|i| a.is_valid(i).then(|| a.value(i).as_primitive::<arrow::datatypes::Float32Type>().values().to_vec()))
        .collect()
}

fn row_of(t: &RecordBatch, shot: u64) -> usize {
    u64s(t, "shot_number").iter().position(|&s| s == shot).unwrap()
}

/// Raw per-beam arrays straight from a file, independent of the ingest.
fn raw<T: hdf5::H5Type>(path: &Path, ds: &str) -> Vec<T> {
    gedisim::io::gedi::without_locks().open(path).unwrap().dataset(ds).unwrap().read_raw::<T>().unwrap()
}

fn beams_of(path: &Path) -> Vec<String> {
    let f = gedisim::io::gedi::without_locks().open(path).unwrap();
    f.member_names().unwrap().into_iter().filter(|n| n.starts_with("BEAM")).collect()
}

fn err_text(l1b: &[PathBuf], l2a: &[PathBuf], opts: &GediOptions) -> String {
    let e = read_gedi(l1b, l2a, opts).expect_err("bad input must give an error").to_string();
    assert!(!e.contains('\n'), "error must be one line: {e}");
    e
}

// ---------------------------------------------------------------------------------------------
// Real V1 files
// ---------------------------------------------------------------------------------------------

#[test]
fn v1_shot_counts_per_beam_and_unpaired_shot() {
    let (t, report) = v1_default().clone();
    let expected = [
        ("BEAM0001", 16, 16),
        ("BEAM0010", 37, 37),
        ("BEAM0011", 59, 60),
        ("BEAM0101", 73, 73),
        ("BEAM0110", 61, 61),
        ("BEAM1000", 38, 38),
        ("BEAM1011", 16, 16),
    ];
    let got: Vec<_> = report.beams.iter().map(|b| (b.beam.as_str(), b.l1b_shots, b.l2a_shots)).collect();
    assert_eq!(got, expected);
    assert_eq!(report.beams.iter().map(|b| b.joined).sum::<usize>(), 300);
    assert_eq!(t.num_rows(), 301);
    assert_eq!(report.rows(), 301);

    // The unpaired L2A shot is kept, with null L1B columns, and reported in one line.
    let b = report.beams.iter().find(|b| b.beam == "BEAM0011").unwrap();
    assert_eq!(b.l2a_only, vec![UNPAIRED_L2A_SHOT]);
    assert!(report.beams.iter().all(|b| b.l1b_only.is_empty()));
    let warnings = report.warnings();
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    let w = &warnings[0];
    for part in ["GEDI02_A_2019108080338", "BEAM0011", "1 L2A shot(s) have no L1B partner", "19640305900108398"] {
        assert!(w.contains(part), "{w}");
    }
    let r = row_of(&t, UNPAIRED_L2A_SHOT);
    let in_l1b = t.column_by_name("in_l1b").unwrap().as_boolean();
    assert!(!in_l1b.value(r));
    assert_eq!(in_l1b.iter().filter(|v| *v == Some(false)).count(), 1);
    assert!(lists(&t, "rx_waveform")[r].is_none());
    assert!(f64s(&t, "elevation_bin0")[r].is_none());
    assert!(lists(&t, "rh")[r].is_some());
    assert_eq!(strs(&t, "xy_source")[r].as_deref(), Some("lowestmode"));
    assert!(f64s(&t, "x")[r].is_some());

    // Beam types come from the group names.
    let beam = strs(&t, "beam");
    let beam_type = strs(&t, "beam_type");
    for (b, ty) in beam.iter().zip(&beam_type) {
        let full = ["BEAM0101", "BEAM0110", "BEAM1000", "BEAM1011"].contains(&b.as_deref().unwrap());
        assert_eq!(ty.as_deref(), Some(if full { "full_power" } else { "coverage" }));
    }
    assert_eq!(strs(&t, "granule")[0].as_deref(), Some("GEDI01_B_2019108080338_O01964_T05337_02_003_01_sub"));
    assert!(strs(&t, "vertical_datum").iter().all(|v| v.as_deref() == Some("WGS84 ellipsoid")));
    assert_eq!(t.schema().metadata().get("gedisim:crs_epsg").map(String::as_str), Some("2154"));
}

#[test]
fn v1_strict_join_rejects_the_unpaired_shot() {
    let opts = GediOptions { strict_join: true, ..Default::default() };
    let e = err_text(&[v1_l1b()], &[v1_l2a()], &opts);
    for part in ["GEDI02_A_2019108080338", "BEAM0011/shot_number", "1 shot(s) have no L1B partner"] {
        assert!(e.contains(part), "{e}");
    }
}

#[test]
fn v1_start_index_is_one_based() {
    let t = v1_default().0.clone();
    let waves = lists(&t, "rx_waveform");
    let mean = f64s(&t, "noise_mean_corrected");
    let energy = f64s(&t, "energy_total");
    let mut max_err = 0.0f64;
    let mut n = 0;
    for ((w, mu), e) in waves.iter().zip(&mean).zip(&energy) {
        let (Some(w), Some(mu), Some(e)) = (w, mu, e) else { continue };
        let sum: f64 = w.iter().map(|&v| f64::from(v) - mu).sum();
        max_err = max_err.max((sum - e).abs());
        n += 1;
    }
    assert_eq!(n, 300);
    eprintln!("energy_total vs Σ(w − μ), 1-based slicing: max |error| {max_err:.4} counts");
    assert!(max_err <= 0.01, "energy_total vs sliced waveform: max |error| {max_err}");

    // Negative control: the same sums with the start index taken as 0-based miss energy_total.
    let l1b = v1_l1b();
    let (mut off, mut total) = (0, 0);
    for beam in beams_of(&l1b) {
        let rx: Vec<f32> = raw(&l1b, &format!("{beam}/rxwaveform"));
        let start: Vec<u64> = raw(&l1b, &format!("{beam}/rx_sample_start_index"));
        let count: Vec<u64> = raw(&l1b, &format!("{beam}/rx_sample_count"));
        let shots: Vec<u64> = raw(&l1b, &format!("{beam}/shot_number"));
        assert_eq!(start[0], 1, "{beam}: the first start index of a 1-based array is 1");
        for i in 0..shots.len() {
            let r = row_of(&t, shots[i]);
            let (s, c) = (start[i] as usize, count[i] as usize);
            if s + c > rx.len() {
                continue; // the last shot has no sample after it
            }
            let sum: f64 = rx[s..s + c].iter().map(|&v| f64::from(v) - mean[r].unwrap()).sum();
            total += 1;
            if (sum - energy[r].unwrap()).abs() > 0.01 {
                off += 1;
            }
        }
    }
    eprintln!("0-based slicing: {off} of {total} shots miss energy_total by more than 0.01");
    assert!(off * 10 >= total * 9, "0-based slicing should not reproduce energy_total ({off} of {total} off)");
}

#[test]
fn v1_rh_relations_and_units() {
    let t = v1_default().0.clone();
    let rh = lists(&t, "rh");
    let rh_a1 = lists(&t, "rh_a1");
    let sel = t.column_by_name("selected_algorithm").unwrap().as_primitive::<UInt8Type>();
    let mut checked = 0;
    for i in 0..t.num_rows() {
        let (Some(rh), Some(a1)) = (&rh[i], &rh_a1[i]) else { panic!("row {i}: rh missing") };
        assert_eq!(rh.len(), 101);
        if sel.value(i) == 1 {
            assert_eq!(rh, a1, "row {i}: rh = rh_a1/100");
            checked += 1;
        }
    }
    assert!(checked >= 300);

    // rh_aN in metres: compare one shot with the file's integer centimetres.
    let l2a = v1_l2a();
    let cm: Vec<i32> = raw(&l2a, "BEAM0101/geolocation/rh_a3");
    let shots: Vec<u64> = raw(&l2a, "BEAM0101/shot_number");
    let r = row_of(&t, shots[5]);
    let a3 = lists(&t, "rh_a3")[r].clone().unwrap();
    let expected: Vec<f32> = cm[5 * 101..6 * 101].iter().map(|&c| (f64::from(c) / 100.0) as f32).collect();
    assert_eq!(a3, expected);
    let rh100 = a3[100];
    assert!(rh100 > 0.5 && rh100 < 60.0, "RH100 {rh100} m is not a height in metres");
    // Every algorithm's RH is present for V1 (all six groups are in the subset).
    for n in 1..=6 {
        assert!(lists(&t, &format!("rh_a{n}")).iter().all(Option::is_some), "rh_a{n}");
    }
}

#[test]
fn v1_positions_are_zero_based_samples() {
    // z(zcross_a1) with the §1 interpolation equals elev_lowestmode_a1: proves the waveform
    // length and the 0-based positions are consistent.
    let t = v1_default().0.clone();
    let (z0, zn) = (f64s(&t, "elevation_bin0"), f64s(&t, "elevation_lastbin"));
    let count = t.column_by_name("rx_sample_count").unwrap().as_primitive::<UInt32Type>();
    let (zc, elev) = (f64s(&t, "zcross_a1"), f64s(&t, "elev_lowestmode_a1"));
    let mut worst = 0.0f64;
    for i in 0..t.num_rows() {
        let (Some(z0), Some(zn), Some(zc), Some(e)) = (z0[i], zn[i], zc[i], elev[i]) else { continue };
        let n = f64::from(count.value(i));
        worst = worst.max((z0 + (zn - z0) * zc / (n - 1.0) - e).abs());
    }
    eprintln!("z(zcross_a1) vs elev_lowestmode_a1: max |error| {worst:.5} m");
    assert!(worst < 0.01, "z(zcross) vs elev_lowestmode_a1: {worst} m");
}

#[test]
fn v1_shot_numbers_are_exact_u64() {
    let t = v1_default().0.clone();
    let got = u64s(&t, "shot_number");
    let l2a = v1_l2a();
    let mut file_shots: Vec<u64> =
        beams_of(&l2a).iter().flat_map(|b| raw::<u64>(&l2a, &format!("{b}/shot_number"))).collect();
    file_shots.sort_unstable();
    let mut sorted = got.clone();
    sorted.sort_unstable();
    assert_eq!(sorted, file_shots);
    assert!(got.iter().all(|&s| s > 1 << 53));
    // The test can fail: a float64 round trip changes some of these values.
    assert!(got.iter().any(|&s| (s as f64) as u64 != s));
}

#[test]
fn v1_has_no_land_cover_and_geoid_defaults_to_l1b() {
    let t = v1_default().0.clone();
    for name in ["leaf_off_flag", "pft_class", "region_class", "urban_proportion", "landsat_water_persistence"] {
        let c = t.column_by_name(name).unwrap();
        assert_eq!(c.null_count(), c.len(), "{name} must be null (unknown) for V1, never 0");
    }
    let geoid = f64s(&t, "geoid");
    let used = f64s(&t, "geoid_offset_used");
    assert_eq!(geoid, used);
    assert_eq!(geoid.iter().filter(|g| g.is_none()).count(), 1, "only the L2A-only shot lacks a geoid");
    // Near 13.7°S 44.1°W the EGM geoid is a few metres below the ellipsoid, not tens.
    assert!(geoid.iter().flatten().all(|g| g.abs() < 30.0));

    let opts = GediOptions { geoid_offset: Some(48.5), ..Default::default() };
    let (t, _) = read(&[v1_l1b()], &[v1_l2a()], &opts);
    assert!(f64s(&t, "geoid_offset_used").iter().all(|g| *g == Some(48.5)));
    assert_eq!(f64s(&t, "geoid"), geoid, "the file's geoid is still recorded");
}

#[test]
fn v1_one_side_alone() {
    let (t, report) = read(&[v1_l1b()], &[], &GediOptions::default());
    assert_eq!(t.num_rows(), 300);
    assert!(report.warnings().is_empty(), "{:?}", report.warnings());
    assert_eq!(t.column_by_name("rh").unwrap().null_count(), 300);
    assert!(strs(&t, "xy_source").iter().all(|s| s.as_deref() == Some("bin_mean")));

    let (t, report) = read(&[], &[v1_l2a()], &GediOptions::default());
    assert_eq!(t.num_rows(), 301);
    assert!(report.warnings().is_empty());
    assert_eq!(t.column_by_name("rx_waveform").unwrap().null_count(), 301);
    assert_eq!(strs(&t, "granule")[0].as_deref(), Some("GEDI02_A_2019108080338_O01964_T05337_02_001_01_sub"));
}

#[test]
fn v1_streaming_gives_one_beam_per_batch() {
    let mut batches = 0;
    let mut rows = 0;
    let report = ingest_gedi(&[v1_l1b()], &[v1_l2a()], &GediOptions::default(), |b| {
        let beams = strs(&b, "beam");
        assert!(beams.iter().all(|x| x == &beams[0]));
        batches += 1;
        rows += b.num_rows();
        Ok(())
    })
    .unwrap();
    assert_eq!((batches, rows), (7, 301));
    assert_eq!(report.rows(), 301);
}

#[test]
fn v1_xy_is_the_projected_lowest_mode() {
    let utm23s = GediOptions { epsg: 32723, ..Default::default() };
    let other = read(&[v1_l1b()], &[v1_l2a()], &utm23s).0;
    for (t, epsg) in [(&v1_default().0, 2154), (&other, 32723)] {
        let p = Projector::new(epsg).unwrap();
        let (lat, lon, x, y) = (f64s(t, "lat_lowestmode"), f64s(t, "lon_lowestmode"), f64s(t, "x"), f64s(t, "y"));
        for i in 0..t.num_rows() {
            let (px, py) = p.project(lon[i].unwrap(), lat[i].unwrap()).unwrap();
            assert_eq!((x[i].unwrap(), y[i].unwrap()), (px, py));
        }
        assert_eq!(t.schema().metadata().get("gedisim:crs_epsg"), Some(&epsg.to_string()));
    }
    // UTM 23S, central meridian 45°W: the shots (44.1°W, 13.7°S) lie ~100 km east of it and
    // ~1 520 km north of the southern false northing of 10 000 km.
    let (x0, y0) = (f64s(&other, "x")[0].unwrap(), f64s(&other, "y")[0].unwrap());
    assert!((590_000.0..610_000.0).contains(&x0), "{x0}");
    assert!((8_470_000.0..8_490_000.0).contains(&y0), "{y0}");
}

// ---------------------------------------------------------------------------------------------
// Projection against independent values
// ---------------------------------------------------------------------------------------------

/// Lambert conformal conic (2 standard parallels) on GRS80, Snyder (1987) eqs. 15-1..15-11,
/// written independently of proj4rs.
fn snyder_lambert93(lon: f64, lat: f64) -> (f64, f64) {
    let a = 6_378_137.0_f64;
    let f = 1.0_f64 / 298.257_222_101;
    let e = (f * (2.0 - f)).sqrt();
    let m = |p: f64| p.cos() / (1.0 - (e * p.sin()).powi(2)).sqrt();
    let t = |p: f64| {
        (std::f64::consts::FRAC_PI_4 - p / 2.0).tan() / ((1.0 - e * p.sin()) / (1.0 + e * p.sin())).powf(e / 2.0)
    };
    let (p1, p2, p0, l0) = (49f64.to_radians(), 44f64.to_radians(), 46.5f64.to_radians(), 3f64.to_radians());
    let n = (m(p1).ln() - m(p2).ln()) / (t(p1).ln() - t(p2).ln());
    let big_f = m(p1) / (n * t(p1).powf(n));
    let rho = |p: f64| a * big_f * t(p).powf(n);
    let theta = n * (lon.to_radians() - l0);
    (700_000.0 + rho(lat.to_radians()) * theta.sin(), 6_600_000.0 + rho(p0) - rho(lat.to_radians()) * theta.cos())
}

#[test]
fn lambert93_known_points() {
    let p = Projector::new(2154).unwrap();
    // The projection origin maps exactly to the false easting/northing.
    let (x, y) = p.project(3.0, 46.5).unwrap();
    assert!((x - 700_000.0).abs() < 1e-6 && (y - 6_600_000.0).abs() < 1e-6, "{x} {y}");
    for (lon, lat) in [(2.3522, 48.8566), (-4.4861, 48.3904), (7.2620, 43.7102), (5.0, 45.0)] {
        let (x, y) = p.project(lon, lat).unwrap();
        let (sx, sy) = snyder_lambert93(lon, lat);
        assert!(
            (x - sx).abs() < 1e-3 && (y - sy).abs() < 1e-3,
            "({lon}, {lat}): proj4rs ({x}, {y}) vs Snyder ({sx}, {sy})"
        );
    }
    // Paris lies ~650 km east and ~6 860 km north in Lambert-93.
    let (x, y) = p.project(2.3522, 48.8566).unwrap();
    assert!((651_000.0..653_000.0).contains(&x) && (6_861_000.0..6_863_000.0).contains(&y), "{x} {y}");
}

#[test]
fn laea_europe_origin() {
    let (x, y) = Projector::new(3035).unwrap().project(10.0, 52.0).unwrap();
    assert!((x - 4_321_000.0).abs() < 1e-6 && (y - 3_210_000.0).abs() < 1e-6, "{x} {y}");
}

// ---------------------------------------------------------------------------------------------
// V2 fixtures (written by gedisim::io::granule)
// ---------------------------------------------------------------------------------------------

const SHOT0: u64 = 29_320_600_200_465_601; // > 2^53, not representable in f64

fn l1b_shot(k: usize, beam: u64) -> L1bShot {
    let n = 40 + 7 * k; // waveform lengths differ per shot
    L1bShot {
        shot_number: SHOT0 + beam * 1_000_000 + k as u64,
        delta_time: 52_000_000.25 + k as f64 * 0.0167,
        rx_waveform: (0..n).map(|i| 200.0 + (i as f32 * 0.37).sin() * 50.0 + k as f32).collect(),
        tx_waveform: (0..128).map(|i| (i as f32 - 64.0).abs() + k as f32).collect(),
        latitude_bin0: 46.5 + k as f64 * 1e-4,
        longitude_bin0: 3.0 + k as f64 * 1e-4,
        latitude_lastbin: 46.5 + k as f64 * 1e-4 - 2e-5,
        longitude_lastbin: 3.0 + k as f64 * 1e-4 + 1e-5,
        elevation_bin0: 400.0 + k as f64,
        elevation_lastbin: 400.0 + k as f64 - 0.15 * (n - 1) as f64,
        noise_mean_corrected: 199.5 + k as f64,
        noise_stddev_corrected: 3.25,
        stale_return_flag: (k % 2) as u8,
        degrade: -(k as i8),
        geoid: 49.75 + k as f32 * 0.125,
        digital_elevation_model: 350.0,
    }
}

fn l2a_shot(k: usize, beam: u64) -> L2aShot {
    let mut s = L2aShot {
        shot_number: SHOT0 + beam * 1_000_000 + k as u64,
        delta_time: 52_000_000.25 + k as f64 * 0.0167,
        degrade_flag: 0,
        energy_total: 1234.5 + k as f32,
        ..Default::default()
    };
    for (a, alg) in s.algorithms.iter_mut().enumerate() {
        alg.elev_lowestmode = 380.0 + a as f32 + k as f32;
        // The first shot's lowest mode is exactly at the Lambert-93 origin.
        alg.lat_lowestmode = 46.5 + k as f64 * 1e-4;
        alg.lon_lowestmode = 3.0 + k as f64 * 1e-4;
        alg.rh_cm = (0..101).map(|i| (i as i16 - 20) * (3 + a as i16) + k as i16).collect();
        alg.sensitivity = 0.9 + 0.01 * a as f32;
        alg.quality_flag = (a % 2) as u8;
        alg.toploc = 10.25 + a as f32;
        alg.botloc = 30.5 + a as f32;
        alg.zcross = 28.75 + a as f32;
    }
    s.select_algorithm(if k.is_multiple_of(2) { 1 } else { 4 });
    s.land_cover.leaf_off_flag = (k % 2) as u8;
    s.land_cover.leaf_off_doy = 300 + k as i16;
    s.land_cover.leaf_on_doy = 100 - k as i16;
    s.land_cover.pft_class = 4;
    s.land_cover.region_class = 1;
    s.land_cover.urban_proportion = k as u8;
    s.land_cover.landsat_water_persistence = 0;
    s
}

struct Fixture {
    _dir: tempfile::TempDir,
    l1b: PathBuf,
    l2a: PathBuf,
    l1b_beams: Vec<Beam<L1bShot>>,
    l2a_beams: Vec<Beam<L2aShot>>,
}

/// Two beams (one coverage, one full power) of three shots each; `drop_l2a` removes L2A shots by
/// (beam index, shot index).
fn fixture(drop_l2a: &[(usize, usize)]) -> Fixture {
    let dir = tempfile::tempdir().unwrap();
    let l1b = dir.path().join(v2_file_name("01_B", "2023100120000", 24561, 2, 1234));
    let l2a = dir.path().join(v2_file_name("02_A", "2023100120000", 24561, 2, 1234));
    let names = ["BEAM0010", "BEAM0101"];
    let l1b_beams: Vec<_> = names
        .iter()
        .enumerate()
        .map(|(b, name)| Beam::new(*name, (0..3).map(|k| l1b_shot(k, b as u64)).collect()))
        .collect();
    let l2a_beams: Vec<_> = names
        .iter()
        .enumerate()
        .map(|(b, name)| {
            let shots = (0..3).filter(|k| !drop_l2a.contains(&(b, *k))).map(|k| l2a_shot(k, b as u64)).collect();
            Beam::new(*name, shots)
        })
        .collect();
    write_l1b_v2(&l1b, &l1b_beams, &GranuleMeta::default()).unwrap();
    write_l2a_v2(&l2a, &l2a_beams, &GranuleMeta::default()).unwrap();
    Fixture { _dir: dir, l1b, l2a, l1b_beams, l2a_beams }
}

fn dtype(path: &Path, ds: &str) -> TypeDescriptor {
    gedisim::io::gedi::without_locks()
        .open(path)
        .unwrap()
        .dataset(ds)
        .unwrap()
        .dtype()
        .unwrap()
        .to_descriptor()
        .unwrap()
}

fn str_attr(loc: &hdf5::Location, name: &str) -> String {
    loc.attr(name).unwrap().read_scalar::<hdf5::types::VarLenUnicode>().unwrap().to_string()
}

#[test]
fn v2_writer_uses_v2_dtypes() {
    let fx = fixture(&[]);
    use TypeDescriptor::*;
    let (u8_, i8_, u16_, i16_, u64_) = (
        Unsigned(IntSize::U1),
        Integer(IntSize::U1),
        Unsigned(IntSize::U2),
        Integer(IntSize::U2),
        Unsigned(IntSize::U8),
    );
    let f32_ = Float(hdf5::types::FloatSize::U4);
    let f64_ = Float(hdf5::types::FloatSize::U8);
    for (ds, t) in [
        ("BEAM0101/shot_number", u64_.clone()),
        ("BEAM0101/rxwaveform", f32_.clone()),
        ("BEAM0101/rx_sample_count", u16_.clone()),
        ("BEAM0101/rx_sample_start_index", u64_.clone()),
        ("BEAM0101/tx_sample_start_index", u64_.clone()),
        ("BEAM0101/stale_return_flag", u8_.clone()),
        ("BEAM0101/geolocation/degrade", i8_.clone()),
        ("BEAM0101/geolocation/elevation_bin0", f64_.clone()),
        ("BEAM0101/geophys_corr/geoid", f32_.clone()),
        ("BEAM0101/noise_mean_corrected", f64_.clone()),
    ] {
        assert_eq!(dtype(&fx.l1b, ds), t, "L1B {ds}");
    }
    for (ds, t) in [
        ("BEAM0101/shot_number", u64_.clone()),
        ("BEAM0101/rh", f32_.clone()),
        ("BEAM0101/geolocation/rh_a1", i16_.clone()),
        ("BEAM0101/geolocation/rh_a6", i16_.clone()),
        ("BEAM0101/land_cover_data/leaf_off_flag", u8_.clone()),
        ("BEAM0101/land_cover_data/leaf_on_doy", i16_.clone()),
        ("BEAM0101/quality_flag", u8_.clone()),
        ("BEAM0101/sensitivity", f32_.clone()),
        ("BEAM0101/elev_lowestmode", f32_.clone()),
        ("BEAM0101/rx_processing_a2/zcross", f32_.clone()),
    ] {
        assert_eq!(dtype(&fx.l2a, ds), t, "L2A {ds}");
    }
    let f = gedisim::io::gedi::without_locks().open(&fx.l2a).unwrap();
    assert_eq!(f.dataset("BEAM0101/rh").unwrap().shape(), vec![3, 101]);
    assert_eq!(str_attr(&f, "short_name"), "GEDI_L2A");
    assert_eq!(str_attr(&f.group("BEAM0101").unwrap(), "description"), "Full power beam");
    assert_eq!(str_attr(&f.group("BEAM0010").unwrap(), "description"), "Coverage beam");
    let ident = f.group("METADATA/DatasetIdentification").unwrap();
    assert_eq!((str_attr(&ident, "PGEVersion"), str_attr(&ident, "VersionID")), ("005".into(), "002".into()));
    let f = gedisim::io::gedi::without_locks().open(&fx.l1b).unwrap();
    assert_eq!(str_attr(&f, "short_name"), "GEDI_L1B");
    let start: Vec<u64> = raw(&fx.l1b, "BEAM0101/rx_sample_start_index");
    assert_eq!(start, vec![1, 41, 88], "1-based, contiguous (counts 40, 47, 54)");
}

#[test]
fn v2_round_trip() {
    let fx = fixture(&[]);
    let (t, report) = read(from_ref(&fx.l1b), from_ref(&fx.l2a), &GediOptions::default());
    assert!(report.warnings().is_empty(), "{:?}", report.warnings());
    assert_eq!(t.num_rows(), 6);
    assert_eq!(strs(&t, "granule")[0].as_deref(), fx.l1b.file_stem().unwrap().to_str());

    let u8s = |name: &str| -> Vec<Option<u8>> {
        t.column_by_name(name).unwrap().as_primitive::<UInt8Type>().iter().collect()
    };
    let i16s = |name: &str| -> Vec<Option<i16>> {
        t.column_by_name(name).unwrap().as_primitive::<Int16Type>().iter().collect()
    };
    let degrade: Vec<Option<i8>> = t.column_by_name("degrade").unwrap().as_primitive::<Int8Type>().iter().collect();
    let counts = t.column_by_name("rx_sample_count").unwrap().as_primitive::<UInt32Type>();
    for (b1, b2) in fx.l1b_beams.iter().zip(&fx.l2a_beams) {
        for (s1, s2) in b1.shots.iter().zip(&b2.shots) {
            let r = row_of(&t, s1.shot_number);
            assert_eq!(strs(&t, "beam")[r].as_deref(), Some(b1.name.as_str()));
            let ty = if b1.name == "BEAM0101" { "full_power" } else { "coverage" };
            assert_eq!(strs(&t, "beam_type")[r].as_deref(), Some(ty));
            assert_eq!(f64s(&t, "delta_time")[r], Some(s1.delta_time));
            assert_eq!(f64s(&t, "lat_bin0")[r], Some(s1.latitude_bin0));
            assert_eq!(f64s(&t, "lon_lastbin")[r], Some(s1.longitude_lastbin));
            assert_eq!(f64s(&t, "elevation_lastbin")[r], Some(s1.elevation_lastbin));
            assert_eq!(lists(&t, "rx_waveform")[r].as_ref(), Some(&s1.rx_waveform));
            assert_eq!(counts.value(r) as usize, s1.rx_waveform.len());
            assert_eq!(lists(&t, "tx_waveform")[r].as_ref(), Some(&s1.tx_waveform));
            assert_eq!(f64s(&t, "noise_mean_corrected")[r], Some(s1.noise_mean_corrected));
            assert_eq!(u8s("stale_return_flag")[r], Some(s1.stale_return_flag));
            assert_eq!(degrade[r], Some(s1.degrade));
            assert_eq!(f64s(&t, "geoid")[r], Some(f64::from(s1.geoid)));
            assert_eq!(f64s(&t, "geoid_offset_used")[r], Some(f64::from(s1.geoid)));

            assert_eq!(u8s("selected_algorithm")[r], Some(s2.selected_algorithm));
            assert_eq!(u8s("quality_flag")[r], Some(s2.quality_flag));
            assert_eq!(f64s(&t, "sensitivity")[r], Some(f64::from(s2.sensitivity)));
            assert_eq!(f64s(&t, "elev_lowestmode")[r], Some(f64::from(s2.elev_lowestmode)));
            assert_eq!(f64s(&t, "energy_total")[r], Some(f64::from(s2.energy_total)));
            assert_eq!(lists(&t, "rh")[r].as_ref(), Some(&s2.rh));
            let sel = s2.selected_algorithm as usize;
            assert_eq!(lists(&t, &format!("rh_a{sel}"))[r].as_ref(), Some(&s2.rh), "rh = rh_a{sel}/100");
            for (a, alg) in s2.algorithms.iter().enumerate() {
                let n = a + 1;
                let metres: Vec<f32> = alg.rh_cm.iter().map(|&c| (f64::from(c) / 100.0) as f32).collect();
                assert_eq!(lists(&t, &format!("rh_a{n}"))[r].as_ref(), Some(&metres));
                assert_eq!(f64s(&t, &format!("elev_lowestmode_a{n}"))[r], Some(f64::from(alg.elev_lowestmode)));
                assert_eq!(f64s(&t, &format!("sensitivity_a{n}"))[r], Some(f64::from(alg.sensitivity)));
                assert_eq!(u8s(&format!("quality_flag_a{n}"))[r], Some(alg.quality_flag));
                assert_eq!(f64s(&t, &format!("toploc_a{n}"))[r], Some(f64::from(alg.toploc)));
                assert_eq!(f64s(&t, &format!("botloc_a{n}"))[r], Some(f64::from(alg.botloc)));
                assert_eq!(f64s(&t, &format!("zcross_a{n}"))[r], Some(f64::from(alg.zcross)));
            }
            let lc = &s2.land_cover;
            assert_eq!(u8s("leaf_off_flag")[r], Some(lc.leaf_off_flag));
            assert_eq!(i16s("leaf_off_doy")[r], Some(lc.leaf_off_doy));
            assert_eq!(i16s("leaf_on_doy")[r], Some(lc.leaf_on_doy));
            assert_eq!(u8s("pft_class")[r], Some(lc.pft_class));
            assert_eq!(u8s("region_class")[r], Some(lc.region_class));
            assert_eq!(u8s("urban_proportion")[r], Some(lc.urban_proportion));
            assert_eq!(u8s("landsat_water_persistence")[r], Some(lc.landsat_water_persistence));
        }
    }
    // The first shot of each beam sits at the Lambert-93 origin: the whole chain gives (700000, 6600000).
    let r = row_of(&t, SHOT0);
    let (x, y) = (f64s(&t, "x")[r].unwrap(), f64s(&t, "y")[r].unwrap());
    assert!((x - 700_000.0).abs() < 1e-6 && (y - 6_600_000.0).abs() < 1e-6, "{x} {y}");
    assert_eq!(strs(&t, "xy_source")[r].as_deref(), Some("lowestmode"));

    // The schema the files produce is the declared one, list columns included.
    assert_eq!(t.schema(), shots_schema(2154));
    assert!(matches!(t.schema().field_with_name("rh").unwrap().data_type(), DataType::List(_)));
}

#[test]
fn v2_int64_shot_numbers_are_accepted() {
    let fx = fixture(&[]);
    let shots: Vec<u64> = raw(&fx.l1b, "BEAM0101/shot_number");
    let f = gedisim::io::gedi::without_locks().open_rw(&fx.l1b).unwrap();
    let g = f.group("BEAM0101").unwrap();
    g.unlink("shot_number").unwrap();
    write_values(&g, "shot_number", &Values::I64(shots.iter().map(|&s| s as i64).collect()), 1).unwrap();
    drop((g, f));
    let (t, report) = read(from_ref(&fx.l1b), from_ref(&fx.l2a), &GediOptions::default());
    assert!(report.warnings().is_empty(), "{:?}", report.warnings());
    assert_eq!(t.num_rows(), 6);
    assert!(shots.iter().all(|s| u64s(&t, "shot_number").contains(s)));
}

// ---------------------------------------------------------------------------------------------
// Bad input: one-line errors naming the file and the field
// ---------------------------------------------------------------------------------------------

fn open_beam(path: &Path, group: &str) -> (hdf5::File, hdf5::Group) {
    let f = gedisim::io::gedi::without_locks().open_rw(path).unwrap();
    let g = f.group(group).unwrap();
    (f, g)
}

#[test]
fn bad_missing_required_dataset() {
    let fx = fixture(&[]);
    {
        let (_f, g) = open_beam(&fx.l1b, "BEAM0101/geolocation");
        g.unlink("elevation_bin0").unwrap();
    }
    let e = err_text(from_ref(&fx.l1b), from_ref(&fx.l2a), &GediOptions::default());
    assert_eq!(e, format!("{}: BEAM0101/geolocation/elevation_bin0: missing", fx.l1b.display()));

    let fx = fixture(&[]);
    {
        let (_f, g) = open_beam(&fx.l2a, "BEAM0010");
        g.unlink("rh").unwrap();
    }
    let e = err_text(from_ref(&fx.l1b), from_ref(&fx.l2a), &GediOptions::default());
    assert_eq!(e, format!("{}: BEAM0010/rh: missing", fx.l2a.display()));

    // Optional datasets may be absent: their columns are null.
    let fx = fixture(&[]);
    {
        let (_f, g) = open_beam(&fx.l2a, "BEAM0010");
        g.unlink("land_cover_data").unwrap();
    }
    let (t, _) = read(from_ref(&fx.l1b), from_ref(&fx.l2a), &GediOptions::default());
    assert_eq!(t.column_by_name("leaf_off_flag").unwrap().null_count(), 3);
}

#[test]
fn bad_beam_arrays_of_different_lengths() {
    let fx = fixture(&[]);
    {
        let (_f, g) = open_beam(&fx.l1b, "BEAM0101/geolocation");
        g.unlink("latitude_bin0").unwrap();
        write_values(&g, "latitude_bin0", &Values::F64(vec![46.5, 46.6]), 1).unwrap();
    }
    let e = err_text(from_ref(&fx.l1b), from_ref(&fx.l2a), &GediOptions::default());
    for part in [
        fx.l1b.display().to_string().as_str(),
        "BEAM0101/geolocation/latitude_bin0",
        "shape [2]",
        "BEAM0101/shot_number has 3 shots",
    ] {
        assert!(e.contains(part), "{e}");
    }
}

#[test]
fn bad_start_index_beyond_the_waveform() {
    let fx = fixture(&[]);
    {
        let (_f, g) = open_beam(&fx.l1b, "BEAM0010");
        g.unlink("rx_sample_start_index").unwrap();
        write_values(&g, "rx_sample_start_index", &Values::U64(vec![1, 41, 89]), 1).unwrap();
    }
    let e = err_text(from_ref(&fx.l1b), from_ref(&fx.l2a), &GediOptions::default());
    for part in
        [fx.l1b.display().to_string().as_str(), "BEAM0010/rx_sample_start_index", "exceeds the rxwaveform length 141"]
    {
        assert!(e.contains(part), "{e}");
    }
}

#[test]
fn bad_nan_coordinate() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(v2_file_name("01_B", "2023100120000", 1, 1, 1));
    let mut shots: Vec<L1bShot> = (0..3).map(|k| l1b_shot(k, 0)).collect();
    shots[1].longitude_lastbin = f64::NAN;
    write_l1b_v2(&path, &[Beam::new("BEAM1000", shots.clone())], &GranuleMeta::default()).unwrap();
    let e = err_text(from_ref(&path), &[], &GediOptions::default());
    assert_eq!(
        e,
        format!(
            "{}: BEAM1000/geolocation/longitude_lastbin: shot {}: invalid coordinate NaN",
            path.display(),
            shots[1].shot_number
        )
    );
}

#[test]
fn bad_l1b_shot_without_l2a_partner() {
    let fx = fixture(&[(1, 2)]);
    let (t, report) = read(from_ref(&fx.l1b), from_ref(&fx.l2a), &GediOptions::default());
    assert_eq!(t.num_rows(), 6, "the unpaired shot is kept, not dropped");
    let warnings = report.warnings();
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    let w = &warnings[0];
    assert!(!w.contains('\n'));
    let lost = fx.l1b_beams[1].shots[2].shot_number;
    for part in [
        fx.l1b.display().to_string().as_str(),
        "BEAM0101",
        "1 L1B shot(s) have no L2A partner",
        lost.to_string().as_str(),
    ] {
        assert!(w.contains(part), "{w}");
    }
    let r = row_of(&t, lost);
    assert!(lists(&t, "rh")[r].is_none() && lists(&t, "rx_waveform")[r].is_some());
    assert_eq!(strs(&t, "xy_source")[r].as_deref(), Some("bin_mean"));

    let e = err_text(from_ref(&fx.l1b), from_ref(&fx.l2a), &GediOptions { strict_join: true, ..Default::default() });
    assert!(e.contains("BEAM0101/shot_number") && e.contains("1 shot(s) have no L2A partner"), "{e}");
}

#[test]
fn bad_float_shot_numbers_and_swapped_products() {
    let fx = fixture(&[]);
    {
        let (_f, g) = open_beam(&fx.l2a, "BEAM0010");
        g.unlink("shot_number").unwrap();
        write_values(&g, "shot_number", &Values::F64(vec![1.0, 2.0, 3.0]), 1).unwrap();
    }
    let e = err_text(&[], from_ref(&fx.l2a), &GediOptions::default());
    assert!(e.contains("BEAM0010/shot_number: expected an integer dtype"), "{e}");

    let fx = fixture(&[]);
    let e = err_text(from_ref(&fx.l2a), from_ref(&fx.l1b), &GediOptions::default());
    assert!(e.contains("short_name: file is GEDI_L2A but was given as GEDI_L1B"), "{e}");

    let e = err_text(from_ref(&fx.l1b), &[], &GediOptions { epsg: 4242, ..Default::default() });
    assert!(e.contains("EPSG:4242"), "{e}");

    let dir = tempfile::tempdir().unwrap();
    let junk = dir.path().join("junk.h5");
    std::fs::write(&junk, b"not hdf5").unwrap();
    let e = err_text(from_ref(&junk), &[], &GediOptions::default());
    assert!(e.starts_with(&format!("{}: cannot open as HDF5", junk.display())), "{e}");
}

// ---------------------------------------------------------------------------------------------
// Pairing of L1B and L2A files
// ---------------------------------------------------------------------------------------------

#[test]
fn granule_keys_pair_v1_and_v2_names() {
    assert_eq!(granule_key(&v1_l1b()), "2019108080338_O01964_T05337_02");
    assert_eq!(granule_key(&v1_l1b()), granule_key(&v1_l2a()));
    let v2 = Path::new("GEDI01_B_2019170155833_O02932_02_T02267_02_005_01_V002.h5");
    let v2a = Path::new("GEDI02_A_2019170155833_O02932_02_T02267_02_003_01_V002.h5");
    assert_eq!(granule_key(v2), "2019170155833_O02932_02_T02267_02");
    assert_eq!(granule_key(v2), granule_key(v2a));
    assert_eq!(granule_key(Path::new("/x/my_file.h5")), "my_file");
}

#[test]
fn files_without_a_partner_file_are_noted_once() {
    let fx = fixture(&[]);
    // A V2 L1B and the V1 L2A: different granules, so nothing joins.
    let (t, report) = read(from_ref(&fx.l1b), &[v1_l2a()], &GediOptions::default());
    assert_eq!(t.num_rows(), 6 + 301);
    let warnings = report.warnings();
    assert_eq!(warnings.len(), 2, "{warnings:?}");
    assert!(warnings[0].starts_with(&format!("{}: no L2A file of granule", fx.l1b.display())), "{}", warnings[0]);
    assert!(warnings[1].starts_with(&format!("{}: no L1B file of granule", v1_l2a().display())), "{}", warnings[1]);
}
