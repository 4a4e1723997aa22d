//! `gedisim export geoparquet`: a table of the dataset (`shots` or `results`) as GeoParquet 1.1.

use std::path::Path;

use crate::dataset::Dataset;
use crate::error::Result;
use crate::ops::report::geoparquet::{export, GeoCrs};

/// Export `table` of `dataset` to `out` (WGS84 points); the number of rows written.
pub fn export_geoparquet(dataset: &Path, table: &str, out: &Path) -> Result<u64> {
    let ds = Dataset::open(dataset)?;
    let rt = crate::sql::runtime()?;
    rt.block_on(export(&ds, table, out, GeoCrs::Wgs84))
}
