//! Shots kept by area (issue 42, docs/gedi-products.md "Shots kept"): a granule read with an area
//! gives exactly the rows of the small granule that holds only the shots inside it, whatever the
//! storage (contiguous, or gzip chunks that do not align with the runs of kept shots); the real V1
//! subset read with a box or polygons gives the rows of its whole read that lie inside.

use std::path::{Path, PathBuf};

use arrow::array::{Array, AsArray, BooleanArray, RecordBatch};
use arrow::compute::{concat_batches, filter_record_batch};
use arrow::datatypes::Float64Type;
use gedisim::dataset::shots::shots_schema;
use gedisim::dataset::Dataset;
use gedisim::io::granule::{write_l1b_v2, write_l2a_v2, Beam, GranuleMeta, Storage};
use gedisim::kernels::gedi::{v2_file_name, L1bShot, L2aShot};
use gedisim::kernels::geo::area::ShotArea;
use gedisim::ops::ingest_gedi::{ingest, read_gedi, GediOptions, GranuleOutcome, IngestRequest, ShotChoice};
use gedisim::ops::progress::NoProgress as Silent;

mod common;

const SHOT0: u64 = 241_560_000_200_000_000;

/// Shot `k` of beam `b` on a track going north from (3.0°E, 46.5°N), 60 m apart.
fn l1b_shot(b: usize, k: usize) -> L1bShot {
    let n = 600 + (k * 37) % 800; // record lengths of 600–1,399 samples, as GEDI's
    let lat = 46.5 + k as f64 * 5.4e-4;
    let lon = 3.0 + b as f64 * 0.006;
    L1bShot {
        shot_number: SHOT0 + b as u64 * 10_000_000 + k as u64,
        delta_time: 52_000_000.0 + k as f64 * 0.0083,
        rx_waveform: (0..n).map(|i| 230.0 + ((i * 7 + k * 13) % 29) as f32 + (i as f32 * 0.05).sin() * 40.0).collect(),
        tx_waveform: (0..128).map(|i| 200.0 + 900.0 * (-((i as f32 - 60.0) / 6.0).powi(2)).exp() + k as f32).collect(),
        latitude_bin0: lat + 1e-6,
        longitude_bin0: lon - 1e-6,
        latitude_lastbin: lat - 1e-6,
        longitude_lastbin: lon + 1e-6,
        elevation_bin0: 500.0 + k as f64 * 0.01,
        elevation_lastbin: 500.0 + k as f64 * 0.01 - 0.15 * (n - 1) as f64,
        noise_mean_corrected: 230.0,
        noise_stddev_corrected: 2.5 + (k % 5) as f64 * 0.1,
        stale_return_flag: 0,
        degrade: 0,
        geoid: 49.5,
        digital_elevation_model: 400.0,
    }
}

fn l2a_shot(b: usize, k: usize) -> L2aShot {
    let l1b = l1b_shot(b, k);
    let mut s = L2aShot {
        shot_number: l1b.shot_number,
        delta_time: l1b.delta_time,
        energy_total: 1500.0 + k as f32,
        ..Default::default()
    };
    for (a, alg) in s.algorithms.iter_mut().enumerate() {
        alg.elev_lowestmode = 420.0 + a as f32;
        // Every 7th shot has no valid lowest mode: it is placed by its L1B bins.
        let bad = k % 7 == 3;
        alg.lat_lowestmode = if bad { f64::NAN } else { l1b.latitude_bin0 + 2e-6 };
        alg.lon_lowestmode = if bad { f64::NAN } else { l1b.longitude_bin0 };
        alg.rh_cm = (0..101).map(|i| i as i16 * (2 + a as i16) + (k % 100) as i16).collect();
        alg.sensitivity = 0.95;
        alg.quality_flag = 1;
    }
    s.select_algorithm(1 + (k % 6) as u8);
    s
}

/// A granule pair of two beams of `n` shots each; `keep` chooses the shots written (by index).
fn write_pair(dir: &Path, n: usize, keep: impl Fn(usize) -> bool, storage: Storage) -> (PathBuf, PathBuf) {
    std::fs::create_dir_all(dir).unwrap();
    let l1b = dir.join(v2_file_name("01_B", "2023100120000", 24561, 2, 1234));
    let l2a = dir.join(v2_file_name("02_A", "2023100120000", 24561, 2, 1234));
    let names = ["BEAM0010", "BEAM0101"];
    let meta = GranuleMeta { storage, ..Default::default() };
    let b1: Vec<_> = names
        .iter()
        .enumerate()
        .map(|(b, name)| Beam::new(*name, (0..n).filter(|&k| keep(k)).map(|k| l1b_shot(b, k)).collect()))
        .collect();
    // One L1B shot of the second beam has no L2A partner: kept with null L2A columns either way.
    let b2: Vec<_> = names
        .iter()
        .enumerate()
        .map(|(b, name)| {
            Beam::new(*name, (0..n).filter(|&k| keep(k) && !(b == 1 && k == n / 2)).map(|k| l2a_shot(b, k)).collect())
        })
        .collect();
    write_l1b_v2(&l1b, &b1, &meta).unwrap();
    write_l2a_v2(&l2a, &b2, &meta).unwrap();
    (l1b, l2a)
}

fn read(l1b: &Path, l2a: &Path, area: ShotArea) -> (RecordBatch, usize) {
    let opts = GediOptions { area, ..Default::default() };
    let (batches, report) = read_gedi(&[l1b.to_path_buf()], &[l2a.to_path_buf()], &opts).unwrap();
    (concat_batches(&shots_schema(opts.epsg), &batches).unwrap(), report.outside_area())
}

/// The box of the shots with index in `lo..hi` of the test track (the lowest mode lies 2e-6° north).
fn box_of(lo: usize, hi: usize) -> ShotArea {
    let lat = |k: usize| 46.5 + k as f64 * 5.4e-4;
    ShotArea::lon_lat_box(&format!("2.99,{},3.01,{}", lat(lo) - 1e-4, lat(hi - 1) + 1e-4)).unwrap()
}

#[test]
fn a_granule_read_by_area_gives_the_rows_of_the_small_granule_of_its_shots() {
    let dir = tempfile::tempdir().unwrap();
    let n = 2_000;
    // Two runs of kept shots per beam: 300..420 and 1500..1503.
    let inside = |k: usize| (300..420).contains(&k) || (1500..1503).contains(&k);
    let area = ShotArea::Polygons {
        source: "two boxes".into(),
        polygons: geo::MultiPolygon(
            [box_of(300, 420), box_of(1500, 1503)]
                .iter()
                .map(|b| match b {
                    ShotArea::LonLatBox([w, s, e, n]) => geo::Rect::new((*w, *s), (*e, *n)).to_polygon(),
                    _ => unreachable!(),
                })
                .collect(),
        ),
    };
    let (s1, s2) = write_pair(&dir.path().join("small"), n, inside, Storage::default());
    let (small, small_outside) = read(&s1, &s2, ShotArea::All);
    assert_eq!(small_outside, 0);
    assert_eq!(small.num_rows(), 2 * 123);
    // Chunks of 97 shots and 997 samples cut across the runs; NASA's layout has one chunk per beam.
    let layouts = [
        Storage::default(),
        Storage { shot_chunk: Some(97), sample_chunk: 997, row_chunk: 13, gzip: 4 },
        Storage::nasa(),
    ];
    for (i, storage) in layouts.into_iter().enumerate() {
        let (f1, f2) = write_pair(&dir.path().join(format!("full{i}")), n, |_| true, storage);
        let (kept, outside) = read(&f1, &f2, area.clone());
        assert_eq!(outside, 2 * n - small.num_rows(), "{storage:?}");
        assert_eq!(kept, small, "{storage:?}: the kept rows differ from the small granule's");
        // Without an area, every shot.
        let (all, outside) = read(&f1, &f2, ShotArea::All);
        assert_eq!((all.num_rows(), outside), (2 * n, 0));
    }
}

#[test]
fn the_real_subset_read_by_box_keeps_the_rows_inside_it() {
    let l1b = common::data("gedi/GEDI01_B_2019108080338_O01964_T05337_02_003_01_sub.h5");
    let l2a = common::data("gedi/GEDI02_A_2019108080338_O01964_T05337_02_001_01_sub.h5");
    let (all, _) = read(&l1b, &l2a, ShotArea::All);
    // Each row's position as the ingest places it: the lowest mode, else the bin mean.
    let col = |name: &str| all.column_by_name(name).unwrap().as_primitive::<Float64Type>().clone();
    let (lat_lm, lon_lm) = (col("lat_lowestmode"), col("lon_lowestmode"));
    let (lat0, lon0, lat1, lon1) = (col("lat_bin0"), col("lon_bin0"), col("lat_lastbin"), col("lon_lastbin"));
    let pos: Vec<(f64, f64)> = (0..all.num_rows())
        .map(|i| match lat_lm.is_valid(i) {
            true => (lon_lm.value(i), lat_lm.value(i)),
            false => ((lon0.value(i) + lon1.value(i)) / 2.0, (lat0.value(i) + lat1.value(i)) / 2.0),
        })
        .collect();
    // A box around the middle third of the latitudes, and the western half of the longitudes.
    let mut lats: Vec<f64> = pos.iter().map(|p| p.1).collect();
    lats.sort_by(f64::total_cmp);
    let mut lons: Vec<f64> = pos.iter().map(|p| p.0).collect();
    lons.sort_by(f64::total_cmp);
    let (s, n) = (lats[lats.len() / 3], lats[2 * lats.len() / 3]);
    let (w, e) = (lons[0] - 0.01, lons[lons.len() / 2]);
    let area = ShotArea::lon_lat_box(&format!("{w},{s},{e},{n}")).unwrap();
    let mask: BooleanArray = pos.iter().map(|&(lon, lat)| Some(area.contains(lon, lat, None))).collect();
    let expected = filter_record_batch(&all, &mask).unwrap();
    assert!(expected.num_rows() > 10 && expected.num_rows() < all.num_rows() / 2, "{}", expected.num_rows());
    let (kept, outside) = read(&l1b, &l2a, area);
    assert_eq!(outside, all.num_rows() - expected.num_rows());
    assert_eq!(kept, expected);
}

#[test]
fn a_granule_is_read_again_when_the_tiles_change_and_kept_whole_once_read_whole() {
    let dir = tempfile::tempdir().unwrap();
    let (l1b, l2a) = write_pair(&dir.path().join("g"), 500, |_| true, Storage::default());
    let ds = Dataset::create(&dir.path().join("ds")).unwrap();
    let request = |shots| IngestRequest { shots, margin_m: 30.0, ..Default::default() };
    let run =
        |shots| ingest(&ds, std::slice::from_ref(&l1b), std::slice::from_ref(&l2a), &request(shots), &Silent).unwrap();
    // No tiles yet: every shot, and the note says why.
    let (o, report) = run(ShotChoice::AlsCoverage);
    assert!(matches!(o[0], GranuleOutcome::Ingested { shots: 1000, .. }), "{o:?}");
    assert!(report.kept_line().unwrap().contains("no ALS tiles yet"), "{:?}", report.kept_line());
    // Read whole, a granule is kept whole by a later default ingest.
    common::write_tile_extents(&ds, &[[0.0, 0.0, 1.0, 1.0]]);
    let (o, _) = run(ShotChoice::AlsCoverage);
    assert!(matches!(o[0], GranuleOutcome::AlreadyIngested { .. }), "{o:?}");
    // A box: read again, the shots inside kept, the others counted.
    let (o, report) = run(ShotChoice::Area(box_of(100, 150)));
    assert!(matches!(o[0], GranuleOutcome::Ingested { shots: 100, .. }), "{o:?}");
    assert_eq!(report.outside_area(), 900);
    let line = report.kept_line().unwrap();
    assert!(line.contains("100 shot(s) kept within --bbox") && line.contains("900 outside"), "{line}");
    // The same box again: nothing new; the tiles' extents (far from the track): read again, none kept.
    assert!(matches!(run(ShotChoice::Area(box_of(100, 150))).0[0], GranuleOutcome::AlreadyIngested { .. }));
    let (o, report) = run(ShotChoice::AlsCoverage);
    assert!(matches!(o[0], GranuleOutcome::Ingested { shots: 0, .. }), "{o:?}");
    assert_eq!(report.outside_area(), 1000);
}

#[test]
fn the_command_line_keeps_the_shots_over_twenty_thousand_tiles_and_says_what_it_left_out() {
    let dir = tempfile::tempdir().unwrap();
    let (l1b, l2a) = write_pair(&dir.path().join("g"), 400, |_| true, Storage::default());
    let ds = Dataset::create(&dir.path().join("ds")).unwrap();
    // One tile under shots 100..150 of the first beam's track; 19,999 more, far away: a request
    // this long passes to the granule reader's child process through stdin, not an argument.
    let projector = gedisim::kernels::geo::projection::Projector::new(2154).unwrap();
    let (x0, y0) = projector.project(3.0, 46.5 + 100.0 * 5.4e-4).unwrap();
    let (x1, y1) = projector.project(3.0, 46.5 + 149.0 * 5.4e-4).unwrap();
    let mut extents = vec![[x0 - 5.0, y0, x1 + 5.0, y1]];
    extents.extend((0..19_999).map(|i| [1e5 + i as f64 * 10.0, 1e5, 1e5 + i as f64 * 10.0 + 5.0, 1e5 + 5.0]));
    common::write_tile_extents(&ds, &extents);
    let args = ["ingest", "gedi", "--l1b", common::s(&l1b), "--l2a", common::s(&l2a), "--dataset"];
    let (ok, _, err) = common::gedisim(&[&args[..], &[common::s(ds.root())]].concat());
    assert!(ok, "{err}");
    // The margin (28.4 m) adds none of the shots 60 m apart beyond the tile's; the second beam is
    // 0.006° (≈ 460 m) east.
    assert!(err.contains("50 shot(s) kept within the extents of the dataset's 20000 ALS tile(s)"), "{err}");
    assert!(err.contains("750 outside it left out"), "{err}");
    let (ok, out, err) = common::gedisim(&[
        "sql",
        "--dataset",
        common::s(ds.root()),
        "--format",
        "csv",
        "select count(*) n, min(shot_number) lo, max(shot_number) hi from shots",
    ]);
    assert!(ok, "{err}");
    assert!(out.contains(&format!("50,{},{}", SHOT0 + 100, SHOT0 + 149)), "{out}");
    // Malformed areas: one line naming the option.
    for (opt, value, says) in [("--bbox", "3,46,2", "3 values"), ("--bbox", "3,47,4,46", "south")] {
        let (ok, _, err) = common::gedisim(&[&args[..], &[common::s(ds.root()), opt, value]].concat());
        assert!(!ok && err.contains(opt) && err.contains(says) && err.trim().lines().count() == 1, "{err}");
    }
    let (ok, _, err) =
        common::gedisim(&[&args[..], &[common::s(ds.root()), "--bbox", "1,2,3,4", "--all-shots"]].concat());
    assert!(!ok && err.contains("cannot be used with"), "{err}");
    // GeoPackages written by GDAL (tests/data/within): areas away from the track keep none of its shots; a
    // table of lines is refused in one line naming the file and the table.
    let within = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/within");
    let (ok, _, err) = common::gedisim(
        &[&args[..], &[common::s(ds.root()), "--within", common::s(&within.join("areas.gpkg"))]].concat(),
    );
    assert!(ok && err.contains("0 shot(s) kept within") && err.contains("800 outside"), "{err}");
    let (ok, _, err) = common::gedisim(
        &[&args[..], &[common::s(ds.root()), "--within", common::s(&within.join("line.gpkg"))]].concat(),
    );
    assert!(!ok && err.contains("line.gpkg: track.geom: a line") && err.trim().lines().count() == 1, "{err}");
}

/// A granule another holder has locked (a child process that inherited its descriptor, a reader on
/// NFS) is still read: gedisim does not take HDF5's advisory locks (src/io/gedi.rs `without_locks`).
/// CI met this race once: a test's granule held by a `gedisim` another test had just spawned.
#[test]
fn a_granule_locked_by_another_holder_is_still_read() {
    let dir = tempfile::tempdir().unwrap();
    let (l1b, l2a) = write_pair(dir.path(), 50, |_| true, Storage::default());
    let held: Vec<std::fs::File> = [&l1b, &l2a]
        .into_iter()
        .map(|p| {
            let f = std::fs::File::open(p).unwrap();
            f.lock().unwrap();
            f
        })
        .collect();
    let (rows, outside) = read(&l1b, &l2a, ShotArea::All);
    assert_eq!((rows.num_rows(), outside), (2 * 50, 0));
    drop(held);
}

/// A large granule is read in parts, some of its beams each, in child processes at once
/// (`BeamPart`, so that HDF5's inflating runs on every core): the batches and beam reports of one
/// whole read, in the same order, for any number of parts (more parts than beams included), with
/// and without an area.
#[test]
fn a_granule_read_in_parts_gives_the_batches_of_one_read() {
    use gedisim::ops::ingest_gedi::{child, pair_granules, read_granule_in_process, BeamPart};
    let reader = child::Reader {
        exe: PathBuf::from(env!("CARGO_BIN_EXE_gedisim")),
        stall_limit: std::time::Duration::from_secs(120),
    };
    let l1b = common::data("gedi/GEDI01_B_2019108080338_O01964_T05337_02_003_01_sub.h5");
    let l2a = common::data("gedi/GEDI02_A_2019108080338_O01964_T05337_02_001_01_sub.h5");
    let pair = pair_granules(&[l1b], &[l2a]).unwrap().0.remove(0);
    for area in [ShotArea::All, ShotArea::lon_lat_box("-180,-90,180,0").unwrap()] {
        let opts = GediOptions { area, ..Default::default() };
        let mut whole = Vec::new();
        let reports = read_granule_in_process(&pair, &opts, BeamPart::WHOLE, &mut |b| {
            whole.push(b);
            Ok(())
        })
        .unwrap();
        assert!(reports.len() >= 4 && !whole.is_empty(), "{} beams", reports.len());
        for parts in [2, 3, reports.len() + 2] {
            let mut got = Vec::new();
            let got_reports = child::read_in_parts(&reader, &pair, &opts, parts, &mut |b| {
                got.push(b);
                Ok(())
            })
            .unwrap();
            assert_eq!(got_reports, reports, "{parts} parts");
            assert_eq!(got, whole, "{parts} parts");
        }
    }
}
