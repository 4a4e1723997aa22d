//! Edges that read foreign formats (LAS/LAZ, GEDI HDF5) into the dataset's Parquet tables.

pub mod als;
pub mod footprints;
pub mod gedi;
pub mod las;
