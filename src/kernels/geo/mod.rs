//! Projections (pure Rust), vertical-datum handling, and the cells a read of a tile needs.

pub mod area;
pub mod cells;
pub mod projection;
