//! The granules of `shots/`, each by its key and what its shots were ingested from: the identity
//! `run` (and the diagnosis's re-use key) keys its work by.

use std::path::{Path, PathBuf};

use crate::dataset::{self, read, tables, Dataset};
use crate::error::{Error, Result};
use crate::ops::ingest_gedi::{self as gedi};

/// One file of `shots/`.
#[derive(Debug, Clone)]
pub(super) struct GranuleFile {
    pub(super) key: String,
    pub(super) path: PathBuf,
    /// The `granule` column.
    pub(super) name: String,
    /// The content hashes it was ingested from (`granules/`), as one string.
    pub(super) inputs: String,
}

pub(super) fn list_granules(ds: &Dataset) -> Result<Vec<GranuleFile>> {
    let dir = ds.root().join(tables::SHOTS);
    let files =
        dataset::table_files(&dir).map_err(|e| Error::file(&dir, format!("no shots table ({e}): give --l1b/--l2a")))?;
    let mut out = Vec::new();
    for path in files {
        let (key, inputs) = granule_inputs(ds, &path)?;
        let name = first_string(&path, "granule")?.unwrap_or_else(|| key.clone());
        out.push(GranuleFile { key, path, name, inputs });
    }
    Ok(out)
}

/// The granule key of a `shots/` file and what its shots were ingested from, as one string: the
/// content hashes of its L1B and L2A and the area its shots were kept by (its `granules/`
/// record); for a file without a record, its size and time. What `run` (and the diagnosis's
/// re-use key) treat as the granule's identity.
pub(crate) fn granule_inputs(ds: &Dataset, shots_file: &Path) -> Result<(String, String)> {
    let key = shots_file.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let record = ds.root().join(tables::GRANULES).join(format!("{key}.parquet"));
    let inputs = match gedi::previous_record(&record)? {
        Some(((a, b), area)) => {
            let area = if area == "all" { String::new() } else { format!(" area={area}") };
            format!("l1b={} l2a={}{area}", a.unwrap_or_default(), b.unwrap_or_default())
        }
        None => {
            let m = std::fs::metadata(shots_file).map_err(|e| Error::file(shots_file, e))?;
            let t = m
                .modified()
                .ok()
                .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
                .map_or(0, |d| d.as_nanos());
            format!("size={} mtime={t}", m.len())
        }
    };
    Ok((key, inputs))
}

/// The first value of string column `column` of a Parquet file.
pub(super) fn first_string(path: &Path, column: &str) -> Result<Option<String>> {
    // One row of one column: the file's first batch of one row, not the whole column.
    let builder = read::open(path)?;
    let mask = parquet::arrow::ProjectionMask::columns(builder.parquet_schema(), [column]);
    let reader =
        builder.with_projection(mask).with_batch_size(1).with_limit(1).build().map_err(|e| Error::table(path, e))?;
    for b in reader {
        let b = b.map_err(|e| Error::table(path, e))?;
        if b.num_rows() > 0 {
            return read::Columns::new(path, &b).string(column, 0);
        }
    }
    Ok(None)
}
