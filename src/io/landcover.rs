//! Land-cover inputs of `ingest strata`: a Corine Land Cover GeoTIFF (pure-Rust `tiff`; GeoTIFF
//! tags read here, EPSG:3035 checked; only the strips or tiles holding shots are decoded) or a CSV
//! `shot_number,forest_type`.
//!
//! GeoTIFF support: one band of integer samples, stripped or tiled, uncompressed/deflate/LZW;
//! georeferencing from ModelPixelScale + ModelTiepoint (or a ModelTransformation without rotation);
//! the CRS from the GeoKeyDirectory (ProjectedCSTypeGeoKey must be 3035). Values: an 8-bit raster
//! holds Copernicus grid codes (1…44, e.g. 23 = CLC 311), a wider one holds CLC codes (311, 312,
//! 313 …).

use std::collections::HashMap;
use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

use tiff::decoder::{Decoder, DecodingResult};
use tiff::tags::Tag;

use crate::error::{Error, Result};
use crate::kernels::geo::projection::Projector;
use crate::kernels::study::classes::{self, ShotPosition, Stratum, UNKNOWN};
/// The CRS a land-cover raster must be in.
pub const LANDCOVER_EPSG: u16 = 3035;

/// `shot_number, forest_type` rows of a CSV with a header naming both (any order, other columns
/// ignored; also `shot`/`shot_id` and `forest`; separators, quotes, BOM as `io::csv_table`).
/// Errors name the file, the line and the field.
pub fn read_strata_csv(path: &Path) -> Result<Vec<Stratum>> {
    let t = crate::io::csv_table::CsvTable::read(path, "shot_number,forest_type")?;
    let (i_shot, i_type) = (t.require(&["shot_number", "shot", "shot_id"])?, t.require(&["forest_type", "forest"])?);
    let mut seen = std::collections::HashSet::new();
    let mut out = Vec::new();
    for row in t.rows() {
        let line = row.0;
        let shot_text = t.field(row, i_shot, "shot_number")?;
        let shot_number: u64 = shot_text.parse().map_err(|_| {
            Error::field(path, format!("line {line}: shot_number"), format!("`{shot_text}` is not an unsigned integer"))
        })?;
        let type_text = t.field(row, i_type, "forest_type")?;
        let forest_type = classes::parse_forest_type(type_text).ok_or_else(|| {
            Error::field(
                path,
                format!("line {line}: forest_type"),
                format!("`{type_text}` is not one of {}", classes::FOREST_TYPES.join(", ")),
            )
        })?;
        if !seen.insert(shot_number) {
            return Err(Error::field(
                path,
                format!("line {line}: shot_number"),
                format!("shot {shot_number} appears twice"),
            ));
        }
        out.push(Stratum { shot_number, forest_type, clc_code: None });
    }
    Ok(out)
}

/// Affine georeferencing of a north-up raster: the pixel (col, row) covers
/// `[x0 + col·sx, x0 + (col+1)·sx) × (y0 − (row+1)·sy, y0 − row·sy]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GeoTransform {
    /// x of the left edge of column 0.
    pub x0: f64,
    /// y of the top edge of row 0.
    pub y0: f64,
    /// Pixel width (> 0).
    pub sx: f64,
    /// Pixel height (> 0, rows go south).
    pub sy: f64,
}

impl GeoTransform {
    /// From ModelPixelScale (sx, sy, sz) and one ModelTiepoint (i, j, k, x, y, z); `pixel_is_point`
    /// (GTRasterTypeGeoKey = 2) moves the tie point from the pixel's centre to its corner.
    pub fn from_tiepoint(scale: &[f64], tiepoint: &[f64], pixel_is_point: bool) -> std::result::Result<Self, String> {
        if scale.len() < 2 || tiepoint.len() < 6 {
            return Err(format!("{} scale values and {} tie-point values (need 3 and 6)", scale.len(), tiepoint.len()));
        }
        let (sx, sy) = (scale[0], scale[1]);
        if !(sx.is_finite() && sy.is_finite() && sx > 0.0 && sy > 0.0) {
            return Err(format!("pixel size ({sx}, {sy}) is not positive"));
        }
        let half = if pixel_is_point { 0.5 } else { 0.0 };
        let (i, j) = (tiepoint[0] + half, tiepoint[1] + half);
        Ok(GeoTransform { x0: tiepoint[3] - i * sx, y0: tiepoint[4] + j * sy, sx, sy })
    }

    /// From a ModelTransformation matrix (16 values, row-major) without rotation or shear.
    pub fn from_matrix(m: &[f64], pixel_is_point: bool) -> std::result::Result<Self, String> {
        if m.len() < 16 {
            return Err(format!("{} values (need 16)", m.len()));
        }
        if m[1] != 0.0 || m[4] != 0.0 {
            return Err("rotated or sheared rasters are not supported".into());
        }
        Self::from_tiepoint(&[m[0], -m[5], 0.0], &[0.0, 0.0, 0.0, m[3], m[7], 0.0], pixel_is_point)
    }

    /// The (column, row) holding (x, y), or `None` outside a `width` × `height` raster.
    pub fn pixel_of(&self, x: f64, y: f64, width: u32, height: u32) -> Option<(u32, u32)> {
        let c = ((x - self.x0) / self.sx).floor();
        let r = ((self.y0 - y) / self.sy).floor();
        (c >= 0.0 && r >= 0.0 && c < width as f64 && r < height as f64).then_some((c as u32, r as u32))
    }
}

/// GeoKeyDirectory entries as (key id → value) for keys stored inline (TIFFTagLocation 0).
pub fn geokeys(directory: &[u16]) -> HashMap<u16, u16> {
    let mut keys = HashMap::new();
    if directory.len() < 4 {
        return keys;
    }
    let n = directory[3] as usize;
    for e in directory[4..].chunks_exact(4).take(n) {
        if e[1] == 0 && e[2] == 1 {
            keys.insert(e[0], e[3]);
        }
    }
    keys
}

/// How the raster's values encode CLC classes.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Codes {
    /// Copernicus grid codes 1…44 (8-bit rasters).
    Grid,
    /// CLC level-3 codes (111…523).
    Clc,
}

/// What the raster holds at a point.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PixelSample {
    /// The point is outside the raster.
    Outside,
    /// No data, or a value that is not a CLC class.
    NoData,
    /// A CLC level-3 code.
    Clc(u16),
}

/// A CLC GeoTIFF opened for sampling.
pub struct LandCoverRaster {
    path: PathBuf,
    decoder: Decoder<BufReader<File>>,
    width: u32,
    height: u32,
    transform: GeoTransform,
    chunk: (u32, u32),
    chunks_across: u32,
    codes: Codes,
    nodata: Option<i64>,
}

impl LandCoverRaster {
    /// Open and check a GeoTIFF: one integer band, north-up georeferencing, EPSG:3035.
    pub fn open(path: &Path) -> Result<Self> {
        let file = File::open(path).map_err(|e| Error::file(path, format!("cannot open: {e}")))?;
        let terr = |field: &str, e: tiff::TiffError| Error::field(path, field, e);
        let mut decoder =
            Decoder::new(BufReader::new(file)).map_err(|e| Error::file(path, format!("not a readable TIFF: {e}")))?;
        let (width, height) = decoder.dimensions().map_err(|e| terr("ImageWidth", e))?;
        let codes = match decoder.colortype().map_err(|e| terr("BitsPerSample", e))? {
            tiff::ColorType::Gray(8) | tiff::ColorType::Palette(8) => Codes::Grid,
            tiff::ColorType::Gray(16) | tiff::ColorType::Gray(32) | tiff::ColorType::Palette(16) => Codes::Clc,
            other => {
                return Err(Error::field(
                    path,
                    "BitsPerSample",
                    format!("{other:?}: expected one band of 8-, 16- or 32-bit class codes"),
                ))
            }
        };
        if let Some(fmt) = decoder.find_tag_unsigned::<u16>(Tag::SampleFormat).map_err(|e| terr("SampleFormat", e))? {
            if fmt == 3 {
                return Err(Error::field(path, "SampleFormat", "floating-point samples: expected integer class codes"));
            }
        }
        let keys = match decoder.find_tag(Tag::GeoKeyDirectoryTag).map_err(|e| terr("GeoKeyDirectory", e))? {
            Some(v) => geokeys(&v.into_u16_vec().map_err(|e| terr("GeoKeyDirectory", e))?),
            None => return Err(Error::field(path, "GeoKeyDirectory", "missing: not a GeoTIFF (expected EPSG:3035)")),
        };
        match (keys.get(&geokey::PROJECTED_CS_TYPE), keys.get(&geokey::GEOGRAPHIC_TYPE)) {
            (Some(&LANDCOVER_EPSG), _) => {}
            (Some(&code), _) => {
                return Err(Error::field(
                    path,
                    "GeoKeyDirectory/ProjectedCSTypeGeoKey",
                    format!("EPSG:{code}, expected EPSG:{LANDCOVER_EPSG} (Corine Land Cover's LAEA Europe)"),
                ))
            }
            (None, Some(&code)) => {
                return Err(Error::field(
                    path,
                    "GeoKeyDirectory/GeographicTypeGeoKey",
                    format!("geographic EPSG:{code}, expected projected EPSG:{LANDCOVER_EPSG}"),
                ))
            }
            (None, None) => {
                return Err(Error::field(
                    path,
                    "GeoKeyDirectory/ProjectedCSTypeGeoKey",
                    format!("missing, expected EPSG:{LANDCOVER_EPSG}"),
                ))
            }
        }
        let pixel_is_point = keys.get(&geokey::RASTER_TYPE) == Some(&2);
        let f64s = |d: &mut Decoder<BufReader<File>>, tag: Tag, name: &str| -> Result<Option<Vec<f64>>> {
            match d.find_tag(tag).map_err(|e| terr(name, e))? {
                Some(v) => Ok(Some(v.into_f64_vec().map_err(|e| terr(name, e))?)),
                None => Ok(None),
            }
        };
        let scale = f64s(&mut decoder, Tag::ModelPixelScaleTag, "ModelPixelScale")?;
        let tie = f64s(&mut decoder, Tag::ModelTiepointTag, "ModelTiepoint")?;
        let matrix = f64s(&mut decoder, Tag::ModelTransformationTag, "ModelTransformation")?;
        let transform = match (scale, tie, matrix) {
            (Some(s), Some(t), _) => GeoTransform::from_tiepoint(&s, &t, pixel_is_point)
                .map_err(|e| Error::field(path, "ModelPixelScale/ModelTiepoint", e))?,
            (_, _, Some(m)) => GeoTransform::from_matrix(&m, pixel_is_point)
                .map_err(|e| Error::field(path, "ModelTransformation", e))?,
            _ => {
                return Err(Error::field(
                    path,
                    "ModelPixelScale/ModelTiepoint",
                    "missing: the raster is not georeferenced",
                ))
            }
        };
        let nodata = match decoder.find_tag(Tag::GdalNodata).map_err(|e| terr("GDAL_NODATA", e))? {
            Some(v) => {
                let s = v.into_string().map_err(|e| terr("GDAL_NODATA", e))?;
                let s = s.trim_matches(|c: char| c == '\0' || c.is_whitespace());
                s.parse::<f64>().ok().map(|v| v as i64)
            }
            None => None,
        };
        let chunk = decoder.chunk_dimensions();
        if chunk.0 == 0 || chunk.1 == 0 {
            return Err(Error::field(path, "RowsPerStrip/TileWidth", "zero-sized strips or tiles"));
        }
        let chunks_across = width.div_ceil(chunk.0);
        Ok(LandCoverRaster {
            path: path.to_path_buf(),
            decoder,
            width,
            height,
            transform,
            chunk,
            chunks_across,
            codes,
            nodata,
        })
    }

    /// The raster's georeferencing.
    pub fn transform(&self) -> GeoTransform {
        self.transform
    }

    /// Forest type (and CLC code) of every shot; returns the strata and the counts of shots
    /// outside the raster and without position (both `unknown`).
    pub fn sample_shots(
        &mut self,
        shots: &[ShotPosition],
        on_shots: &dyn Fn(u64, u64),
    ) -> Result<(Vec<Stratum>, usize, usize)> {
        let projector = Projector::new(LANDCOVER_EPSG as u32)?;
        let mut out: Vec<Stratum> =
            shots.iter().map(|s| Stratum { shot_number: s.0, forest_type: UNKNOWN, clc_code: None }).collect();
        let mut no_position = 0;
        // (index in shots, projected position)
        let mut points: Vec<(usize, (f64, f64))> = Vec::with_capacity(shots.len());
        for (i, (_, pos)) in shots.iter().enumerate() {
            match pos.map(|(lon, lat)| projector.project(lon, lat)) {
                Some(Ok(xy)) => points.push((i, xy)),
                _ => no_position += 1,
            }
        }
        let total = shots.len() as u64;
        on_shots(no_position as u64, total);
        let xy: Vec<(f64, f64)> = points.iter().map(|p| p.1).collect();
        let samples = self.sample_xy(&xy, &|n| on_shots(n, total))?;
        let mut outside = 0;
        for ((i, _), sample) in points.iter().zip(samples) {
            match sample {
                PixelSample::Outside => outside += 1,
                PixelSample::NoData => {}
                PixelSample::Clc(code) => {
                    out[*i].clc_code = Some(code);
                    out[*i].forest_type = classes::forest_type_of_clc(code);
                }
            }
        }
        Ok((out, outside, no_position))
    }

    /// The CLC class at each EPSG:3035 point. Each strip or tile holding a point is decoded once;
    /// `on_points(n)` reports progress.
    pub fn sample_xy(&mut self, points: &[(f64, f64)], on_points: &dyn Fn(u64)) -> Result<Vec<PixelSample>> {
        let mut out = vec![PixelSample::Outside; points.len()];
        // (index in points, chunk, (row, column) within the chunk)
        let mut located: Vec<(usize, u32, (usize, usize))> = Vec::new();
        for (i, &(x, y)) in points.iter().enumerate() {
            if let Some((c, r)) = self.transform.pixel_of(x, y, self.width, self.height) {
                // In u64: a strip spans the image width, so width × rows per strip can pass u32.
                let (c, r, (cw, ch)) = (u64::from(c), u64::from(r), (u64::from(self.chunk.0), u64::from(self.chunk.1)));
                let chunk = (r / ch) * u64::from(self.chunks_across) + c / cw;
                let chunk = u32::try_from(chunk).map_err(|_| {
                    Error::field(&self.path, "TileOffsets", format!("strip/tile {chunk} is beyond TIFF's 32-bit index"))
                })?;
                located.push((i, chunk, ((r % ch) as usize, (c % cw) as usize)));
            }
        }
        on_points((points.len() - located.len()) as u64);
        located.sort_by_key(|l| l.1);
        let mut k = 0;
        while k < located.len() {
            let chunk = located[k].1;
            let (values, data_w) = self.read_chunk(chunk)?;
            let end = k + located[k..].iter().take_while(|l| l.1 == chunk).count();
            for &(i, _, (row, col)) in &located[k..end] {
                let v = (col < data_w).then(|| values.get(row * data_w + col).copied()).flatten();
                let code = v.filter(|v| Some(*v) != self.nodata).and_then(|v| match self.codes {
                    Codes::Grid => u16::try_from(v).ok().and_then(classes::clc_code_of_grid_code),
                    Codes::Clc => u16::try_from(v).ok().filter(|c| classes::CLC_CODES.contains(c)),
                });
                out[i] = code.map(PixelSample::Clc).unwrap_or(PixelSample::NoData);
            }
            on_points((end - k) as u64);
            k = end;
        }
        Ok(out)
    }

    /// The samples of one strip or tile, row-major, and the width of its data: the decoder returns a
    /// chunk's data only (the last strip is shorter; edge tiles are narrower and shorter than the
    /// nominal tile).
    fn read_chunk(&mut self, chunk: u32) -> Result<(Vec<i64>, usize)> {
        let data =
            self.decoder.read_chunk(chunk).map_err(|e| Error::field(&self.path, format!("strip/tile {chunk}"), e))?;
        let values: Vec<i64> = match data {
            DecodingResult::U8(v) => v.into_iter().map(i64::from).collect(),
            DecodingResult::U16(v) => v.into_iter().map(i64::from).collect(),
            DecodingResult::U32(v) => v.into_iter().map(i64::from).collect(),
            DecodingResult::I8(v) => v.into_iter().map(i64::from).collect(),
            DecodingResult::I16(v) => v.into_iter().map(i64::from).collect(),
            DecodingResult::I32(v) => v.into_iter().map(i64::from).collect(),
            _ => return Err(Error::field(&self.path, "SampleFormat", "expected integer class codes")),
        };
        let (data_w, _) = self.decoder.chunk_data_dimensions(chunk);
        Ok((values, data_w as usize))
    }
}

/// GeoKey ids used here.
pub mod geokey {
    /// 1 = projected, 2 = geographic.
    pub const MODEL_TYPE: u16 = 1024;
    /// 1 = PixelIsArea, 2 = PixelIsPoint.
    pub const RASTER_TYPE: u16 = 1025;
    /// Geographic CRS EPSG code.
    pub const GEOGRAPHIC_TYPE: u16 = 2048;
    /// Projected CRS EPSG code.
    pub const PROJECTED_CS_TYPE: u16 = 3072;
}

impl std::fmt::Debug for LandCoverRaster {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LandCoverRaster").field("path", &self.path).field("size", &(self.width, self.height)).finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiepoint_transform_maps_corners() {
        let t =
            GeoTransform::from_tiepoint(&[100.0, 100.0, 0.0], &[0.0, 0.0, 0.0, 3_500_000.0, 2_600_000.0, 0.0], false)
                .unwrap();
        assert_eq!(t.pixel_of(3_500_000.0, 2_600_000.0, 10, 10), Some((0, 0)));
        assert_eq!(t.pixel_of(3_500_099.9, 2_599_900.1, 10, 10), Some((0, 0)));
        assert_eq!(t.pixel_of(3_500_100.0, 2_599_899.0, 10, 10), Some((1, 1)));
        assert_eq!(t.pixel_of(3_499_999.0, 2_599_999.0, 10, 10), None);
        assert_eq!(t.pixel_of(3_501_000.0, 2_599_999.0, 10, 10), None);
        // PixelIsPoint: the tie point is the centre of pixel (0, 0).
        let p =
            GeoTransform::from_tiepoint(&[100.0, 100.0, 0.0], &[0.0, 0.0, 0.0, 3_500_050.0, 2_599_950.0, 0.0], true)
                .unwrap();
        assert_eq!((p.x0, p.y0), (3_500_000.0, 2_600_000.0));
    }

    #[test]
    fn bad_georeferencing_is_an_error() {
        assert!(GeoTransform::from_tiepoint(&[0.0, 100.0, 0.0], &[0.0; 6], false).is_err());
        assert!(GeoTransform::from_tiepoint(&[100.0], &[0.0; 6], false).is_err());
        let mut m = [0.0; 16];
        m[0] = 10.0;
        m[5] = -10.0;
        m[1] = 0.1;
        assert!(GeoTransform::from_matrix(&m, false).is_err());
        m[1] = 0.0;
        m[3] = 100.0;
        m[7] = 200.0;
        assert_eq!(
            GeoTransform::from_matrix(&m, false).unwrap(),
            GeoTransform { x0: 100.0, y0: 200.0, sx: 10.0, sy: 10.0 }
        );
    }

    #[test]
    fn geokey_directory_parses_inline_keys() {
        let dir = [1, 1, 0, 3, 1024, 0, 1, 1, 1025, 0, 1, 1, 3072, 0, 1, 3035];
        let k = geokeys(&dir);
        assert_eq!(k.get(&geokey::PROJECTED_CS_TYPE), Some(&3035));
        assert_eq!(k.get(&geokey::RASTER_TYPE), Some(&1));
        assert!(geokeys(&[1, 1]).is_empty());
    }
}
