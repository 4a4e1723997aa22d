//! `gedi_link_margin_twin(wave, z0, dz, link_margin_db, cover, seed [, true_cover])`: a noisy
//! waveform with gediMetric's link-margin noise ([`LinkMarginTwin`], mode (b) of
//! [`crate::kernels::waveform::noise_twin`]; reference defaults otherwise). The struct it returns:
//! [`super::twin`].

use datafusion::logical_expr::Documentation;

use super::twin::{record_elevations, Column, Made, TwinFunction};
use super::DOC_SECTION;
use crate::kernels::waveform::noise_twin::{LinkMarginTwin, TwinError};

/// `gedi_link_margin_twin`.
pub static LINK_MARGIN_TWIN: TwinFunction = TwinFunction {
    name: "gedi_link_margin_twin",
    required: &["wave", "z0", "dz", "link_margin_db", "cover", "seed"],
    optional: &["true_cover"],
    make: link_margin_twin,
    documentation,
};

fn documentation() -> Documentation {
    Documentation::builder(
        DOC_SECTION,
        "A noisy waveform with gediMetric's link-margin noise model, from a noise-free simulated one, as the same \
            struct as gedi_noise_twin.",
        "gedi_link_margin_twin(wave, z0, dz, link_margin_db, cover, seed [, true_cover])",
    )
    .with_argument("wave", "simulated waveform, list of numbers; sample k at elevation z0 − k·dz")
    .with_argument("z0", "elevation of sample 0 (m)")
    .with_argument("dz", "sample spacing of `wave` (m)")
    .with_argument("link_margin_db", "link margin (dB) that sets the noise level")
    .with_argument("cover", "canopy cover the link margin refers to (0–1)")
    .with_argument("seed", "random seed (integer)")
    .with_argument("true_cover", "optional: the footprint's own cover (0–1)")
    .with_sql_example("select gedi_link_margin_twin(wave, z0, 0.15, 3.0, 0.8, 1) from sim limit 1")
    .build()
}

/// Mode (b); `c` = link_margin_db, cover, seed [, true_cover].
fn link_margin_twin(sim: &[f64], z0: f64, dz: f64, c: &[Column], i: usize) -> Made {
    if !z0.is_finite() {
        return Err(TwinError::Invalid("z0"));
    }
    let mut twin = LinkMarginTwin::new(c[0].f64(i), c[1].f64(i));
    twin.true_cover = c.get(3).map(|t| t.f64(i));
    let made = twin.apply(sim, dz, c[2].seed(i))?;
    let (bin0, last) = record_elevations(z0, twin.pre_samples as isize, made.wave.len());
    Ok((made, bin0, last))
}
