//! `ingest strata`: the forest type of every shot, from a Corine Land Cover GeoTIFF (EPSG:3035)
//! sampled at the shot, or from a CSV `shot_number,forest_type`. Writes `<dataset>/strata/`.
//! The raster and the CSV are read by `io::landcover` (only the strips or tiles that hold a shot
//! are decoded, so a Europe-wide raster is not loaded).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use crate::dataset::shots::shot_positions;
use crate::dataset::strata::{strata_batch, strata_metadata, strata_schema};
use crate::dataset::{self, tables, Dataset};
use crate::error::{Error, Result};
use crate::io::landcover::{read_strata_csv, LandCoverRaster};
use crate::ops::progress::{Progress, Step};

/// What `ingest strata` did.
#[derive(Debug, Clone, Default)]
pub struct StrataReport {
    /// Rows written.
    pub rows: usize,
    /// Count per forest type.
    pub counts: HashMap<&'static str, usize>,
    /// Shots outside the raster (forest type `unknown`).
    pub outside: usize,
    /// Shots without a position (forest type `unknown`).
    pub no_position: usize,
    /// CSV rows whose shot is not in the dataset (CSV input, when `shots/` exists).
    pub not_in_dataset: usize,
    /// Where the table was written.
    pub path: PathBuf,
}

/// Read `landcover` (`.tif`/`.tiff` GeoTIFF or `.csv`) and write `<dataset>/strata/strata.parquet`,
/// replacing a previous one, as one [`Step::Strata`] counted in shots (raster input).
pub fn ingest_strata(ds: &Dataset, landcover: &Path, progress: &dyn Progress) -> Result<StrataReport> {
    let ds = &ds.as_writer()?;
    progress.start(Step::Strata, 0);
    let report = strata_of(ds, landcover, &|n, total| {
        progress.set_total(total);
        progress.advance(n);
    });
    progress.finish();
    report
}

fn strata_of(ds: &Dataset, landcover: &Path, on_shots: &dyn Fn(u64, u64)) -> Result<StrataReport> {
    let ext = landcover.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).unwrap_or_default();
    let mut report = StrataReport::default();
    let (strata, source) = match ext.as_str() {
        "csv" => {
            let strata = read_strata_csv(landcover)?;
            if ds.has_table(tables::SHOTS) {
                let known: std::collections::HashSet<u64> = shot_positions(ds)?.into_iter().map(|s| s.0).collect();
                report.not_in_dataset = strata.iter().filter(|s| !known.contains(&s.shot_number)).count();
            }
            (strata, format!("csv:{}", file_name(landcover)))
        }
        "tif" | "tiff" => {
            let shots = shot_positions(ds)?;
            let mut raster = LandCoverRaster::open(landcover)?;
            let (strata, outside, no_position) = raster.sample_shots(&shots, on_shots)?;
            report.outside = outside;
            report.no_position = no_position;
            (strata, format!("clc:{}", file_name(landcover)))
        }
        _ => {
            return Err(Error::file(landcover, "land cover: expected a GeoTIFF (.tif, .tiff) or a CSV (.csv) file"));
        }
    };
    for s in &strata {
        *report.counts.entry(s.forest_type).or_default() += 1;
    }
    report.rows = strata.len();
    let batch = strata_batch(&strata, &source)?;
    let dest = ds.table_file(tables::STRATA, "strata")?;
    report.path = dataset::write_parquet(&dest, strata_schema(), &[batch], &strata_metadata(&source))?;
    Ok(report)
}

fn file_name(p: &Path) -> String {
    p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default()
}
