//! NASA's stored L2A results for the shared real V1 L1B/L2A pair (tests/data/gedi, PROVENANCE.md):
//! each joined shot's waveform, noise, geolocation and the stored values for a1..a6.

use std::path::PathBuf;

use gedisim::kernels::waveform::l2a::{Noise, WaveformGeolocation};

/// L1B file of the shared pair.
pub const L1B: &str = "GEDI01_B_2019108080338_O01964_T05337_02_003_01_sub.h5";
/// L2A file of the shared pair.
pub const L2A: &str = "GEDI02_A_2019108080338_O01964_T05337_02_001_01_sub.h5";
/// Beams used to fit constants (calibration half); the other beams are the held-out half.
pub const CALIBRATION_BEAMS: [&str; 4] = ["BEAM0001", "BEAM0011", "BEAM0110", "BEAM1011"];

/// NASA's stored L2A values of one shot for one algorithm.
#[derive(Debug, Clone)]
pub struct NasaL2a {
    pub toploc: f64,
    pub botloc: f64,
    pub zcross: f64,
    pub num_modes: usize,
    pub selected_mode: usize,
    pub modelocs: Vec<f64>,
    pub rx_cumulative: Vec<f64>,
    pub rh_cm: Vec<i32>,
    pub sensitivity: f64,
    pub min_detection_threshold: f64,
}

/// One shot present in both files.
#[derive(Debug, Clone)]
pub struct RealShot {
    pub beam: String,
    pub shot_number: u64,
    pub wave: Vec<f32>,
    pub tx: Vec<f32>,
    pub noise: Noise,
    pub geo: WaveformGeolocation,
    pub energy_total: f64,
    /// Index 0 = a1.
    pub nasa: Vec<NasaL2a>,
}

impl RealShot {
    /// Whether the shot belongs to the calibration half.
    pub fn is_calibration(&self) -> bool {
        CALIBRATION_BEAMS.contains(&self.beam.as_str())
    }
}

fn data_path(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/gedi").join(name)
}

fn read<T: hdf5::H5Type>(group: &hdf5::Group, name: &str) -> Vec<T> {
    group.dataset(name).and_then(|d| d.read_raw::<T>()).unwrap_or_else(|e| panic!("{}: {name}: {e}", group.name()))
}

/// Every shot of the pair that joins on `shot_number`, in file order.
pub fn load_real_shots() -> Vec<RealShot> {
    let l1 = gedisim::io::gedi::without_locks().open(data_path(L1B)).expect("open L1B");
    let l2 = gedisim::io::gedi::without_locks().open(data_path(L2A)).expect("open L2A");
    let mut shots = Vec::new();
    let beams = l1.member_names().expect("L1B members");
    for beam in beams.iter().filter(|b| b.starts_with("BEAM")) {
        let b1 = l1.group(beam).expect("L1B beam");
        let b2 = l2.group(beam).expect("L2A beam");
        let sn1: Vec<u64> = read(&b1, "shot_number");
        let sn2: Vec<u64> = read(&b2, "shot_number");
        let wave: Vec<f32> = read(&b1, "rxwaveform");
        let start: Vec<u64> = read(&b1, "rx_sample_start_index");
        let count: Vec<u16> = read(&b1, "rx_sample_count");
        let tx: Vec<f32> = read(&b1, "txwaveform");
        let tx_start: Vec<u64> = read(&b1, "tx_sample_start_index");
        let tx_count: Vec<u16> = read(&b1, "tx_sample_count");
        let mean: Vec<f64> = read(&b1, "noise_mean_corrected");
        let sd: Vec<f64> = read(&b1, "noise_stddev_corrected");
        let geo = |n: &str| -> Vec<f64> { read(&b1, &format!("geolocation/{n}")) };
        let (z0, zn) = (geo("elevation_bin0"), geo("elevation_lastbin"));
        let (la0, lan) = (geo("latitude_bin0"), geo("latitude_lastbin"));
        let (lo0, lon) = (geo("longitude_bin0"), geo("longitude_lastbin"));
        let energy: Vec<f64> = read(&b2, "energy_total");
        let algs: Vec<AlgArrays> = (1..=6).map(|a| AlgArrays::read(&b2, a)).collect();
        for (i, &sn) in sn1.iter().enumerate() {
            let Some(j) = sn2.iter().position(|&s| s == sn) else {
                continue;
            };
            let s0 = start[i] as usize - 1; // 1-based in the file
            let n = usize::from(count[i]);
            let t0 = tx_start[i] as usize - 1;
            shots.push(RealShot {
                beam: beam.clone(),
                shot_number: sn,
                wave: wave[s0..s0 + n].to_vec(),
                tx: tx[t0..t0 + usize::from(tx_count[i])].to_vec(),
                noise: Noise { mean: mean[i], stddev: sd[i] },
                geo: WaveformGeolocation {
                    sample_count: n,
                    elevation_bin0: z0[i],
                    elevation_lastbin: zn[i],
                    latitude_bin0: la0[i],
                    latitude_lastbin: lan[i],
                    longitude_bin0: lo0[i],
                    longitude_lastbin: lon[i],
                },
                energy_total: energy[j],
                nasa: algs.iter().map(|a| a.shot(j)).collect(),
            });
        }
    }
    shots
}

/// The per-algorithm arrays of one beam.
struct AlgArrays {
    toploc: Vec<f64>,
    botloc: Vec<f64>,
    zcross: Vec<f64>,
    num_modes: Vec<u8>,
    selected_mode: Vec<u8>,
    modelocs: Vec<f64>,
    modes_per_shot: usize,
    cumulative: Vec<f64>,
    rh: Vec<i32>,
    sensitivity: Vec<f64>,
    min_detection_threshold: Vec<f64>,
}

impl AlgArrays {
    fn read(beam: &hdf5::Group, alg: usize) -> Self {
        let g = beam.group(&format!("rx_processing_a{alg}")).expect("rx_processing group");
        let geo = beam.group("geolocation").expect("geolocation group");
        let modelocs: Vec<f64> = read(&g, "rx_modelocs");
        let n = read::<f64>(&g, "toploc").len();
        Self {
            toploc: read(&g, "toploc"),
            botloc: read(&g, "botloc"),
            zcross: read(&g, "zcross"),
            num_modes: read(&g, "rx_nummodes"),
            selected_mode: read(&g, "selected_mode"),
            modes_per_shot: modelocs.len() / n.max(1),
            modelocs,
            cumulative: read(&g, "rx_cumulative"),
            rh: read(&geo, &format!("rh_a{alg}")),
            sensitivity: read(&geo, &format!("sensitivity_a{alg}")),
            min_detection_threshold: read(&g, "min_detection_threshold"),
        }
    }

    fn shot(&self, j: usize) -> NasaL2a {
        let m = self.modes_per_shot;
        NasaL2a {
            toploc: self.toploc[j],
            botloc: self.botloc[j],
            zcross: self.zcross[j],
            num_modes: usize::from(self.num_modes[j]),
            selected_mode: usize::from(self.selected_mode[j]),
            modelocs: self.modelocs[j * m..(j + 1) * m].to_vec(),
            rx_cumulative: self.cumulative[j * 101..(j + 1) * 101].to_vec(),
            rh_cm: self.rh[j * 101..(j + 1) * 101].to_vec(),
            sensitivity: self.sensitivity[j],
            min_detection_threshold: self.min_detection_threshold[j],
        }
    }
}
