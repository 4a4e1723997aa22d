//! The study's pure kernels: RH alignment to the ALS ground, the strata classes, the study's
//! quality filter, the selection of the results rows (every filter, counted) and the MSD
//! decomposition. No I/O, no Arrow: the `results` table (`tables::results`), `run`,
//! `ingest strata` and `report` call them.

pub mod align;
pub mod classes;
pub mod msd;
pub mod select;
