//! Planted geolocation errors: "real" GEDI shots simulated from a dataset's ALS at known shifted
//! positions and datum, passed through the seeded noise twin and written as a V2 L1B granule.
//! Shared by `tests/collocate.rs` and `benches/collocate.rs` (included by path).

use std::path::Path;

use gedisim::dataset::als::{AlsTable, BBox};
use gedisim::dataset::Dataset;
use gedisim::io::granule::{write_l1b_v2, Beam, GranuleMeta};
use gedisim::kernels::gedi::L1bShot;
use gedisim::kernels::geo::projection::Projector;
use gedisim::kernels::sim::{self, Footprint, Profile, SimConfig, Weighting};
use gedisim::kernels::waveform::l2a::Noise;
use gedisim::kernels::waveform::noise_twin::{NoiseShape, ShotTwin, GEDI_BIN_M};

/// One planted beam: shots evenly spaced on a segment, reported positions.
#[derive(Debug, Clone)]
pub struct PlantedBeam {
    /// Beam group name (`BEAM0101` …).
    pub name: &'static str,
    /// Reported position of the first shot (m, EPSG:2154).
    pub start: (f64, f64),
    /// Reported position of the last shot.
    pub end: (f64, f64),
    /// Number of shots.
    pub shots: usize,
    /// Waveform energy above the noise (counts).
    pub energy: f64,
}

/// The error planted in every shot.
#[derive(Debug, Clone, Copy)]
pub struct Plant {
    /// Where the waveform was formed minus the reported position (m).
    pub shift: (f64, f64),
    /// GEDI ellipsoidal height minus ALS height of the same surface (m).
    pub datum: f64,
    /// The geoid height written to the L1B `geophys_corr/geoid`.
    pub l1b_geoid: f32,
    /// Noise σ (counts) on a mean of 230 counts.
    pub noise_sigma: f64,
    /// Seed of the first shot's noise (shot k uses seed + k).
    pub seed: u64,
}

/// Noise-only samples before the simulated waveform in each record.
const LEADING_SAMPLES: usize = 100;

/// First shot number; beam b, shot k has `FIRST_SHOT + b·100_000 + k`.
pub const FIRST_SHOT: u64 = 19_640_500_100_100_000;

/// Simulates the planted shots from `ds`'s ALS (default profile, count weighting) and writes them
/// as a V2 L1B granule at `dest`. Returns the reported positions of the shots, beam by beam.
pub fn write_planted_l1b(ds: &Dataset, beams: &[PlantedBeam], plant: &Plant, dest: &Path) -> Vec<Vec<(f64, f64)>> {
    let als = AlsTable::open(ds).expect("ALS table");
    let proj = Projector::new(2154).unwrap();
    let cfg = SimConfig::new(Profile::Default);
    let mut out_beams = Vec::new();
    let mut reported_all = Vec::new();
    for (b, beam) in beams.iter().enumerate() {
        let reported: Vec<(f64, f64)> = (0..beam.shots)
            .map(|k| {
                let t = k as f64 / (beam.shots - 1).max(1) as f64;
                (beam.start.0 + t * (beam.end.0 - beam.start.0), beam.start.1 + t * (beam.end.1 - beam.start.1))
            })
            .collect();
        let truth: Vec<Footprint> = reported
            .iter()
            .enumerate()
            .map(|(k, &(x, y))| Footprint::at(k.to_string(), x + plant.shift.0, y + plant.shift.1))
            .collect();
        let half = 20.0;
        let boxes: Vec<BBox> = truth.iter().map(|f| [f.x - half, f.y - half, f.x + half, f.y + half]).collect();
        let (points, _) = als.points_near(&boxes).expect("ALS points");
        let sims = sim::simulate(&points, &truth, &cfg).expect("simulate");
        let mut shots = Vec::new();
        for (k, (s, &(x, y))) in sims.iter().zip(&reported).enumerate() {
            let s = s.as_ref().expect("planted shots are on the ALS");
            let wave: Vec<f64> = s.get(Weighting::Count).wave.iter().map(|&v| v as f64).collect();
            let signal_len = (((wave.len() - 1) as f64 * s.dz) / GEDI_BIN_M).floor() as usize + 1;
            let twin = ShotTwin {
                energy_total: beam.energy,
                noise: Noise { mean: 230.0, stddev: plant.noise_sigma },
                sample_count: LEADING_SAMPLES + signal_len + 60,
                tx_pulse: None,
                quantum: 1.0,
                noise_shape: NoiseShape::WHITE,
            };
            let seed = plant.seed + (b * 100_000 + k) as u64;
            let made = twin.apply(&wave, s.dz, LEADING_SAMPLES as isize, seed).expect("noise twin");
            let n = made.wave.len();
            // Record sample i is simulated sample (i − LEADING)·GEDI_BIN_M below the first label.
            let bin0 = s.z0 + LEADING_SAMPLES as f64 * GEDI_BIN_M + plant.datum;
            let (lon, lat) = proj.unproject(x, y).unwrap();
            shots.push(L1bShot {
                shot_number: FIRST_SHOT + (b * 100_000 + k) as u64,
                delta_time: 1.0e8 + k as f64 / 242.0,
                rx_waveform: made.wave,
                tx_waveform: Vec::new(),
                latitude_bin0: lat,
                longitude_bin0: lon,
                latitude_lastbin: lat,
                longitude_lastbin: lon,
                elevation_bin0: bin0,
                elevation_lastbin: bin0 - (n - 1) as f64 * GEDI_BIN_M,
                noise_mean_corrected: 230.0,
                noise_stddev_corrected: plant.noise_sigma,
                geoid: plant.l1b_geoid,
                ..Default::default()
            });
        }
        out_beams.push(Beam::new(beam.name, shots));
        reported_all.push(reported);
    }
    write_l1b_v2(dest, &out_beams, &GranuleMeta::default()).expect("write the planted L1B");
    reported_all
}
