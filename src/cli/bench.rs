//! `gedisim bench decode` (hidden): the baseline of the ingest benchmark.

use std::path::PathBuf;
use std::time::Instant;

use gedisim::Result;

use super::reporters::peak_rss_mb;

pub fn bench_decode(file: PathBuf) -> Result<()> {
    let start = Instant::now();
    let (n, checksum) = gedisim::ops::bench::decode_all(&file)?;
    let s = start.elapsed().as_secs_f64();
    println!(
        "decode: {n} points, {s:.2} s, {:.0} points/s, peak RSS {:.1} MB (checksum {checksum:.1})",
        n as f64 / s,
        peak_rss_mb()
    );
    Ok(())
}
