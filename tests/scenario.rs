//! `gedisim scenario`: worlds ingest like NASA files, plant what truth.json says, are
//! reproducible, and reject bad effect specifications with one-line errors.

mod common;

use std::path::Path;

use arrow::array::{Array, Float64Array, StringArray};
use common::{data, files_with_suffix, gedisim};
use gedisim::kernels::scenario::real;
use gedisim::ops::ingest_gedi::{read_gedi, GediOptions};

/// A small flat leaf-off tile keeps the worlds fast.
const TILE: &str = "als/lidarforfuel_2_bas_lig.laz";

fn scenario(out: &Path, extra: &[&str]) -> String {
    let tile = data(TILE);
    let mut args = vec!["scenario", "--als", tile.to_str().unwrap(), "--out", out.to_str().unwrap()];
    args.extend_from_slice(extra);
    let (ok, _, err) = gedisim(&args);
    assert!(ok, "{err}");
    err
}

fn truth(out: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(out.join("truth.json")).unwrap()).unwrap()
}

/// Ingest the world's granules and tiles into `ds`; returns the shots ingested.
fn ingest(world: &Path, ds: &Path) -> usize {
    let gedi = world.join("gedi");
    let g = gedi.to_str().unwrap();
    let (ok, _, err) = gedisim(&[
        "ingest",
        "gedi",
        "--l1b",
        g,
        "--l2a",
        g,
        "--out",
        ds.to_str().unwrap(),
        "--strict-join",
        "--epsg",
        "2154",
    ]);
    assert!(ok, "{err}");
    assert!(!err.contains("warning"), "{err}");
    let shots = err.lines().filter_map(|l| l.split(": ").nth(1)?.strip_suffix(" shots")?.parse::<usize>().ok()).sum();
    let (ok, _, err) = gedisim(&["ingest", "als", world.join("als").to_str().unwrap(), "--out", ds.to_str().unwrap()]);
    assert!(ok, "{err}");
    shots
}

/// Median over shots of (GEDI ground − geoid − mean ALS ground point within 3 m of the shot),
/// with the ALS ground read from the ingested ALS table, not from truth.json.
fn median_ground_offset(ds: &Path) -> (usize, f64) {
    let q = "select count(*) as n, median(d) as med from (select s.shot_number, avg(s.elev_lowestmode - s.geoid - \
    a.z) as d \
             from shots s join als a on a.classification = 2 and a.x between s.x - 3 and s.x + 3 and a.y between \
             s.y - 3 and s.y + 3 \
             where s.quality_flag = 1 group by s.shot_number) t";
    let (ok, out, err) = gedisim(&["sql", "--dataset", ds.to_str().unwrap(), q]);
    assert!(ok, "{err}");
    let row = out.lines().nth(3).unwrap();
    let cells: Vec<&str> = row.split('|').map(str::trim).filter(|s| !s.is_empty()).collect();
    (cells[0].parse().unwrap(), cells[1].parse().unwrap())
}

#[test]
fn none_and_datum_worlds_ingest_and_show_the_planted_datum() {
    let tmp = tempfile::tempdir().unwrap();
    let mut medians = Vec::new();
    for (effect, dz) in [("none", 0.0), ("datum", 2.0)] {
        let world = tmp.path().join(effect);
        // `none` ignores the magnitude.
        scenario(&world, &["--effect", effect, "--magnitude", "4", "--passes", "4", "--seed", "3"]);
        let t = truth(&world);
        assert_eq!(t["effect"], effect);
        assert_eq!(t["datum_dz_m"].as_f64().unwrap(), dz);
        assert_eq!(t["geoid"]["dataset"], "geophys_corr/geoid");
        let planned = t["n_shots"].as_u64().unwrap() as usize;
        assert!(planned >= 20, "{planned} shots");
        let per_track: u64 = t["tracks"].as_array().unwrap().iter().map(|x| x["n_shots"].as_u64().unwrap()).sum();
        assert_eq!(per_track as usize, planned);
        assert_eq!(files_with_suffix(&world.join("als"), ".laz").len(), 1);

        let ds = tmp.path().join(format!("{effect}_ds"));
        assert_eq!(ingest(&world, &ds), planned, "every planned shot is ingested");
        let (n, med) = median_ground_offset(&ds);
        assert!(n >= planned * 2 / 3, "{n} valid shots of {planned}");
        assert!((med - dz).abs() < 0.5, "{effect}: median GEDI ground − geoid − ALS ground {med:.3} m, planted {dz} m");
        medians.push(med);
    }
    // Same seed: the worlds differ by the datum alone.
    assert!((medians[1] - medians[0] - 2.0).abs() < 0.05, "{medians:?}");
}

#[test]
fn same_seed_gives_identical_granules_and_another_seed_does_not() {
    let tmp = tempfile::tempdir().unwrap();
    let run = |name: &str, seed: &str| {
        let world = tmp.path().join(name);
        scenario(&world, &["--effect", "noise", "--passes", "2", "--seed", seed]);
        files_with_suffix(&world.join("gedi"), ".h5")
    };
    let (a, b, c) = (run("a", "9"), run("b", "9"), run("c", "10"));
    assert_eq!(a.len(), b.len());
    assert!(!a.is_empty());
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(x.file_name(), y.file_name());
        assert!(std::fs::read(x).unwrap() == std::fs::read(y).unwrap(), "{} differs", x.display());
    }
    assert_eq!(
        std::fs::read(tmp.path().join("a/truth.json")).unwrap(),
        std::fs::read(tmp.path().join("b/truth.json")).unwrap()
    );
    let waves = |files: &[std::path::PathBuf]| {
        let l1b: Vec<_> = files.iter().filter(|f| f.to_string_lossy().contains("GEDI01_B")).cloned().collect();
        let (batches, _) = read_gedi(&l1b, &[], &GediOptions::default()).unwrap();
        batches.iter().map(|b| format!("{:?}", b.column_by_name("rx_waveform").unwrap())).collect::<String>()
    };
    assert_ne!(waves(&a), waves(&c), "another seed draws other waveforms");
    // A world is not silently overwritten.
    let world = tmp.path().join("a");
    let tile = data(TILE);
    let (ok, _, err) =
        gedisim(&["scenario", "--effect", "none", "--als", tile.to_str().unwrap(), "--out", world.to_str().unwrap()]);
    assert!(!ok && err.contains("--force") && err.trim().lines().count() == 1, "{err}");
}

#[test]
fn pair_effect_is_planted_and_recorded() {
    let tmp = tempfile::tempdir().unwrap();
    let world = tmp.path().join("w");
    let err = scenario(
        &world,
        &["--effect", "datum+ground_detection", "--param", "dz_m=-1", "--param", "algorithm=2", "--passes", "2"],
    );
    assert!(err.contains("datum+ground_detection"), "{err}");
    let t = truth(&world);
    assert_eq!(t["effect"], "datum+ground_detection");
    assert_eq!(t["effects"][0]["params"]["dz_m"].as_f64(), Some(-1.0));
    assert_eq!(t["effects"][1]["params"]["algorithm"].as_f64(), Some(2.0));
    assert_eq!(t["ground_detection_offset_m"], serde_json::json!([0.0, 0.5, 0.0, 0.0, 0.0, 0.0]));
    // The stored products: a2's ground is 0.5 m above a1's wherever both found the same mode.
    let files = files_with_suffix(&world.join("gedi"), ".h5");
    let (l1b, l2a): (Vec<_>, Vec<_>) = files.into_iter().partition(|f| f.to_string_lossy().contains("GEDI01_B"));
    let (batches, _) = read_gedi(&l1b, &l2a, &GediOptions::default()).unwrap();
    let mut diffs = Vec::new();
    for b in &batches {
        let col = |n: &str| b.column_by_name(n).unwrap().as_any().downcast_ref::<Float64Array>().unwrap().clone();
        let (a1, a2) = (col("elev_lowestmode_a1"), col("elev_lowestmode_a2"));
        let geoid = col("geoid");
        assert!(
            b.column_by_name("beam_type").unwrap().as_any().downcast_ref::<StringArray>().unwrap().null_count() == 0
        );
        for i in 0..b.num_rows() {
            assert!((geoid.value(i) - 49.0).abs() < 1e-5);
            diffs.push(a2.value(i) - a1.value(i));
        }
    }
    let near = diffs.iter().filter(|d| (**d - 0.5).abs() < 0.2).count();
    assert!(near * 2 > diffs.len(), "a2 − a1 ground: {diffs:?}");
}

#[test]
fn bad_effects_and_parameters_are_one_line_errors_naming_the_field() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("w");
    let o = out.to_str().unwrap();
    for (args, needle) in [
        (vec!["--effect", "bogus"], "unknown effect 'bogus'"),
        (vec!["--effect", "datum", "--param", "dz_m=abc"], "--param dz_m"),
        (vec!["--effect", "datum", "--param", "dz_m"], "--param dz_m"),
        (vec!["--effect", "datum", "--param", "fsigma_m=7"], "--param fsigma_m"),
        (vec!["--effect", "footprint", "--param", "fsigma_m=-1"], "--param fsigma_m"),
        (vec!["--effect", "weighting", "--param", "method=magic"], "--param method"),
        (vec!["--effect", "datum+datum"], "twice"),
        (vec!["--effect", "pulse", "--magnitude", "nan"], "--magnitude"),
        (vec!["--effect", "none", "--passes", "0"], "--passes"),
    ] {
        let mut a = vec!["scenario", "--out", o];
        a.extend(args.iter());
        let (ok, _, err) = gedisim(&a);
        assert!(!ok, "{args:?} accepted");
        assert_eq!(err.trim().lines().count(), 1, "{args:?}: {err}");
        assert!(err.contains(needle), "{args:?}: {err}");
    }
    assert!(!out.join("truth.json").exists());
    let (ok, _, err) = gedisim(&["scenario", "--effect", "none", "--als", "/nonexistent/tile.laz", "--out", o]);
    assert!(!ok && err.trim().lines().count() == 1 && err.contains("/nonexistent/tile.laz"), "{err}");
}

/// The constants the worlds use are the medians of the shared real granule, per beam type.
#[test]
fn scenario_constants_match_the_real_granule() {
    let l1b = data("gedi/GEDI01_B_2019108080338_O01964_T05337_02_003_01_sub.h5");
    let (batches, _) = read_gedi(&[l1b], &[], &GediOptions::default()).unwrap();
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        let n = v.len();
        if n % 2 == 1 {
            v[n / 2]
        } else {
            (v[n / 2 - 1] + v[n / 2]) / 2.0
        }
    };
    for (kind, rec) in [("coverage", real::COVERAGE), ("full_power", real::FULL_POWER)] {
        let (mut sd, mut mean) = (Vec::new(), Vec::new());
        for b in &batches {
            let bt = b.column_by_name("beam_type").unwrap().as_any().downcast_ref::<StringArray>().unwrap();
            let col = |n: &str| b.column_by_name(n).unwrap().as_any().downcast_ref::<Float64Array>().unwrap().clone();
            let (s, m) = (col("noise_stddev_corrected"), col("noise_mean_corrected"));
            for i in 0..b.num_rows() {
                if bt.value(i) == kind {
                    sd.push(s.value(i));
                    mean.push(m.value(i));
                }
            }
        }
        let (msd, mmean) = (median(sd), median(mean));
        println!("{kind}: median noise_stddev_corrected {msd:.3}, noise_mean_corrected {mmean:.2}");
        assert!((msd - rec.noise_stddev).abs() < 0.005, "{kind}: {msd}");
        assert!((mmean - rec.noise_mean).abs() < 0.05, "{kind}: {mmean}");
    }
}

#[test]
fn shots_carry_real_transmit_pulses_and_plots_get_their_mean() {
    use gedisim::kernels::sim::{pulse::parse_pulse_text, PulseReference};
    let tmp = tempfile::tempdir().unwrap();
    let world = tmp.path().join("world");
    scenario(&world, &["--effect", "none", "--seed", "5"]);
    let ds = tmp.path().join("ds");
    let shots = ingest(&world, &ds);
    // Every shot's txwaveform is a real GEDI pulse shape: its slow tail puts the energy centroid
    // after the peak (a Gaussian would put it at the peak). Over the 300 bundled L1B records
    // (floor = median of samples 0–19, clipped at 0) it lies 0.217–0.782 m after the peak (median
    // 0.506); the draws stretch time by at most ±8 %, hence 0.15–0.9 m.
    let dataset = gedisim::dataset::Dataset::open(&ds).unwrap();
    let pulses = gedisim::sql::pulses::shot_pulses(&dataset, PulseReference::Peak, 0.15).unwrap();
    assert_eq!((pulses.by_shot.len(), pulses.missing, pulses.unusable), (shots, 0, 0));
    for p in pulses.by_shot.values() {
        let centroid: f32 = p.x.iter().zip(&p.y).map(|(x, y)| x * y).sum();
        assert!((0.15..0.9).contains(&centroid), "centroid {centroid} m after the peak");
    }
    // Plots (positions without a shot) are simulated with the mean recorded pulse, written beside
    // the output as a pulse file.
    let t = truth(&world);
    let s = &t["shots"][0];
    let csv = tmp.path().join("plots.csv");
    std::fs::write(&csv, format!("id,x,y\np1,{},{}\n", s["x"], s["y"])).unwrap();
    let d = ds.to_str().unwrap();
    let (ok, _, err) =
        gedisim(&["simulate", "--dataset", d, "--footprints", csv.to_str().unwrap(), "--pulse", "recorded"]);
    assert!(ok, "{err}");
    let text = std::fs::read_to_string(ds.join("simulated/plots.pulse.txt")).unwrap();
    let pairs = parse_pulse_text(&text).unwrap();
    let total: f32 = pairs.iter().map(|p| p.1).sum();
    assert!((total - 1.0).abs() < 1e-3 && pairs.len() > 50, "{} samples, Σ {total}", pairs.len());
    // Direct mode has no shots to take pulses from: one line saying so.
    let (ok, _, err) = gedisim(&[
        "simulate",
        "--als",
        data(TILE).to_str().unwrap(),
        "--footprints",
        csv.to_str().unwrap(),
        "--out",
        tmp.path().join("x.parquet").to_str().unwrap(),
        "--pulse",
        "recorded",
    ]);
    assert!(!ok && err.contains("--pulse recorded") && err.trim().lines().count() == 1, "{err}");
}

#[test]
fn a_tile_without_a_crs_is_said_to_be_taken_as_lambert_93() {
    // The small tile with its CRS records removed (LAS, uncompressed).
    let tmp = tempfile::tempdir().unwrap();
    let mut reader = las::Reader::from_path(data(TILE)).unwrap();
    let mut builder = las::Builder::from(reader.header().clone());
    builder.vlrs.retain(|v| v.user_id != "LASF_Projection" && v.user_id != "laszip encoded");
    builder.evlrs.retain(|v| v.user_id != "LASF_Projection");
    builder.point_format.is_compressed = false;
    let tile = tmp.path().join("no_crs.las");
    let mut writer = las::Writer::from_path(&tile, builder.into_header().unwrap()).unwrap();
    for p in reader.read_all().unwrap().points() {
        writer.write_point(p.unwrap()).unwrap();
    }
    writer.close().unwrap();
    drop(writer);
    let run = |out: &str, extra: &[&str]| {
        let out = tmp.path().join(out);
        let mut args = vec!["scenario", "--effect", "none", "--passes", "1", "--als", tile.to_str().unwrap()];
        args.extend_from_slice(&["--out", out.to_str().unwrap()]);
        args.extend_from_slice(extra);
        let (ok, _, err) = gedisim(&args);
        assert!(ok, "{err}");
        err
    };
    let err = run("default", &[]);
    let said: Vec<&str> = err.lines().filter(|l| l.starts_with("warning:")).collect();
    assert_eq!(said.len(), 1, "{err}");
    assert!(said[0].contains("no_crs.las") && said[0].contains("EPSG:2154") && said[0].contains("--epsg"), "{err}");
    let err = run("named", &["--epsg", "2154"]);
    assert!(!err.contains("warning"), "{err}");
    // The real tile carries its CRS: nothing to say.
    let err = scenario(&tmp.path().join("real"), &["--effect", "none", "--passes", "1"]);
    assert!(!err.contains("warning"), "{err}");
}
