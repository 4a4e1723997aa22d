//! Seeded mutation fuzzing of every file format gedisim reads: small files made from the real
//! bundled data (LAZ and LAS points of a LiDAR HD tile, a COPC tile written by copclib, an
//! L1B/L2A granule pair of real shots, a land-cover GeoTIFF, a footprint CSV), truncated,
//! bit-flipped and with fields overwritten by extreme values. Every case must end in `Ok` or a
//! one-line error: no panic, no abort, and for ALS ingest no table file without its registry row
//! and no temporary file.
//!
//! `cargo test --test fuzz` runs a bounded number of cases per format (seconds). More cases, a
//! nightly-style run: `GEDISIM_FUZZ_CASES=20000 cargo test --test fuzz` (cases per format);
//! `GEDISIM_FUZZ_SEED` replays another seed. A failing case prints its seed and mutation.

mod common;

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};

use rand_chacha::rand_core::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

use common::{data, files_with_suffix};
use gedisim::error::Error;

fn cases(default: usize) -> usize {
    std::env::var("GEDISIM_FUZZ_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

fn seed() -> u64 {
    std::env::var("GEDISIM_FUZZ_SEED").ok().and_then(|v| v.parse().ok()).unwrap_or(20)
}

/// One mutation of `bytes`, described for the failure message. `hot` is the byte range that holds
/// the format's header fields (where overwrites aim half of the time).
fn mutate(rng: &mut ChaCha8Rng, bytes: &[u8], hot: usize) -> (Vec<u8>, String) {
    let mut b = bytes.to_vec();
    let pick = |rng: &mut ChaCha8Rng, n: usize| (rng.next_u64() % n.max(1) as u64) as usize;
    match rng.next_u32() % 4 {
        0 => {
            let at = pick(rng, b.len());
            b.truncate(at);
            (b, format!("truncate at {at}"))
        }
        1 => {
            let flips = 1 + pick(rng, 8);
            let mut at = Vec::new();
            for _ in 0..flips {
                let i = pick(rng, b.len());
                b[i] ^= 1 << (rng.next_u32() % 8);
                at.push(i);
            }
            (b, format!("bit flips at {at:?}"))
        }
        _ => {
            let width = [1usize, 2, 4, 8][pick(rng, 4)];
            let region = if rng.next_u32().is_multiple_of(2) { hot.min(b.len()) } else { b.len() };
            let at = pick(rng, region.saturating_sub(width));
            let value: u64 = match rng.next_u32() % 5 {
                0 => 0,
                1 => u64::MAX,
                2 => 1 << (rng.next_u32() % 64),
                3 => f64::NAN.to_bits(),
                _ => rng.next_u64(),
            };
            let end = (at + width).min(b.len());
            let n = end - at;
            b[at..end].copy_from_slice(&value.to_le_bytes()[..n]);
            (b, format!("overwrite {width} bytes at {at} with {value:#x}"))
        }
    }
}

/// Run `cases` mutations of `original` through `read` (a file path in, `Ok` or an error out).
/// Panics name the seed, the case and the mutation.
fn fuzz(name: &str, original: &[u8], hot: usize, cases: usize, read: impl Fn(&Path, usize) -> Result<(), Error>) {
    let dir = tempfile::tempdir().unwrap();
    let ext = Path::new(name).extension().and_then(|e| e.to_str()).unwrap_or("bin");
    let mut rng = ChaCha8Rng::seed_from_u64(seed());
    let (mut ok, mut failed) = (0, 0);
    for case in 0..cases {
        let (bytes, what) = mutate(&mut rng, original, hot);
        let path = dir.path().join(format!("case{case}.{ext}"));
        std::fs::write(&path, &bytes).unwrap();
        let t0 = std::time::Instant::now();
        let result = catch_unwind(AssertUnwindSafe(|| read(&path, case)));
        if t0.elapsed().as_secs_f64() > 0.3 {
            eprintln!(
                "SLOW {name} case {case} ({what}): {:.2} s {:?}",
                t0.elapsed().as_secs_f64(),
                result.as_ref().map(|r| r.as_ref().err().map(|e| e.to_string()))
            );
        }
        match result {
            Ok(Ok(())) => ok += 1,
            Ok(Err(e)) => {
                let line = e.to_string();
                assert!(!line.contains('\n'), "{name} case {case} ({what}): a multi-line error: {line}");
                failed += 1;
            }
            Err(_) => {
                let keep = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("fuzz-{}-{case}-{name}", seed()));
                std::fs::write(&keep, &bytes).unwrap();
                panic!("{name}: case {case} of seed {} ({what}) panicked; the file is {}", seed(), keep.display())
            }
        }
        let _ = std::fs::remove_file(&path);
    }
    eprintln!("{name}: {cases} cases, {ok} read, {failed} rejected with one line");
    assert_eq!(ok + failed, cases);
}

/// The first `n` points of a real LiDAR HD tile as a small LAS or LAZ file (its header and CRS
/// records kept).
fn small_tile(dir: &Path, n: u64, compressed: bool) -> PathBuf {
    let mut reader = las::Reader::from_path(data("als/pdal-ign-plugin_mnx_input_crop_2.laz")).unwrap();
    let mut header = reader.header().clone().into_raw().unwrap();
    if !compressed {
        header.point_data_record_format &= 0x3f;
    }
    let mut builder = las::Builder::new(header).unwrap();
    // Its records but the LASzip one, which the writer makes anew.
    builder.vlrs = reader.header().vlrs().iter().filter(|v| v.user_id != "laszip encoded").cloned().collect();
    builder.point_format.is_compressed = compressed;
    let header = builder.into_header().unwrap();
    let path = dir.join(if compressed { "small.laz" } else { "small.las" });
    let mut writer = las::Writer::from_path(&path, header).unwrap();
    for p in reader.read_points(n).unwrap().points() {
        writer.write_point(p.unwrap()).unwrap();
    }
    writer.close().unwrap();
    path
}

/// Read every point; and for every tenth case, ingest into a fresh dataset and check that nothing
/// partial is left.
fn read_tile(path: &Path, case: usize) -> Result<(), Error> {
    gedisim::io::las::read_points(path)?;
    if case.is_multiple_of(10) {
        let ds_dir = path.with_extension("ds");
        let ds = gedisim::dataset::Dataset::create(&ds_dir)?;
        let opts = gedisim::ops::ingest_als::AlsOptions { epsg: Some(2154), ..Default::default() };
        let result = gedisim::ops::ingest_als::ingest_tiles(
            &ds,
            &[path.to_path_buf()],
            &opts,
            &gedisim::ops::progress::NoProgress,
        );
        assert!(files_with_suffix(&ds_dir, ".tmp").is_empty(), "temporary left: {result:?}");
        if result.is_err() {
            assert!(files_with_suffix(&ds_dir.join("tiles"), ".parquet").is_empty(), "a tile row after an error");
        }
        std::fs::remove_dir_all(&ds_dir).unwrap();
        result?;
    }
    Ok(())
}

#[test]
fn fuzz_laz_tiles() {
    let dir = tempfile::tempdir().unwrap();
    let tile = small_tile(dir.path(), 3000, true);
    let original = std::fs::read(&tile).unwrap();
    read_tile(&tile, 0).expect("the unmutated tile reads");
    let offset = u32::from_le_bytes(original[96..100].try_into().unwrap()) as usize;
    fuzz("small.laz", &original, offset + 64, cases(1500), read_tile);
}

/// A small COPC tile written by copclib (4000 real points, 102 nodes, 8 hierarchy pages) mutated
/// in its header and VLRs or in its hierarchy (the EVLRs at its end), then read whole and around
/// two footprints. Fewer cases than the other formats: each read starts 102 LAZ chunks, whose
/// decoders set up their models anew (≈ 70 ms a case).
#[test]
fn fuzz_copc_tiles() {
    use gedisim::io::copc::{Attributes, CopcTile};
    use gedisim::kernels::geo::cells::Cells;
    let original = std::fs::read(data("als-copc/small-4000.depth3-paged.copc.laz")).unwrap();
    let header = las::raw::Header::read_from(original.as_slice()).unwrap();
    let evlrs = header.evlr.expect("COPC has EVLRs").start_of_first_evlr as usize;
    let cells = Cells::around([(689_410.0, 6_735_460.0), (689_440.0, 6_735_490.0)], 18.4);
    let read = |path: &Path, _: usize| -> Result<(), Error> {
        let tile = CopcTile::open(path)?;
        tile.read(Some(&cells), Attributes::All)?;
        tile.read(None, Attributes::WithoutPulseIdentity)?;
        Ok(())
    };
    let dir = tempfile::tempdir().unwrap();
    let whole = dir.path().join("small.copc.laz");
    std::fs::write(&whole, &original).unwrap();
    read(&whole, 0).expect("the unmutated tile reads");
    // The header and VLRs (hot: the first 1000 bytes) as they are, and the hierarchy moved to the
    // front so that `mutate`'s overwrites aim at it: mutated, then put back.
    fuzz("small.copc.laz", &original, 1000, cases(250), read);
    let (points, hierarchy) = original.split_at(evlrs);
    let rotated = [hierarchy, points].concat();
    fuzz("hierarchy.copc.laz", &rotated, hierarchy.len(), cases(250), |path, case| {
        let mut b = std::fs::read(path).unwrap();
        if b.len() >= hierarchy.len() {
            b.rotate_left(hierarchy.len());
        }
        let back = path.with_extension("back.laz");
        std::fs::write(&back, &b).unwrap();
        let r = read(&back, case);
        let _ = std::fs::remove_file(&back);
        r
    });
}

#[test]
fn fuzz_las_tiles() {
    let dir = tempfile::tempdir().unwrap();
    let tile = small_tile(dir.path(), 2000, false);
    let original = std::fs::read(&tile).unwrap();
    read_tile(&tile, 0).expect("the unmutated tile reads");
    let offset = u32::from_le_bytes(original[96..100].try_into().unwrap()) as usize;
    fuzz("small.las", &original, offset, cases(1500), read_tile);
}

/// A granule pair of real shots (the first `per_beam` of each beam of the bundled pair), written in
/// the V2 layout.
fn small_granule(dir: &Path, per_beam: usize) -> (PathBuf, PathBuf) {
    let l1b = dir.join("GEDI01_B_2019108080338_O01964_T05337_02_003_01_sub.h5");
    let l2a = dir.join("GEDI02_A_2019108080338_O01964_T05337_02_001_01_sub.h5");
    let (mut b1, mut b2) = (Vec::new(), Vec::new());
    let mut shots = common::nasa::load_real_shots();
    shots.sort_by(|a, b| (&a.beam, a.shot_number).cmp(&(&b.beam, b.shot_number)));
    for beam in ["BEAM0101", "BEAM1000"] {
        let s: Vec<_> = shots.iter().filter(|s| s.beam == beam).take(per_beam).collect();
        b1.push(gedisim::io::granule::Beam::new(beam, s.iter().map(|s| l1b_shot(s)).collect()));
        b2.push(gedisim::io::granule::Beam::new(beam, s.iter().map(|s| l2a_shot(s)).collect()));
    }
    let meta = gedisim::io::granule::GranuleMeta::default();
    gedisim::io::granule::write_l1b_v2(&l1b, &b1, &meta).unwrap();
    gedisim::io::granule::write_l2a_v2(&l2a, &b2, &meta).unwrap();
    (l1b, l2a)
}

fn l1b_shot(s: &common::nasa::RealShot) -> gedisim::kernels::gedi::L1bShot {
    gedisim::kernels::gedi::L1bShot {
        shot_number: s.shot_number,
        rx_waveform: s.wave.clone(),
        tx_waveform: s.tx.clone(),
        latitude_bin0: s.geo.latitude_bin0,
        longitude_bin0: s.geo.longitude_bin0,
        latitude_lastbin: s.geo.latitude_lastbin,
        longitude_lastbin: s.geo.longitude_lastbin,
        elevation_bin0: s.geo.elevation_bin0,
        elevation_lastbin: s.geo.elevation_lastbin,
        noise_mean_corrected: s.noise.mean,
        noise_stddev_corrected: s.noise.stddev,
        ..Default::default()
    }
}

fn l2a_shot(s: &common::nasa::RealShot) -> gedisim::kernels::gedi::L2aShot {
    let lat = (s.geo.latitude_bin0 + s.geo.latitude_lastbin) / 2.0;
    let lon = (s.geo.longitude_bin0 + s.geo.longitude_lastbin) / 2.0;
    let mut shot = gedisim::kernels::gedi::L2aShot { shot_number: s.shot_number, ..Default::default() };
    for (a, nasa) in shot.algorithms.iter_mut().zip(&s.nasa) {
        a.lat_lowestmode = lat;
        a.lon_lowestmode = lon;
        a.elev_lowestmode = (s.geo.elevation_lastbin + 10.0) as f32;
        a.rh_cm = nasa.rh_cm.iter().map(|&cm| cm as i16).collect();
        a.quality_flag = 1;
    }
    shot.select_algorithm(1);
    shot
}

fn read_granule(l1b: Option<&Path>, l2a: Option<&Path>) -> Result<(), Error> {
    let opts = gedisim::ops::ingest_gedi::GediOptions::default();
    let as_list = |p: Option<&Path>| p.map(|p| vec![p.to_path_buf()]).unwrap_or_default();
    gedisim::ops::ingest_gedi::read_gedi(&as_list(l1b), &as_list(l2a), &opts).map(|_| ())
}

#[test]
fn fuzz_gedi_granules() {
    read_in_children();
    let dir = tempfile::tempdir().unwrap();
    let (l1b, l2a) = small_granule(dir.path(), 4);
    read_granule(Some(&l1b), Some(&l2a)).expect("the unmutated pair reads");
    // The file name carries the granule id, so mutated copies keep it (one folder per case).
    for (name, original, other) in [("L1B", &l1b, &l2a), ("L2A", &l2a, &l1b)] {
        let bytes = std::fs::read(original).unwrap();
        let file_name = original.file_name().unwrap().to_owned();
        let n = cases(400);
        fuzz(&format!("{name}.h5"), &bytes, 4096, n, |path, case| {
            let case_dir = dir.path().join(format!("{name}-{case}"));
            std::fs::create_dir_all(&case_dir).unwrap();
            let named = case_dir.join(&file_name);
            std::fs::rename(path, &named).unwrap();
            let r = if name == "L1B" {
                read_granule(Some(&named), Some(other))
            } else {
                read_granule(Some(other), Some(&named))
            };
            std::fs::remove_dir_all(&case_dir).unwrap();
            r
        });
    }
}

/// As the command line does: a crash or a hang of the HDF5 library ends the child, not this test.
/// The stall limit is short: these granules read in milliseconds.
fn read_in_children() {
    use gedisim::ops::ingest_gedi::child;
    let exe = PathBuf::from(env!("CARGO_BIN_EXE_gedisim"));
    child::read_in_children(child::Reader { exe, stall_limit: std::time::Duration::from_secs(10) });
}

/// Case `case` of `seed` of [`fuzz`] over `original` (the L1B is fuzzed first, with `hot` 4096).
fn replay(seed: u64, case: usize, original: &[u8]) -> Vec<u8> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..case).for_each(|_| drop(mutate(&mut rng, original, 4096)));
    mutate(&mut rng, original, 4096).0
}

/// Seed 7's L1B case 544 (byte 895, in a global-heap reference, set to 0xff) crashed HDF5 1.10.8
/// inside `ingest gedi`: now the child that reads the granule dies, and the command ends with one
/// line naming that file, exit code 1 and no shots file.
#[test]
fn a_granule_that_crashes_hdf5_ends_as_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let (l1b, l2a) = small_granule(dir.path(), 4);
    std::fs::write(&l1b, replay(7, 544, &std::fs::read(&l1b).unwrap())).unwrap();
    let ds = dir.path().join("ds");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_gedisim"))
        .args(["ingest", "gedi", "--out"])
        .arg(&ds)
        .arg("--l1b")
        .arg(&l1b)
        .arg("--l2a")
        .arg(&l2a)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    let lines: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error")).collect();
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert_eq!(lines.len(), 1, "{stderr}");
    assert!(lines[0].contains(&*l1b.display().to_string()), "{stderr}");
    if hdf5::library_version() == (1, 10, 8) {
        assert!(lines[0].contains("the HDF5 library crashed reading this file (signal 11, SIGSEGV)"), "{stderr}");
    }
    assert!(files_with_suffix(&ds.join("shots"), "").is_empty(), "a shots file was left behind");
}

/// Seed 7's L1B case 3067 made HDF5 1.10.8 loop for ever reading the `short_name` attribute (in
/// `H5HG_read`, the global heap): the child is stopped after the stall limit, and the read ends
/// with one line naming the L1B.
#[test]
fn a_granule_that_hangs_hdf5_ends_as_one_line() {
    read_in_children();
    let dir = tempfile::tempdir().unwrap();
    let (l1b, l2a) = small_granule(dir.path(), 4);
    std::fs::write(&l1b, replay(7, 3067, &std::fs::read(&l1b).unwrap())).unwrap();
    let err = read_granule(Some(&l1b), Some(&l2a)).expect_err("the corrupt L1B does not read").to_string();
    assert!(!err.contains('\n'), "{err}");
    assert!(err.starts_with(&*l1b.display().to_string()), "{err}");
    if hdf5::library_version() == (1, 10, 8) {
        assert!(err.contains("made no progress reading this file for 10 s and was stopped"), "{err}");
    }
}

#[test]
fn fuzz_landcover_geotiff() {
    use tiff::encoder::{colortype, TiffEncoder};
    use tiff::tags::Tag;
    let dir = tempfile::tempdir().unwrap();
    let tif = dir.path().join("clc.tif");
    let mut enc = TiffEncoder::new(std::fs::File::create(&tif).unwrap()).unwrap();
    let mut img = enc.new_image::<colortype::Gray8>(40, 30).unwrap();
    img.rows_per_strip(4).unwrap();
    img.encoder().write_tag(Tag::ModelPixelScaleTag, &[100.0f64, 100.0, 0.0][..]).unwrap();
    img.encoder().write_tag(Tag::ModelTiepointTag, &[0.0f64, 0.0, 0.0, 3_800_000.0, 2_600_000.0, 0.0][..]).unwrap();
    let geokeys: [u16; 16] = [1, 1, 0, 3, 1024, 0, 1, 1, 1025, 0, 1, 1, 3072, 0, 1, 3035];
    img.encoder().write_tag(Tag::GeoKeyDirectoryTag, &geokeys[..]).unwrap();
    img.encoder().write_tag(Tag::GdalNodata, "48").unwrap();
    let pixels: Vec<u8> = (0..40 * 30).map(|i| [23u8, 24, 25, 12, 48][i % 5]).collect();
    img.write_data(&pixels).unwrap();
    let original = std::fs::read(&tif).unwrap();
    let points: Vec<(f64, f64)> =
        (0..200).map(|i| (3_800_050.0 + 19.7 * i as f64, 2_599_950.0 - 14.3 * i as f64)).collect();
    let sample = |path: &Path, _: usize| -> Result<(), Error> {
        let mut raster = gedisim::io::landcover::LandCoverRaster::open(path)?;
        raster.sample_xy(&points, &|_| {})?;
        Ok(())
    };
    sample(&tif, 0).expect("the unmutated raster reads");
    fuzz("clc.tif", &original, 512, cases(1500), sample);
}

#[test]
fn fuzz_footprint_csv() {
    let mut text = String::from("id,x,y,note\n");
    for i in 0..50 {
        text.push_str(&format!(
            "shot{i},{:.2},{:.2},plot {}\n",
            925_000.0 + 3.1 * i as f64,
            6_570_000.0 - 2.7 * i as f64,
            i % 7
        ));
    }
    let read = |path: &Path, _: usize| gedisim::io::footprints::read_footprints_csv(path).map(|_| ());
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("footprints.csv");
    std::fs::write(&csv, &text).unwrap();
    read(&csv, 0).expect("the unmutated CSV reads");
    fuzz("footprints.csv", text.as_bytes(), 16, cases(3000), read);
}
