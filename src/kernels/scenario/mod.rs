//! Scenario worlds for the withheld-effect checks (issue 10): real ALS tiles plus pseudo-real GEDI
//! L1B/L2A shots simulated with the "true" physics and exactly one withheld effect (or a pair, or
//! none). Pure kernels: the effect registry ([`effects`]), the layout of tracks and shots
//! ([`plan`]), one shot from its simulation ([`shot`]), seeded streams ([`rng`]) and the measured
//! constants of real records ([`real`]) and the types of `truth.json` ([`truth`]). Files are read
//! and written by `ops::scenario`.

pub mod effects;
pub mod granules;
pub mod plan;
pub mod real;
pub mod rng;
pub mod shot;
pub mod truth;

pub use effects::{Effect, EffectError, EffectSet, Physics, WaveParts};
