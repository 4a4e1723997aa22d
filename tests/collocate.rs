//! Collocation: the separable raster against the brute-force simulator, and planted offsets on
//! real tiles recovered through the CLI at the track, beam and shot levels.
//!
//! Run: `cargo test --test collocate -- --nocapture` (prints the figures quoted in
//! docs/collocation.md).

mod common;

use common::data;
use gedisim::collocate::raster::offset_waves;
use gedisim::collocate::CollocateConfig;
use gedisim::sim::{self, Footprint, Weighting};

/// Largest |raster − brute force| over the peak of the brute-force waveform, both normalised to a
/// unit integral, on the absolute bins.
fn max_relative_difference(points: &sim::AlsPoints, centre: (f64, f64), offsets: &[(usize, usize)], nudge: f64) -> f64 {
    let cfg = CollocateConfig::new(10.0, 1.0).unwrap();
    let model = CollocateConfig::model();
    let cand: Vec<u32> = (0..points.len() as u32).collect();
    let waves = offset_waves(&points.x, &points.y, &points.z, &cand, centre, &cfg.grid, &model).expect("points contribute");
    let mut worst = 0f64;
    for &(i, j) in offsets {
        let fp = Footprint { id: format!("{i},{j}"), x: centre.0 + cfg.grid.offset(i) + nudge, y: centre.1 + cfg.grid.offset(j) };
        let brute = sim::simulate(points, &[fp], &model).unwrap().remove(0).expect("simulated");
        let b = &brute.get(Weighting::Count).wave;
        // Brute-force bin k is labelled by its centre z0 − k·dz: absolute bin round(label/dz − ½).
        let bin_of = |k: usize| ((brute.z0 - k as f64 * brute.dz) / brute.dz - 0.5).round() as i64;
        let mine = waves.column(i * cfg.grid.n() + j);
        let total: f64 = mine.iter().map(|&v| v as f64).sum::<f64>() * waves.dz;
        let peak = b.iter().cloned().fold(0f32, f32::max) as f64;
        let mut seen = 0.0;
        for (k, &v) in b.iter().enumerate() {
            let row = bin_of(k) - waves.first_bin;
            let m = if row >= 0 && (row as usize) < mine.len() { mine[row as usize] as f64 / total } else { 0.0 };
            worst = worst.max((m - v as f64).abs() / peak);
            seen += m;
        }
        // Every bin of the raster lies inside the brute-force waveform.
        let all: f64 = mine.iter().map(|&v| v as f64).sum::<f64>() / total;
        worst = worst.max((seen - all).abs());
    }
    worst
}

#[test]
fn raster_matches_brute_force_simulation_at_every_tested_offset() {
    let offsets = [(10, 10), (14, 7), (0, 0), (20, 20), (0, 20), (3, 16), (10, 0)];
    let mut report = Vec::new();
    for (tile, centre) in [("lidarforfuel_1_42", (817622.0, 6460817.0)), ("lidarforfuel_2_bas_lig", (368528.0, 6807456.0))] {
        let points = gedisim::ingest::las::read_points(&data(&format!("als/{tile}.laz"))).unwrap();
        let points = gedisim::simulate::drop_ingest_classes(&points);
        let worst = max_relative_difference(&points, centre, &offsets, 0.0);
        report.push(format!("{tile}: {worst:.2e}"));
        assert!(worst < 1e-4, "{tile}: raster differs from the brute-force simulator by {worst:e} of the peak");
        // The comparison is sharp: the brute force 5 cm away already differs by more.
        let nudged = max_relative_difference(&points, centre, &offsets[..1], 0.05);
        assert!(nudged > 1e-4, "{tile}: a 5 cm displacement is not detected ({nudged:e})");
    }
    println!("raster vs brute-force simulation, max |difference| / peak over {} offsets: {}", offsets.len(), report.join(", "));
}

