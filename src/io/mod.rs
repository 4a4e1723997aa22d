//! I/O adapters: foreign formats (LAS/LAZ, GEDI HDF5, user CSV) read into kernel types and
//! written from them, from local files or remote objects (`source`). No sequencing of steps (that
//! is `ops`), no Parquet tables (that is `dataset`).

pub mod bundled;
pub mod cmr;
pub mod copc;
pub mod csv_table;
pub mod download;
pub mod footprints;
pub mod gedi;
pub mod granule;
pub mod landcover;
pub mod las;
pub mod pulse;
pub mod source;
pub mod store;
pub mod within;

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// Files as given; folders expanded (sorted) to the files they hold for which `wanted` is true.
pub fn expand_inputs(inputs: &[PathBuf], wanted: impl Fn(&Path) -> bool) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for p in inputs {
        if p.is_dir() {
            let mut found: Vec<PathBuf> = std::fs::read_dir(p)
                .map_err(|e| Error::file(p, format!("cannot list folder: {e}")))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|f| f.is_file() && wanted(f))
                .collect();
            found.sort();
            out.extend(found);
        } else if p.is_file() || source::is_remote(p) {
            out.push(p.clone());
        } else {
            return Err(Error::file(p, "no such file or folder"));
        }
    }
    Ok(out)
}

/// Whether `path`'s extension is `ext` (case-insensitive).
pub fn has_extension(path: &Path, ext: &str) -> bool {
    path.extension().and_then(|e| e.to_str()).map(|e| e.eq_ignore_ascii_case(ext)).unwrap_or(false)
}
