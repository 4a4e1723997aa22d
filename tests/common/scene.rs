//! Test and benchmark scenes: one real LiDAR HD tile replicated on a grid of (100·i, 100·j) m
//! translations, written as one LAZ file. Shared by `tests/` and `benches/` (included by path).

use std::path::Path;

/// Writes `src` replicated `nx` × `ny` times with X/Y offsets of (`step`·i, `step`·j) m to `dest`
/// (LAZ, written under a temporary name and renamed); returns the number of points written.
pub fn replicated_tile(src: &Path, nx: usize, ny: usize, step: f64, dest: &Path) -> u64 {
    tilted_replicated_tile(src, nx, ny, step, 0.0, dest)
}

/// As [`replicated_tile`], on a plane rising `slope_deg` along +X: every point (ground and canopy
/// alike) raised by (x − the tile's minimum x) · tan(slope), so canopy heights are kept and the
/// scene has the slope a hillside forest has.
pub fn tilted_replicated_tile(src: &Path, nx: usize, ny: usize, step: f64, slope_deg: f64, dest: &Path) -> u64 {
    let mut reader = las::Reader::from_path(src).expect("read the source tile");
    let points: Vec<las::Point> =
        reader.read_all().expect("decode the source tile").points().map(|p| p.expect("a point")).collect();
    let x0 = reader.header().bounds().min.x;
    let rise = slope_deg.to_radians().tan();
    let mut builder = las::Builder::from(reader.header().clone());
    builder.point_format.is_compressed = true;
    builder.evlrs.clear();
    let header = builder.into_header().expect("a LAZ header");
    // The extension decides compression in `las::Writer::from_path`: keep `.laz` last.
    let tmp = dest.with_extension("tmp.laz");
    let mut writer = las::Writer::from_path(&tmp, header).expect("create the scene");
    for i in 0..nx {
        for j in 0..ny {
            for p in &points {
                let mut q = p.clone();
                q.x += step * i as f64;
                q.y += step * j as f64;
                q.z += (q.x - x0) * rise;
                writer.write_point(q).expect("write a point");
            }
        }
    }
    writer.close().expect("close the scene");
    drop(writer);
    std::fs::rename(&tmp, dest).expect("rename the scene into place");
    (points.len() * nx * ny) as u64
}
