//! Projections (pure Rust) and vertical-datum handling.
