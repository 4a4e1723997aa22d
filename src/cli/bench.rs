//! `gedisim bench decode` (hidden): the baseline of the ingest benchmark.

use std::path::PathBuf;
use std::time::Instant;


use gedisim::{Error, Result};

use super::reporters::peak_rss_mb;

pub fn bench_decode(file: PathBuf) -> Result<()> {
    let start = Instant::now();
    let mut reader = las::Reader::from_path(&file).map_err(|e| Error::file(&file, e))?;
    let mut pd = las::PointDataBuilder::new().for_header(reader.header()).build();
    let mut n = 0u64;
    let mut checksum = 0f64;
    loop {
        let got = reader.fill_points(1 << 20, &mut pd).map_err(|e| Error::file(&file, e))?;
        if got == 0 {
            break;
        }
        n += got;
        // Touch the coordinates so that the decode cannot be skipped.
        checksum += pd.z().sum::<f64>();
    }
    let s = start.elapsed().as_secs_f64();
    println!("decode: {n} points, {s:.2} s, {:.0} points/s, peak RSS {:.1} MB (checksum {checksum:.1})", n as f64 / s, peak_rss_mb());
    Ok(())
}
