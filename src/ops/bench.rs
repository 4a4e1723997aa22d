//! `gedisim bench decode` (hidden): measurements the benchmarks compare with.

use std::path::Path;

use crate::error::{Error, Result};

/// Decode every point of a LAS/LAZ file with the `las` crate alone, touching each z: the baseline
/// the ingest benchmark compares with. Returns the point count and the sum of z.
pub fn decode_all(path: &Path) -> Result<(u64, f64)> {
    let mut reader = las::Reader::from_path(path).map_err(|e| Error::file(path, e))?;
    let mut pd = las::PointDataBuilder::new().for_header(reader.header()).build();
    let (mut n, mut checksum) = (0u64, 0f64);
    loop {
        let got = reader.fill_points(1 << 20, &mut pd).map_err(|e| Error::file(path, e))?;
        if got == 0 {
            break;
        }
        n += got;
        checksum += pd.z().sum::<f64>();
    }
    Ok((n, checksum))
}
