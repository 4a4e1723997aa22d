//! `gedisim granules`: the GEDI L1B and L2A V2 granules that cross a dataset's ALS tiles, found
//! through NASA's CMR search (docs/granules.md).

use std::path::Path;

use crate::dataset::{self, Dataset};
use crate::error::{Error, Result};
use crate::io::cmr::{self, GranuleQuery};
use crate::io::download::{self, Download};

pub use crate::io::cmr::Granule;
pub use crate::io::download::Fetched;
use crate::kernels::geo::projection::Projector;
use crate::ops::progress::{Progress, Step};

/// The environment variable that holds the Earthdata Login bearer token `--download` sends.
pub const TOKEN_VAR: &str = "EARTHDATA_TOKEN";

/// The collections searched: GEDI L1B and L2A, version 2 (short name, version).
pub const COLLECTIONS: [(&str, &str); 2] = [("GEDI01_B", "002"), ("GEDI02_A", "002")];

/// NASA's operational CMR.
pub const CMR: &str = "https://cmr.earthdata.nasa.gov";

/// What `gedisim granules` is asked for.
#[derive(Debug, Clone, PartialEq)]
pub struct GranulesOptions {
    /// CMR's address.
    pub cmr: String,
    /// First and last day (`YYYY-MM-DD`), either may be open.
    pub from: Option<chrono::NaiveDate>,
    pub to: Option<chrono::NaiveDate>,
}

/// The granules found, and the box they were searched in.
#[derive(Debug, Clone, PartialEq)]
pub struct GranulesFound {
    /// West, south, east, north (degrees).
    pub bbox: [f64; 4],
    pub granules: Vec<Granule>,
}

/// The longitude/latitude box of the dataset's tiles: every tile corner taken back to WGS 84.
pub fn dataset_box(ds: &Dataset) -> Result<[f64; 4]> {
    let extents = crate::ops::ingest_gedi::coverage::dataset_extents(ds)?;
    if extents.is_empty() {
        return Err(Error::file(ds.root(), "the dataset has no ALS tiles: ingest them first (`gedisim ingest als`)"));
    }
    let epsg = dataset::dataset_epsg(ds)?
        .ok_or_else(|| Error::file(ds.root(), "the dataset's tiles record no CRS (gedisim:crs_epsg)"))?;
    let projector = Projector::new(epsg)?;
    let mut b = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
    for [x0, y0, x1, y1] in extents {
        for (x, y) in [(x0, y0), (x0, y1), (x1, y0), (x1, y1)] {
            let (lon, lat) = projector
                .unproject(x, y)
                .map_err(|e| Error::field(ds.root(), "tiles", format!("EPSG:{epsg} corner ({x}, {y}): {e}")))?;
            b = [b[0].min(lon), b[1].min(lat), b[2].max(lon), b[3].max(lat)];
        }
    }
    Ok(b)
}

/// CMR's `temporal` value for the days `from`..=`to` (UTC), if either is given.
pub fn temporal(from: Option<chrono::NaiveDate>, to: Option<chrono::NaiveDate>) -> Result<Option<String>> {
    if let (Some(f), Some(t)) = (from, to) {
        if f > t {
            return Err(Error::Usage(format!("--from {f} is after --to {t}")));
        }
    }
    let start = from.map(|d| format!("{d}T00:00:00Z")).unwrap_or_default();
    let end = to.map(|d| format!("{d}T23:59:59Z")).unwrap_or_default();
    Ok((from.is_some() || to.is_some()).then(|| format!("{start},{end}")))
}

/// The L1B and L2A granules crossing the tiles of the dataset at `root`; `on_page` hears each
/// collection's count so far.
pub fn find_granules(root: &Path, opts: &GranulesOptions, on_page: &dyn Fn(&str, usize)) -> Result<GranulesFound> {
    let temporal = temporal(opts.from, opts.to)?;
    let ds = Dataset::open(root)?;
    let bbox = dataset_box(&ds)?;
    let mut granules = Vec::new();
    for (short_name, version) in COLLECTIONS {
        let q =
            GranuleQuery { short_name: short_name.into(), version: version.into(), bbox, temporal: temporal.clone() };
        granules.extend(cmr::search(&opts.cmr, &q, &|n| on_page(short_name, n))?);
    }
    Ok(GranulesFound { bbox, granules })
}

/// Download every granule found into `dir` (created if needed), `parallel` at once, with the
/// Earthdata bearer `token`: each under its granule name, resumed where an earlier run stopped,
/// checked against the size the server gives and the size CMR announced. Granules without a
/// download address are refused, as are names that are not plain file names.
pub fn download(
    found: &GranulesFound,
    dir: &Path,
    token: &str,
    parallel: usize,
    progress: &dyn Progress,
) -> Result<Vec<Fetched>> {
    let downloads = found
        .granules
        .iter()
        .map(|g| {
            let url = g.url.clone().ok_or_else(|| {
                Error::field(&g.granule_id, "links", "CMR gives no download address (rel …/data#) for this granule")
            })?;
            if Path::new(&g.granule_id).file_name().is_none_or(|n| n != g.granule_id.as_str()) {
                return Err(Error::field(&g.granule_id, "producer_granule_id", "not a plain file name"));
            }
            Ok(Download { url, path: dir.join(&g.granule_id), announced_mb: g.size_mb })
        })
        .collect::<Result<Vec<_>>>()?;
    std::fs::create_dir_all(dir).map_err(|e| Error::file(dir, e))?;
    let total: f64 = found.granules.iter().filter_map(|g| g.size_mb).sum();
    progress.start(Step::Download, (total * 1e6) as u64);
    let fetched = download::fetch_all(&downloads, token, parallel, &|n| progress.advance(n));
    progress.finish();
    fetched
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn temporal_covers_whole_days_and_refuses_a_reversed_range() {
        let d = |s: &str| Some(s.parse::<chrono::NaiveDate>().unwrap());
        assert_eq!(temporal(None, None).unwrap(), None);
        assert_eq!(
            temporal(d("2020-01-01"), d("2020-12-31")).unwrap().unwrap(),
            "2020-01-01T00:00:00Z,2020-12-31T23:59:59Z"
        );
        assert_eq!(temporal(None, d("2021-06-01")).unwrap().unwrap(), ",2021-06-01T23:59:59Z");
        assert!(temporal(d("2021-01-02"), d("2021-01-01")).is_err());
    }
}
