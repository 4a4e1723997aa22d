//! `gedi_noise_twin(wave, z0, dz, energy_total, noise_mean, noise_stddev, sample_count, start,
//! seed [, quantum [, noise_correlation, noise_ratio]])`: the twin of one real shot
//! ([`ShotTwin`], mode (a) of [`crate::kernels::waveform::noise_twin`]); the noise is correlated
//! like real GEDI records ([`NoiseShape::GEDI_V1`]) unless `noise_correlation` (samples; 0 =
//! white) and `noise_ratio` (per-sample σ over `noise_stddev`) say otherwise. `wave`'s sample 0
//! goes to record sample `start` (negative: above the record; simulated samples outside the record
//! must be zero, as a simulation's empty buffers are). The struct it returns: [`super::twin`].

use datafusion::logical_expr::Documentation;

use super::twin::{record_elevations, Column, Made, TwinFunction};
use super::DOC_SECTION;
use crate::kernels::waveform::l2a::Noise;
use crate::kernels::waveform::noise_twin::{NoiseShape, ShotTwin, TwinError};

/// `gedi_noise_twin`.
pub static NOISE_TWIN: TwinFunction = TwinFunction {
    name: "gedi_noise_twin",
    required: &["wave", "z0", "dz", "energy_total", "noise_mean", "noise_stddev", "sample_count", "start", "seed"],
    optional: &["quantum", "noise_correlation", "noise_ratio"],
    make: shot_twin,
    documentation,
};

fn documentation() -> Documentation {
    Documentation::builder(
        DOC_SECTION,
        "A GEDI-like received waveform (the noise twin of one real shot) from a noise-free simulated one, as a \
            struct {rxwaveform, elevation_bin0, elevation_lastbin, noise_mean, noise_stddev, no_result_reason} that \
            gedi_l2a can process.",
        "gedi_noise_twin(wave, z0, dz, energy_total, noise_mean, noise_stddev, sample_count, start, seed [, quantum \
            [, noise_correlation, noise_ratio]])",
    )
    .with_argument("wave", "simulated waveform, list of numbers; sample k at elevation z0 − k·dz")
    .with_argument("z0", "elevation of sample 0 (m)")
    .with_argument("dz", "sample spacing of `wave` (m)")
    .with_argument("energy_total", "received energy above the noise (DN·samples) the twin is scaled to")
    .with_argument("noise_mean", "noise mean (DN)")
    .with_argument("noise_stddev", "noise standard deviation (DN)")
    .with_argument("sample_count", "samples of the record (1 ns each)")
    .with_argument("start", "record sample where `wave`'s sample 0 lands (negative: above the record)")
    .with_argument("seed", "random seed (integer; the same seed gives the same twin)")
    .with_argument("quantum", "optional: digitiser step (DN); 0 = none")
    .with_argument("noise_correlation", "optional: Gaussian correlation length of the noise (samples; 0 = white)")
    .with_argument("noise_ratio", "optional: per-sample σ over noise_stddev")
    .with_sql_example("select gedi_noise_twin(wave, z0, 0.15, 6900, 241, 2.5, 800, -300, 1) from sim limit 1")
    .build()
}

/// Mode (a); `c` = energy_total, noise_mean, noise_stddev, sample_count, start, seed
/// [, quantum [, noise_correlation [, noise_ratio]]]. The noise shape defaults to the one measured
/// on real GEDI records ([`NoiseShape::GEDI_V1`]).
fn shot_twin(sim: &[f64], z0: f64, dz: f64, c: &[Column], i: usize) -> Made {
    let (count, start) = (c[3].i64(i), c[4].i64(i));
    let count = usize::try_from(count).map_err(|_| TwinError::Invalid("sample_count"))?;
    let start = isize::try_from(start).map_err(|_| TwinError::Invalid("start"))?;
    if !z0.is_finite() {
        return Err(TwinError::Invalid("z0"));
    }
    let twin = ShotTwin {
        energy_total: c[0].f64(i),
        noise: Noise { mean: c[1].f64(i), stddev: c[2].f64(i) },
        sample_count: count,
        tx_pulse: None,
        quantum: c.get(6).map_or(0.0, |q| q.f64(i)),
        noise_shape: NoiseShape {
            correlation: c.get(7).map_or(NoiseShape::GEDI_V1.correlation, |v| v.f64(i)),
            per_sample_ratio: c.get(8).map_or(NoiseShape::GEDI_V1.per_sample_ratio, |v| v.f64(i)),
        },
    };
    let made = twin.apply(sim, dz, start, c[5].seed(i))?;
    let (bin0, last) = record_elevations(z0, start, made.wave.len());
    Ok((made, bin0, last))
}
