//! The demo's inputs, embedded in the binary so that an installed `gedisim` runs `demo` and
//! `scenario` from any directory: the three LiDAR HD tiles (`tests/data/als/`, provenance in its
//! PROVENANCE.md) and the real L1B granule whose transmit records give every generated shot its
//! pulse (`tests/data/gedi/`). Written once to a cache folder the binary knows
//! ([`cache_root`]) and checked byte for byte on every use.

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

type Files = [(&'static str, &'static [u8])];

static TILES: &Files = &[
    ("lidarforfuel_1_42.laz", include_bytes!("../../tests/data/als/lidarforfuel_1_42.laz")),
    ("lidarforfuel_2_bas_lig.laz", include_bytes!("../../tests/data/als/lidarforfuel_2_bas_lig.laz")),
    (
        "pdal-ign-plugin_mnx_input_crop_2.laz",
        include_bytes!("../../tests/data/als/pdal-ign-plugin_mnx_input_crop_2.laz"),
    ),
];

static L1B: &Files = &[(
    "GEDI01_B_2019108080338_O01964_T05337_02_003_01_sub.h5",
    include_bytes!("../../tests/data/gedi/GEDI01_B_2019108080338_O01964_T05337_02_003_01_sub.h5"),
)];

/// Where the embedded files are written: `$GEDISIM_CACHE`, else `$XDG_CACHE_HOME/gedisim`, else
/// `~/.cache/gedisim`, else the system's temporary folder; one sub-folder per gedisim version.
pub fn cache_root() -> PathBuf {
    let base = std::env::var_os("GEDISIM_CACHE")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("XDG_CACHE_HOME").map(|d| PathBuf::from(d).join("gedisim")))
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache").join("gedisim")))
        .unwrap_or_else(|| std::env::temp_dir().join("gedisim"));
    base.join(format!("bundled-{}", env!("CARGO_PKG_VERSION")))
}

/// The folder holding the three bundled ALS tiles.
pub fn tiles() -> Result<PathBuf> {
    materialize("als", TILES)
}

/// The folder holding the bundled L1B granule.
pub fn l1b() -> Result<PathBuf> {
    materialize("gedi", L1B)
}

/// `files` in `<cache_root>/<sub>/`, each (re)written when absent or different.
fn materialize(sub: &str, files: &Files) -> Result<PathBuf> {
    let dir = cache_root().join(sub);
    std::fs::create_dir_all(&dir)
        .map_err(|e| Error::file(&dir, format!("cannot create the bundled data folder: {e}")))?;
    for (name, bytes) in files {
        let path = dir.join(name);
        if std::fs::read(&path).is_ok_and(|on_disk| on_disk == *bytes) {
            continue;
        }
        write_new(&path, bytes)?;
    }
    Ok(dir)
}

/// Write `bytes` to a unique temporary name beside `path`, then rename it over `path`.
fn write_new(path: &Path, bytes: &[u8]) -> Result<()> {
    let tmp = path.with_extension(format!("{}.tmp", std::process::id()));
    std::fs::write(&tmp, bytes).map_err(|e| Error::file(&tmp, format!("cannot write: {e}")))?;
    std::fs::rename(&tmp, path).map_err(|e| Error::file(path, format!("cannot write: {e}")))
}
