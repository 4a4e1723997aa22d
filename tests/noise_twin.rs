//! Self-consistency of the noise twin (mode a) on the 300 real shots: each real waveform is
//! denoised (noise removed and smoothed), re-noised by a twin of its own shot (energy, μ, σ, record
//! length) and processed by the L2A kernel; its sensitivity and RH50/RH98 are compared with NASA's
//! stored values.
//!
//! Run: `cargo test --test noise_twin -- --nocapture`

mod common;

use common::nasa::load_real_shots;
use gedisim::process::denoise::{denoise, DenoiseSettings};
use gedisim::process::l2a::{AlgorithmSettings, L2aProcessor};
use gedisim::process::noise_twin::{LinkMarginTwin, ShotTwin, GEDI_BIN_M, SIM_BIN_M};

const SENSITIVITY_TOL: f64 = 0.01;
const RH_TOL_CM: i32 = 30;

#[test]
fn shot_twin_of_each_denoised_real_waveform_reproduces_nasa_l2a() {
    let shots = load_real_shots();
    let settings = AlgorithmSettings::all_gedi();
    let mut processor = L2aProcessor::new();
    let mut outcomes = Vec::new();
    // Per algorithm: shots processed, sensitivity ok, RH50 ok, RH98 ok, all three ok.
    let mut counts = [[0usize; 5]; 6];
    for (index, shot) in shots.iter().enumerate() {
        let clean = denoise(&shot.wave, shot.noise, DenoiseSettings::default());
        let twin = ShotTwin {
            energy_total: shot.energy_total,
            noise: shot.noise,
            sample_count: shot.wave.len(),
            tx_pulse: None,
            quantum: 0.0,
        };
        // The cleaned waveform is already on the GEDI grid and spans the whole record.
        let made = twin
            .apply(&clean, GEDI_BIN_M, 0, 1000 + index as u64)
            .expect("twin of a real shot");
        processor.process_all(&made.wave, made.noise, &shot.geo, &settings, &mut outcomes);
        for (alg, outcome) in outcomes.iter().enumerate() {
            let Ok(r) = outcome else { continue };
            let nasa = &shot.nasa[alg];
            let sens = (r.sensitivity - nasa.sensitivity).abs() <= SENSITIVITY_TOL;
            let rh50 = (r.rh_cm[50] - nasa.rh_cm[50]).abs() <= RH_TOL_CM;
            let rh98 = (r.rh_cm[98] - nasa.rh_cm[98]).abs() <= RH_TOL_CM;
            let c = &mut counts[alg];
            c[0] += 1;
            c[1] += usize::from(sens);
            c[2] += usize::from(rh50);
            c[3] += usize::from(rh98);
            c[4] += usize::from(sens && rh50 && rh98);
        }
    }
    let n = shots.len() as f64;
    let pct = |c: usize| 100.0 * c as f64 / n;
    println!(
        "\nNoise twin (mode a) self-consistency on {} real shots (% of shots)",
        shots.len()
    );
    println!(
        "alg | processed | sensitivity ±{SENSITIVITY_TOL} | RH50 ±0.3 m | RH98 ±0.3 m | all three"
    );
    for (alg, c) in counts.iter().enumerate() {
        println!(
            "a{} | {:5.1} | {:5.1} | {:5.1} | {:5.1} | {:5.1}",
            alg + 1,
            pct(c[0]),
            pct(c[1]),
            pct(c[2]),
            pct(c[3]),
            pct(c[4])
        );
    }
    // Floors just below the measured rates (docs/l2a.md).
    // Measured: 100.0, 95.0, 93.0, 100.0, 63.3, 87.7 % (a5/a6: their 2σ/4σ back thresholds make the
    // lowest weak mode depend on the noise draw, see docs/l2a.md).
    let floors = [99.5, 94.5, 92.5, 99.5, 62.5, 87.0];
    for (alg, c) in counts.iter().enumerate() {
        assert!(
            pct(c[4]) >= floors[alg],
            "a{}: {:.1} % of shots agree",
            alg + 1,
            pct(c[4])
        );
    }
}

#[test]
fn link_margin_twin_is_processed_like_a_gedi_waveform() {
    // A canopy (top) and a ground return on 0.15 m bins, as a simulator would give.
    let sim: Vec<f64> = (0..300)
        .map(|i| {
            let z = i as f64;
            0.3 * (-0.5 * ((z - 100.0) / 15.0).powi(2)).exp()
                + (-0.5 * ((z - 230.0) / 6.0).powi(2)).exp()
        })
        .collect();
    let mut processor = L2aProcessor::new();
    for db in [8.0, 3.0] {
        let twin = LinkMarginTwin::new(db, 0.5);
        let made = twin.apply(&sim, SIM_BIN_M, 11).expect("link-margin twin");
        let geo = gedisim::process::l2a::WaveformGeolocation::from_spacing(
            made.wave.len(),
            100.0,
            GEDI_BIN_M,
        );
        let r = processor
            .process(&made.wave, made.noise, &geo, &AlgorithmSettings::a1())
            .expect("processed");
        // The ground peak sits at 230 bins of 0.15 m below the top, 200 noise samples later.
        let ground = 200.0 + 230.0 * SIM_BIN_M / GEDI_BIN_M;
        println!(
            "link margin {db} dB: zcross {:.2} (ground at {ground:.1}), sensitivity {:.3}",
            r.zcross, r.sensitivity
        );
        assert!((r.zcross - ground).abs() < 3.0, "{db} dB: ground not found");
        assert!(r.sensitivity > 0.0 && r.sensitivity < 1.0, "{db} dB");
    }
}
