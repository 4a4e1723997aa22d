//! Which shots `ingest gedi` and `run` keep (docs/gedi-products.md, "Shots kept"): by default those
//! within the dataset's ALS coverage, the tile extents grown by the collocation's search and the
//! footprint's reach.

use std::path::{Path, PathBuf};

use crate::dataset::als::tiles_col;
use crate::dataset::{self, tables, Dataset};
use crate::error::{Error, Result};
use crate::io::las::read_header;
use crate::kernels::geo::area::ShotArea;

/// The user's choice of shots.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum ShotChoice {
    /// The dataset's ALS coverage (every shot when it has no tiles yet, said).
    #[default]
    AlsCoverage,
    /// `--all-shots`.
    All,
    /// `--bbox`.
    Area(ShotArea),
    /// `--within <GeoJSON>`.
    Within(PathBuf),
}

impl ShotChoice {
    /// The area to keep: the choice, or the coverage of the dataset's tiles and of `als_inputs`
    /// (LAS/LAZ/COPC headers, read before the tiles are ingested) grown by `margin_m`; and what to
    /// call it when a dataset without tiles keeps every shot.
    pub fn area(&self, ds: &Dataset, als_inputs: &[PathBuf], margin_m: f64) -> Result<(ShotArea, Option<String>)> {
        match self {
            ShotChoice::All => Ok((ShotArea::All, None)),
            ShotChoice::Area(a) => Ok((a.clone(), None)),
            ShotChoice::Within(file) => Ok((crate::io::within::read_within(file)?, None)),
            ShotChoice::AlsCoverage => {
                let mut extents = dataset_extents(ds)?;
                for f in crate::ops::ingest_als::expand_inputs(als_inputs)? {
                    extents.push(header_extent(&f)?);
                }
                // One extent per tile, in one order: the area's key does not change with how the
                // tiles were named (the dataset's, the inputs about to be ingested).
                extents.sort_by(|a, b| {
                    a.iter()
                        .zip(b)
                        .map(|(x, y)| x.total_cmp(y))
                        .find(|o| o.is_ne())
                        .unwrap_or(std::cmp::Ordering::Equal)
                });
                extents.dedup();
                if extents.is_empty() {
                    let all = "every shot (the dataset has no ALS tiles yet: ingest them first, or give --bbox or \
                               --within, to keep only the shots over them)";
                    return Ok((ShotArea::All, Some(all.to_string())));
                }
                Ok((ShotArea::Tiles { extents, margin_m }, None))
            }
        }
    }
}

/// The horizontal extent of each tile of the dataset: its header bounds (its `als/` file's
/// `gedisim:tile_extent`), else (a tile ingested by an earlier version) the extent of the points written.
pub(crate) fn dataset_extents(ds: &Dataset) -> Result<Vec<[f64; 4]>> {
    let tiles_dir = ds.root().join(tables::TILES);
    let als_dir = ds.root().join(tables::ALS);
    let mut out = Vec::new();
    for f in dataset::table_files(&tiles_dir).unwrap_or_default() {
        if let Some(e) = dataset::als::tile_extent(&als_dir.join(f.file_name().unwrap_or_default())) {
            out.push(e);
            continue;
        }
        dataset::read::for_each_batch(
            &f,
            Some(&[tiles_col::XMIN, tiles_col::YMIN, tiles_col::XMAX, tiles_col::YMAX]),
            None,
            |c| {
                for i in 0..c.num_rows() {
                    let v = [tiles_col::XMIN, tiles_col::YMIN, tiles_col::XMAX, tiles_col::YMAX].map(|k| c.f64(k, i));
                    if let [Some(x0), Some(y0), Some(x1), Some(y1)] = v.map(|r| r.ok().flatten()) {
                        out.push([x0, y0, x1, y1]);
                    }
                }
                Ok(())
            },
        )?;
    }
    Ok(out)
}

/// A LAS/LAZ/COPC file's horizontal header bounds.
fn header_extent(path: &Path) -> Result<[f64; 4]> {
    let b = read_header(path)?.bounds;
    let e = [b[0], b[1], b[3], b[4]];
    if e.iter().all(|v| v.is_finite()) && e[0] <= e[2] && e[1] <= e[3] {
        Ok(e)
    } else {
        let msg = format!("{e:?} is not an extent: give --bbox, --within or --all-shots");
        Err(Error::field(path, "header bounds", msg))
    }
}
