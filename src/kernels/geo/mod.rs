//! Projections (pure Rust) and vertical-datum handling.

pub mod projection;
