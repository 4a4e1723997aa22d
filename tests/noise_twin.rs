//! Self-consistency of the noise twin (mode a) on the 300 real shots: each real waveform is
//! denoised (features above the noise kept, mean removed), re-noised by a twin of its own shot
//! (energy, μ, σ, record length, noise shaped like real records) and processed by the L2A kernel;
//! its sensitivity and RH50/RH98 are compared with NASA's stored values, and with a second twin of
//! another seed (how much one noise draw decides the result). Also: the noise of the real records
//! has the shape the twin uses.
//!
//! Run: `cargo test --test noise_twin -- --nocapture`

mod common;

use common::nasa::{load_real_shots, RealShot};
use gedisim::kernels::waveform::denoise::{denoise, DenoiseSettings};
use gedisim::kernels::waveform::l2a::{AlgorithmSettings, GaussianKernel, L2aOutcome, L2aProcessor};
use gedisim::kernels::waveform::noise_twin::{LinkMarginTwin, NoiseShape, ShotTwin, GEDI_BIN_M, SIM_BIN_M};

const SENSITIVITY_TOL: f64 = 0.01;
const RH_TOL_CM: i32 = 30;

/// Sensitivity, RH50 and RH98 of two outcomes agree within the tolerances.
fn agree(sens: (f64, f64), rh50: (i32, i32), rh98: (i32, i32)) -> [bool; 3] {
    [
        (sens.0 - sens.1).abs() <= SENSITIVITY_TOL,
        (rh50.0 - rh50.1).abs() <= RH_TOL_CM,
        (rh98.0 - rh98.1).abs() <= RH_TOL_CM,
    ]
}

/// Noise draws per shot: rates are averaged over them, so that they do not hang on one seed.
const DRAWS: u64 = 4;

/// Per algorithm, summed over [`DRAWS`] twins of each shot: [processed, sensitivity ok, RH50 ok,
/// RH98 ok, all three ok, misses with another ground mode] against NASA, and all three ok between the twins of draws
/// 2k and 2k+1.
fn twin_rates(shots: &[RealShot], shape: NoiseShape) -> ([[usize; 6]; 6], [usize; 6]) {
    let settings = AlgorithmSettings::all_gedi();
    let mut processor = L2aProcessor::new();
    let mut outcomes: Vec<Vec<L2aOutcome>> = vec![Vec::new(); DRAWS as usize];
    let mut counts = [[0usize; 6]; 6];
    let mut between = [0usize; 6];
    for (index, shot) in shots.iter().enumerate() {
        let clean = denoise(&shot.wave, shot.noise, DenoiseSettings::default());
        let twin = ShotTwin {
            energy_total: shot.energy_total,
            noise: shot.noise,
            sample_count: shot.wave.len(),
            tx_pulse: None,
            quantum: 0.0,
            noise_shape: shape,
        };
        for (draw, out) in outcomes.iter_mut().enumerate() {
            // The cleaned waveform is already on the GEDI grid and spans the whole record.
            let seed = 1000 + index as u64 + 1_000_000 * draw as u64;
            let made = twin.apply(&clean, GEDI_BIN_M, 0, seed).expect("twin of a real shot");
            processor.process_all(&made.wave, made.noise, &shot.geo, &settings, out);
        }
        for alg in 0..settings.len() {
            let nasa = &shot.nasa[alg];
            for draw in 0..outcomes.len() {
                let Ok(r) = &outcomes[draw][alg] else {
                    continue;
                };
                let ok = agree(
                    (r.sensitivity, nasa.sensitivity),
                    (r.rh_cm[50], nasa.rh_cm[50]),
                    (r.rh_cm[98], nasa.rh_cm[98]),
                );
                let c = &mut counts[alg];
                c[0] += 1;
                for k in 0..3 {
                    c[k + 1] += usize::from(ok[k]);
                }
                c[4] += usize::from(ok.iter().all(|&v| v));
                // A miss whose ground mode is another one (more than 2 samples away).
                c[5] += usize::from(!ok.iter().all(|&v| v) && (r.zcross - nasa.zcross).abs() > 2.0);
                if draw % 2 == 1 {
                    if let Ok(o) = &outcomes[draw - 1][alg] {
                        let ok = agree(
                            (r.sensitivity, o.sensitivity),
                            (r.rh_cm[50], o.rh_cm[50]),
                            (r.rh_cm[98], o.rh_cm[98]),
                        );
                        between[alg] += usize::from(ok.iter().all(|&v| v));
                    }
                }
            }
        }
    }
    (counts, between)
}

#[test]
fn shot_twin_of_each_denoised_real_waveform_reproduces_nasa_l2a() {
    let shots = load_real_shots();
    let n = shots.len() as f64;
    let pct = |c: usize| 100.0 * c as f64 / (n * DRAWS as f64);
    let pct_pairs = |c: usize| 100.0 * c as f64 / (n * (DRAWS / 2) as f64);
    let mut measured = Vec::new();
    for (name, shape) in [("GEDI_V1 (measured)", NoiseShape::GEDI_V1), ("WHITE", NoiseShape::WHITE)] {
        let (counts, between) = twin_rates(&shots, shape);
        println!(
            "\nNoise twin (mode a, noise shape {name}) on {} real shots, {DRAWS} noise draws each (% of shot-draws)",
            shots.len()
        );
        println!(
            "alg | processed | sensitivity ±{SENSITIVITY_TOL} | RH50 ±0.3 m | RH98 ±0.3 m | all three | twin vs \
                twin (another seed) | misses with another ground mode (% of misses)"
        );
        for (alg, c) in counts.iter().enumerate() {
            println!(
                "a{} | {:5.1} | {:5.1} | {:5.1} | {:5.1} | {:5.1} | {:5.1} | {:5.1}",
                alg + 1,
                pct(c[0]),
                pct(c[1]),
                pct(c[2]),
                pct(c[3]),
                pct(c[4]),
                pct_pairs(between[alg]),
                100.0 * c[5] as f64 / (c[0] - c[4]).max(1) as f64
            );
        }
        measured.push((counts, between));
    }
    // Floors just below the rates measured with the real records' noise shape (docs/l2a.md).
    // Measured (4 draws): all three 99.9, 98.8, 96.8, 99.8, 67.8, 91.5 %; twin vs twin 99.7, 98.0,
    // 95.3, 99.7, 57.2, 89.3 %. a5: the noise draw decides the lowest mode in ~40 % of shots, so
    // no twin with its own noise can agree with NASA's one draw much more often (docs/l2a.md).
    let floors = [99.5, 98.4, 96.4, 99.4, 67.4, 91.1];
    let floors_between = [99.3, 97.6, 94.9, 99.3, 56.8, 88.9];
    let (counts, between) = &measured[0];
    for alg in 0..6 {
        assert_eq!(counts[alg][0], shots.len() * DRAWS as usize, "a{}: every twin is processed", alg + 1);
        assert!(
            pct(counts[alg][4]) >= floors[alg],
            "a{}: {:.1} % of shots agree with NASA",
            alg + 1,
            pct(counts[alg][4])
        );
        assert!(
            pct_pairs(between[alg]) >= floors_between[alg],
            "a{}: {:.1} % of shots agree between two twins",
            alg + 1,
            pct_pairs(between[alg])
        );
    }
}

/// The noise of the real records (the samples before the signal) has the shape the twin uses:
/// per-sample σ over the reported σ, and the σ of the Gaussian filter whose autocorrelation
/// exp(−l²/(4σ²)) fits lags 1–4 (least squares in −ln ρ). Measured on the calibration half,
/// checked on the held-out half.
#[test]
fn real_record_noise_has_the_measured_shape() {
    let shots = load_real_shots();
    let measure = |calibration: bool| {
        let (mut lags, mut count) = ([0.0f64; 5], 0usize);
        for s in shots.iter().filter(|s| s.is_calibration() == calibration) {
            // Noise only: up to 40 samples above NASA's signal start, at most 150 samples.
            let end = (s.nasa[0].toploc as usize).saturating_sub(40).min(150);
            let x: Vec<f64> = s.wave[..end].iter().map(|&w| (f64::from(w) - s.noise.mean) / s.noise.stddev).collect();
            let m = x.iter().sum::<f64>() / x.len() as f64;
            let x: Vec<f64> = x.iter().map(|v| v - m).collect();
            for (l, lag) in lags.iter_mut().enumerate() {
                *lag += x.iter().zip(&x[l..]).map(|(a, b)| a * b).sum::<f64>() / x.len() as f64;
            }
            count += 1;
        }
        // Lag 0 sums each shot's variance: the pooled per-sample σ.
        let ratio = (lags[0] / count as f64).sqrt();
        let rho: Vec<f64> = lags[1..].iter().map(|l| l / lags[0]).collect();
        // −ln ρ(l) = l²·a with a = 1/(4σ²): least squares over l = 1..4.
        let (num, den) = (1..=4).fold((0.0, 0.0), |(n, d), l| {
            let l2 = (l * l) as f64;
            (n - rho[l - 1].ln() * l2, d + l2 * l2)
        });
        let correlation = (1.0 / (4.0 * num / den)).sqrt();
        (ratio, correlation, rho)
    };
    let (cal_ratio, cal_corr, cal_rho) = measure(true);
    let (held_ratio, held_corr, held_rho) = measure(false);
    println!(
        "real record noise, calibration half: per-sample σ = {cal_ratio:.3}·noise_stddev, filter σ \
        {cal_corr:.3} samples, autocorrelation lags 1–4 {cal_rho:.3?}"
    );
    println!(
        "real record noise, held-out half:    per-sample σ = {held_ratio:.3}·noise_stddev, filter σ \
        {held_corr:.3} samples, autocorrelation lags 1–4 {held_rho:.3?}"
    );
    let shape = NoiseShape::GEDI_V1;
    assert!((cal_ratio - shape.per_sample_ratio).abs() < 0.01, "{cal_ratio}");
    assert!((cal_corr - shape.correlation).abs() < 0.01, "{cal_corr}");
    // The held-out half has the same shape within 10 %.
    assert!((held_ratio / cal_ratio - 1.0).abs() < 0.1, "{held_ratio}");
    assert!((held_corr / cal_corr - 1.0).abs() < 0.1, "{held_corr}");

    // What L2A sees: the noise after its smoothing (widths 3.5 and 6.5), in units of σ, on the
    // real records (median over shots) and on the twins' noise of each shape.
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let smoothed_sd = |x: &[f32], sd: f64, width: f64| {
        let mut out = Vec::new();
        let k = GaussianKernel::for_width(width);
        k.smooth_into(x, &mut out);
        let h = k.half_width();
        let inner = &out[h..out.len() - h];
        let m = inner.iter().sum::<f64>() / inner.len() as f64;
        (inner.iter().map(|v| (v - m).powi(2)).sum::<f64>() / inner.len() as f64).sqrt() / sd
    };
    for width in [3.5, 6.5] {
        let real = median(
            shots
                .iter()
                .map(|s| {
                    let end = (s.nasa[0].toploc as usize).saturating_sub(40).min(150);
                    smoothed_sd(&s.wave[..end], s.noise.stddev, width)
                })
                .collect(),
        );
        let twin_sd = |shape: NoiseShape| {
            let noise = gedisim::kernels::waveform::l2a::Noise { mean: 200.0, stddev: 3.0 };
            let twin = ShotTwin {
                energy_total: 1e-9,
                noise,
                sample_count: 150,
                tx_pulse: None,
                quantum: 0.0,
                noise_shape: shape,
            };
            median(
                (0..300)
                    .map(|seed| {
                        let t = twin.apply(&[1.0], GEDI_BIN_M, 0, seed).expect("twin");
                        smoothed_sd(&t.wave, 3.0, width)
                    })
                    .collect(),
            )
        };
        let (shaped, white) = (twin_sd(NoiseShape::GEDI_V1), twin_sd(NoiseShape::WHITE));
        println!(
            "noise after L2A smoothing of width {width} (σ units, median): real records {real:.3}, \
             twin GEDI_V1 {shaped:.3}, twin WHITE {white:.3}"
        );
        // Measured: the shaped twin is ~10 % below the real level, white noise ~25 % below.
        assert!(
            (shaped - real).abs() < (white - real).abs() / 2.0,
            "the measured shape at least halves white noise's gap: {shaped} {white} vs {real}"
        );
    }
}

#[test]
fn link_margin_twin_is_processed_like_a_gedi_waveform() {
    // A canopy (top) and a ground return on 0.15 m bins, as a simulator would give.
    let sim: Vec<f64> = (0..300)
        .map(|i| {
            let z = i as f64;
            0.3 * (-0.5 * ((z - 100.0) / 15.0).powi(2)).exp() + (-0.5 * ((z - 230.0) / 6.0).powi(2)).exp()
        })
        .collect();
    let mut processor = L2aProcessor::new();
    for db in [8.0, 3.0] {
        let twin = LinkMarginTwin::new(db, 0.5);
        let made = twin.apply(&sim, SIM_BIN_M, 11).expect("link-margin twin");
        let geo =
            gedisim::kernels::waveform::l2a::WaveformGeolocation::from_spacing(made.wave.len(), 100.0, GEDI_BIN_M);
        let r = processor.process(&made.wave, made.noise, &geo, &AlgorithmSettings::a1()).expect("processed");
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
