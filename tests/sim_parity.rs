//! Golden parity of the `gedirat` profile against gediRat + gediMetric on three real tiles
//! (tests/data/golden/PROVENANCE.md), and the measured effect of each `default` decision.
//!
//! Checked per tile × pulse variant × weighting: every waveform line (bin count, elevation label
//! as printed, totals and canopy/ground columns within 10⁻⁵ of the waveform's peak), the truths
//! (ground, top, slope, cover) and rhReal at 5 % steps against the metric files.

use std::collections::HashMap;
use std::io::Read;
use std::path::{Path, PathBuf};

use gedisim::io::las::read_points;
use gedisim::kernels::sim::pulse::parse_pulse_text;
use gedisim::kernels::sim::{
    simulate, AlsPoints, Footprint, Profile, Pulse, Quirks, SimConfig, SimulatedFootprint, Weighting,
};

const TILES: [&str; 3] = ["lidarforfuel_1_42", "lidarforfuel_2_bas_lig", "pdal-ign-plugin_mnx_input_crop_2"];
const VARIANTS: [&str; 3] = ["gauss", "empirical", "gauss_nonorm"];

fn data(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data").join(rel)
}

fn gunzip(path: &Path) -> Vec<u8> {
    let mut out = Vec::new();
    flate2::read::GzDecoder::new(std::fs::File::open(path).unwrap()).read_to_end(&mut out).unwrap();
    out
}

/// Regular files of a (ustar) tar archive: name → content.
fn untar(bytes: &[u8]) -> HashMap<String, String> {
    let mut files = HashMap::new();
    let mut at = 0;
    while at + 512 <= bytes.len() && bytes[at] != 0 {
        let header = &bytes[at..at + 512];
        let field =
            |a: usize, b: usize| String::from_utf8_lossy(&header[a..b]).trim_end_matches('\0').trim().to_string();
        let name = field(0, 100);
        let size = usize::from_str_radix(&field(124, 136), 8).unwrap();
        let body = &bytes[at + 512..at + 512 + size];
        if header[156] == b'0' || header[156] == 0 {
            let base = name.rsplit('/').next().unwrap().to_string();
            files.insert(base, String::from_utf8(body.to_vec()).unwrap());
        }
        at += 512 + size.div_ceil(512) * 512;
    }
    files
}

fn footprints(tile: &str) -> Vec<Footprint> {
    let text = std::fs::read_to_string(data(&format!("golden/{tile}/footprints.csv"))).unwrap();
    text.lines()
        .skip(1)
        .map(|l| {
            let c: Vec<&str> = l.split(',').collect();
            Footprint::at(c[0], c[1].parse().unwrap(), c[2].parse().unwrap())
        })
        .collect()
}

fn config(profile: Profile, variant: &str) -> SimConfig {
    let mut cfg = SimConfig::new(profile);
    match variant {
        "empirical" => {
            let text = std::fs::read_to_string(data("golden/gedi_tx_pulse.txt")).unwrap();
            cfg.pulse = Pulse::tabulated(&parse_pulse_text(&text).unwrap()).unwrap();
        }
        "gauss_nonorm" => cfg.normalise_density = false,
        _ => {}
    }
    cfg
}

/// A gediRat ASCII waveform: printed labels and the 9 value columns as printed.
struct GoldenWave {
    labels: Vec<String>,
    cols: Vec<[String; 9]>,
}

fn parse_wave(text: &str) -> GoldenWave {
    let (mut labels, mut cols) = (Vec::new(), Vec::new());
    for line in text.lines().filter(|l| !l.starts_with('#')) {
        let t: Vec<&str> = line.split_whitespace().collect();
        labels.push(t[0].to_string());
        cols.push(std::array::from_fn(|i| t[i + 1].to_string()));
    }
    GoldenWave { labels, cols }
}

/// Column (0-based among the 9 value columns) of the total of weighting `w`; +1 canopy, +2 ground.
fn column(w: Weighting) -> usize {
    match w {
        Weighting::Int => 0,
        Weighting::Count => 3,
        Weighting::Frac => 6,
        Weighting::Share => unreachable!("gediRat writes no intensity share"),
    }
}

/// gediMetric output: waveID → whitespace-separated columns (index 0 = column 1).
fn parse_metrics(path: &Path) -> HashMap<String, Vec<String>> {
    String::from_utf8(gunzip(path))
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| {
            let c: Vec<String> = l.split_whitespace().map(String::from).collect();
            (c[0].clone(), c)
        })
        .collect()
}

#[derive(Default)]
struct Tally {
    waves: usize,
    bins: usize,
    lines_identical: usize,
    max_dev_total: f64,
    max_dev_split: f64,
    truths: usize,
    truths_identical: usize,
    max_dev_ground: f64,
    max_dev_top: f64,
    max_dev_slope: f64,
    max_dev_cover: f64,
    rh: usize,
    rh_identical: usize,
    max_dev_rh: f64,
}

impl Tally {
    fn add(&mut self, o: &Tally) {
        self.waves += o.waves;
        self.bins += o.bins;
        self.lines_identical += o.lines_identical;
        self.truths += o.truths;
        self.truths_identical += o.truths_identical;
        self.rh += o.rh;
        self.rh_identical += o.rh_identical;
        for (a, b) in [
            (&mut self.max_dev_total, o.max_dev_total),
            (&mut self.max_dev_split, o.max_dev_split),
            (&mut self.max_dev_ground, o.max_dev_ground),
            (&mut self.max_dev_top, o.max_dev_top),
            (&mut self.max_dev_slope, o.max_dev_slope),
            (&mut self.max_dev_cover, o.max_dev_cover),
            (&mut self.max_dev_rh, o.max_dev_rh),
        ] {
            *a = a.max(b);
        }
    }
}

/// Compares one weighting of one simulated footprint with the golden wave file and metric line.
fn compare(sim: &SimulatedFootprint, w: Weighting, golden: &GoldenWave, metric: &[String], t: &mut Tally) {
    let ww = sim.get(w);
    assert_eq!(ww.wave.len(), golden.labels.len(), "{} {}: bin count", sim.id, w.name());
    assert_eq!(format!("{:.6}", sim.z0), golden.labels[0], "{}: first bin label", sim.id);
    let c = column(w);
    let peak = golden.cols.iter().map(|r| r[c].parse::<f64>().unwrap()).fold(0.0, f64::max);
    t.waves += 1;
    t.bins += ww.wave.len();
    for (k, row) in golden.cols.iter().enumerate() {
        // Labels as the reference computes them: (f32)top − (f32)k·res in f32.
        let label = sim.z0 as f32 - k as f32 * sim.dz as f32;
        assert_eq!(format!("{label:.6}"), golden.labels[k], "{} bin {k}: label", sim.id);
        let ours = [ww.wave[k], ww.canopy[k], ww.ground[k]];
        let printed = [format!("{:.10}", ours[0]), format!("{:.6}", ours[1]), format!("{:.6}", ours[2])];
        t.lines_identical += usize::from((0..3).all(|i| printed[i] == row[c + i]));
        for i in 0..3 {
            let dev = (ours[i] as f64 - row[c + i].parse::<f64>().unwrap()).abs() / peak;
            let max = if i == 0 { &mut t.max_dev_total } else { &mut t.max_dev_split };
            *max = max.max(dev);
            assert!(dev <= 1e-5, "{} {} bin {k} col {}: {} vs {}", sim.id, w.name(), c + i + 2, ours[i], row[c + i]);
        }
    }

    let tr = &ww.truth;
    let g: f64 = metric[1].parse().unwrap();
    let top: f64 = metric[2].parse().unwrap();
    let slope: f64 = metric[3].parse().unwrap();
    let cover: f64 = metric[4].parse().unwrap();
    let (ours_g, ours_top, ours_slope) = (tr.als_ground.unwrap(), tr.true_top.unwrap(), tr.slope_deg.unwrap());
    let devs = [
        (ours_g - g).abs(),
        (ours_top - top).abs(),
        (ours_slope as f64 - slope).abs(),
        (tr.als_cover as f64 - cover).abs(),
    ];
    t.max_dev_ground = t.max_dev_ground.max(devs[0]);
    t.max_dev_top = t.max_dev_top.max(devs[1]);
    t.max_dev_slope = t.max_dev_slope.max(devs[2]);
    t.max_dev_cover = t.max_dev_cover.max(devs[3]);
    t.truths += 4;
    let ours_printed =
        [format!("{ours_g:.2}"), format!("{ours_top:.2}"), format!("{ours_slope:.4}"), format!("{:.4}", tr.als_cover)];
    t.truths_identical += (0..4).filter(|&i| ours_printed[i] == metric[i + 1]).count();
    let id = &sim.id;
    assert!(devs[0] <= 0.005 + 1e-9, "{id} {}: ground {ours_g} vs {g}", w.name());
    assert!(devs[1] <= 0.005 + 1e-9, "{id} {}: top {ours_top} vs {top}", w.name());
    assert!(devs[2] <= 0.01, "{id} {}: slope {ours_slope} vs {slope}", w.name());
    assert!(devs[3] <= 1e-4, "{id} {}: cover {} vs {cover}", w.name(), tr.als_cover);

    let rh = ww.rh.expect("ground present");
    for k in 0..21 {
        let golden_rh = &metric[76 + k];
        let ours = format!("{:.2}", rh[5 * k]);
        t.rh += 1;
        t.rh_identical += usize::from(&ours == golden_rh);
        t.max_dev_rh = t.max_dev_rh.max((rh[5 * k] as f64 - golden_rh.parse::<f64>().unwrap()).abs());
        assert_eq!(&ours, golden_rh, "{id} {}: rhReal {}", w.name(), 5 * k);
    }
}

fn load(tile: &str) -> AlsPoints {
    read_points(&data(&format!("als/{tile}.laz"))).unwrap()
}

#[test]
fn gedirat_profile_matches_golden_files() {
    let mut total = Tally::default();
    for tile in TILES {
        let points = load(tile);
        let fps = footprints(tile);
        for variant in VARIANTS {
            let sims = simulate(&points, &fps, &config(Profile::Gedirat, variant)).unwrap();
            let waves = untar(&gunzip(&data(&format!("golden/{tile}/{variant}_waves.tar.gz"))));
            for w in Weighting::STUDY {
                let metrics = parse_metrics(&data(&format!("golden/{tile}/{variant}_{}_metric.txt.gz", w.name())));
                let mut t = Tally::default();
                for (fp, sim) in fps.iter().zip(&sims) {
                    let sim = sim.as_ref().unwrap_or_else(|e| panic!("{tile} {variant} {}: skipped {e:?}", fp.id));
                    let golden = parse_wave(&waves[&format!("wave.{}.wave", fp.id)]);
                    compare(sim, w, &golden, &metrics[&fp.id], &mut t);
                }
                println!(
                    "{tile:34} {variant:12} {:5}: {} waves, {} lines ({} identical as printed), max dev/peak total \
                    {:.1e} split {:.1e}; \
                     truths {}/{} identical (max |d| ground {:.3} top {:.3} slope {:.4} cover {:.5}); rhReal {}/{} \
                     identical",
                    w.name(),
                    t.waves,
                    t.bins,
                    t.lines_identical,
                    t.max_dev_total,
                    t.max_dev_split,
                    t.truths_identical,
                    t.truths,
                    t.max_dev_ground,
                    t.max_dev_top,
                    t.max_dev_slope,
                    t.max_dev_cover,
                    t.rh_identical,
                    t.rh
                );
                total.add(&t);
            }
        }
    }
    println!(
        "PARITY SUMMARY: {} waveforms, {} bins x 3 columns ({} lines identical as printed), max |dev|/peak {:.2e} \
        (totals) {:.2e} (canopy/ground); \
         {} truths ({} identical as printed; max |d| ground {:.4} m, top {:.4} m, slope {:.4} deg, cover {:.5}); {} \
         rhReal values ({} identical, max |d| {:.3} m)",
        total.waves,
        total.bins,
        total.lines_identical,
        total.max_dev_total,
        total.max_dev_split,
        total.truths,
        total.truths_identical,
        total.max_dev_ground,
        total.max_dev_top,
        total.max_dev_slope,
        total.max_dev_cover,
        total.rh,
        total.rh_identical,
        total.max_dev_rh
    );
    assert_eq!(total.waves, 3 * 3 * 3 * 52);
    // Measured: exact parity as printed, so assert it (stricter than the tolerances above).
    assert_eq!(total.lines_identical, total.bins, "waveform lines identical as printed");
    assert_eq!(total.truths_identical, total.truths, "truths identical as printed");
    assert_eq!(total.rh_identical, total.rh, "rhReal identical as printed");
}

/// Largest differences between two runs over the footprints both simulated.
#[derive(Default)]
struct Effect {
    compared: usize,
    same_grid: usize,
    max_wave_dev: f64,
    rh_changed: usize,
    max_rh_dev: f64,
    max_rh_inner_dev: f64,
    max_ground_dev: f64,
    max_top_dev: f64,
    skipped: usize,
}

fn effect(
    base: &[Result<SimulatedFootprint, gedisim::kernels::sim::SkipReason>],
    other: &[Result<SimulatedFootprint, gedisim::kernels::sim::SkipReason>],
    e: &mut Effect,
) {
    for (a, b) in base.iter().zip(other) {
        let (Ok(a), Ok(b)) = (a, b) else {
            e.skipped += usize::from(a.is_ok() != b.is_ok());
            continue;
        };
        for w in Weighting::STUDY {
            let (wa, wb) = (a.get(w), b.get(w));
            e.compared += 1;
            if wa.wave.len() == wb.wave.len() && (a.z0 - b.z0).abs() < 0.6 * a.dz {
                e.same_grid += 1;
                let peak = wa.wave.iter().fold(0f32, |m, &v| m.max(v)) as f64;
                let dev = wa.wave.iter().zip(&wb.wave).map(|(x, y)| (x - y).abs() as f64).fold(0.0, f64::max);
                e.max_wave_dev = e.max_wave_dev.max(dev / peak);
            }
            let (ra, rb) = (wa.rh.unwrap(), wb.rh.unwrap());
            let d = ra.iter().zip(&rb).map(|(x, y)| (x - y).abs() as f64).fold(0.0, f64::max);
            e.rh_changed += usize::from(d > 0.0);
            e.max_rh_dev = e.max_rh_dev.max(d);
            // RH0 and RH100 hinge on the faintest bins; RH1…RH99 show the bulk of the change.
            let inner = ra[1..100].iter().zip(&rb[1..100]).map(|(x, y)| (x - y).abs() as f64).fold(0.0, f64::max);
            e.max_rh_inner_dev = e.max_rh_inner_dev.max(inner);
            e.max_ground_dev =
                e.max_ground_dev.max((wa.truth.als_ground.unwrap() - wb.truth.als_ground.unwrap()).abs());
            e.max_top_dev = e.max_top_dev.max((wa.truth.true_top.unwrap() - wb.truth.true_top.unwrap()).abs());
        }
    }
}

/// Measures, on the golden tiles and footprints (all three variants), the effect of switching off
/// each reference quirk alone, and of the whole `default` profile, relative to `gedirat`.
/// Prints the table reported in docs/simulator.md.
#[test]
fn effect_of_each_default_decision() {
    let reference = Profile::Gedirat.quirks();
    let toggles: [(&str, Quirks); 8] = [
        ("batch_grid", Quirks { batch_grid: false, ..reference }),
        ("top_edge_labels", Quirks { top_edge_labels: false, ..reference }),
        ("f32_sums", Quirks { f32_sums: false, ..reference }),
        ("f32_tap_offsets", Quirks { f32_tap_offsets: false, ..reference }),
        ("divide_by_taps", Quirks { divide_by_taps: false, ..reference }),
        ("shifted_density_grid", Quirks { shifted_density_grid: false, ..reference }),
        ("frac_split_uncleaned", Quirks { frac_split_uncleaned: false, ..reference }),
        ("printed_metrics", Quirks { printed_metrics: false, ..reference }),
    ];
    let mut effects: Vec<(String, Effect)> = toggles.iter().map(|(n, _)| (n.to_string(), Effect::default())).collect();
    effects.push(("whole default profile".into(), Effect::default()));
    let mut default_secs = 0.0;
    let mut default_waves = 0;
    for tile in TILES {
        let points = load(tile);
        let fps = footprints(tile);
        for variant in VARIANTS {
            let base = simulate(&points, &fps, &config(Profile::Gedirat, variant)).unwrap();
            for (i, (_, q)) in toggles.iter().enumerate() {
                let cfg = SimConfig { quirks: *q, ..config(Profile::Gedirat, variant) };
                effect(&base, &simulate(&points, &fps, &cfg).unwrap(), &mut effects[i].1);
            }
            let started = std::time::Instant::now();
            let default = simulate(&points, &fps, &config(Profile::Default, variant)).unwrap();
            default_secs += started.elapsed().as_secs_f64();
            default_waves += default.iter().filter(|r| r.is_ok()).count();
            effect(&base, &default, &mut effects[8].1);
        }
    }
    println!(
        "| switched off | footprint-weightings | same bin grid | max |dwave|/peak | RH changed | max \
        |dRH0..100| m | max |dRH1..99| m | max |dground| m | max |dtop| m | skip changes |"
    );
    for (name, e) in &effects {
        println!(
            "| {name} | {} | {} | {:.1e} | {} | {:.2} | {:.2} | {:.4} | {:.2} | {} |",
            e.compared,
            e.same_grid,
            e.max_wave_dev,
            e.rh_changed,
            e.max_rh_dev,
            e.max_rh_inner_dev,
            e.max_ground_dev,
            e.max_top_dev,
            e.skipped
        );
    }
    println!(
        "default profile: {default_waves} footprints (3 weightings each) in {default_secs:.3} s = {:.3} ms per \
            footprint (this build, index build included)",
        1e3 * default_secs / default_waves as f64
    );
    // Every footprint of the golden tiles is inside its tile: the default profile keeps them all.
    assert_eq!(effects[8].1.skipped, 0);
    assert_eq!(effects[8].1.compared, 3 * 3 * 3 * 52);
}
