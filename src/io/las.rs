//! LAS/LAZ files: header facts, CRS, and points decoded in chunks (memory bounded by the chunk).

use std::path::{Path, PathBuf};

use las::{PointData, PointDataBuilder, Reader};

use crate::error::{Error, Result};
use crate::kernels::sim::AlsPoints;

/// Points decoded per chunk when streaming a tile.
pub const CHUNK_POINTS: u64 = 1 << 20;

/// What a tile's header and VLRs say, before any point is read.
#[derive(Debug, Clone, PartialEq)]
pub struct TileHeader {
    pub path: PathBuf,
    /// "1.4" etc.
    pub version: String,
    pub point_format: u8,
    pub compressed: bool,
    /// Point count announced by the header.
    pub number_of_points: u64,
    /// Header bounds [xmin, ymin, zmin, xmax, ymax, zmax].
    pub bounds: [f64; 6],
    /// Horizontal CRS as an EPSG code, when the WKT or GeoTIFF records give one.
    pub epsg: Option<u32>,
    /// The WKT CRS record, when present.
    pub crs_wkt: Option<String>,
    /// Names of the extra-bytes dimensions.
    pub extra_bytes: Vec<String>,
    /// Number of EVLRs (stored after the points).
    pub n_evlrs: usize,
    /// The header carries the COPC info VLR: the points are an octree of LAZ chunks (`io::copc`).
    pub copc: bool,
}

/// Where a file's parts lie, as checked by [`check_layout`].
#[derive(Debug, Clone)]
pub(crate) struct Layout {
    /// First byte of the point data.
    pub data_start: u64,
    pub file_len: u64,
    /// (file offset, bytes) of the data of each COPC hierarchy EVLR (`copc`/1000): COPC 1.0 has
    /// one holding every page, copclib writes one per page.
    pub copc_hierarchy: Vec<(u64, u64)>,
    /// The data of a WKT CRS EVLR (`LASF_Projection`/2112). The `las` crate (0.11) reads only
    /// the first EVLR, and COPC writers put the hierarchy first (tests/data/als-copc).
    pub wkt_evlr: Option<Vec<u8>>,
}

/// Largest WKT CRS record read from an EVLR (bytes).
const MAX_WKT_BYTES: u64 = 1 << 20;

/// The header facts of a LAS/LAZ file, local or remote, reading only its header and (E)VLRs.
pub fn read_header(path: &Path) -> Result<TileHeader> {
    let (mut file, len) = crate::io::source::open(path)?;
    let layout = check_layout(path, &mut file, len)?;
    let h = las::Header::new(&mut std::io::BufReader::new(file)).map_err(|e| {
        Error::field(
            path,
            "header",
            format!("cannot read the header or its VLRs: {}", crate::error::one_line(&e.to_string())),
        )
    })?;
    tile_header(path, &h, &layout)
}

/// A tile opened for streaming.
pub struct TileReader {
    header: TileHeader,
    reader: Reader,
    buffer: PointData,
    read_so_far: u64,
}

impl TileReader {
    /// Open a LAS or LAZ file and read its header.
    pub fn open(path: &Path) -> Result<Self> {
        Self::open_with(path, false)
    }

    /// Open a file; `parallel` decodes LAZ chunks on the rayon pool.
    pub fn open_with(path: &Path, parallel: bool) -> Result<Self> {
        let (mut file, len) = crate::io::source::open(path)?;
        let layout = check_layout(path, &mut file, len)?;
        let laz_parallelism = if parallel { las::LazParallelism::Yes } else { las::LazParallelism::No };
        let options = las::ReaderOptions::default().with_laz_parallelism(laz_parallelism);
        let reader = Reader::with_options(std::io::BufReader::with_capacity(1 << 20, file), options).map_err(|e| {
            Error::field(
                path,
                "header",
                format!(
                    "cannot read the header, VLRs or LAZ chunk table (truncated or not LAS/LAZ?): {}",
                    crate::error::one_line(&e.to_string())
                ),
            )
        })?;
        let header = tile_header(path, reader.header(), &layout)?;
        let buffer = PointDataBuilder::new().for_header(reader.header()).build();
        Ok(TileReader { header, reader, buffer, read_so_far: 0 })
    }

    /// The header facts.
    pub fn header(&self) -> &TileHeader {
        &self.header
    }

    /// Decode up to `n` further points; `None` once the header's count has been read.
    ///
    /// A file holding fewer points than its header announces (truncated, or a lying header)
    /// gives an error naming `number_of_points`.
    pub fn next_chunk(&mut self, n: u64) -> Result<Option<AlsPoints>> {
        let left = self.header.number_of_points - self.read_so_far;
        if left == 0 {
            return Ok(None);
        }
        let want = n.min(left);
        let path = self.header.path.clone();
        let cannot_decode = |why: String| {
            Error::field(
                &path,
                "points",
                format!(
                    "cannot decode points {}..{} (header number_of_points = {}): {why}",
                    self.read_so_far,
                    self.read_so_far + want,
                    self.header.number_of_points,
                ),
            )
        };
        // A corrupt LAZ stream can only be found by decoding it, and the `laz` decoder indexes its
        // contexts with decoded values (an out-of-range index panics): the one place a
        // third-party panic is caught instead of prevented, and reported as corrupt data.
        let (reader, buffer) = (&mut self.reader, &mut self.buffer);
        let got = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| reader.fill_points(want, buffer)))
            .map_err(|_| cannot_decode("corrupt compressed data (the LAZ decoder failed)".into()))?
            .map_err(|e| cannot_decode(crate::error::one_line(&e.to_string())))?;
        if got < want {
            return Err(Error::field(
                &path,
                "number_of_points",
                format!(
                    "header announces {} points but the file holds {}",
                    self.header.number_of_points,
                    self.read_so_far + got
                ),
            ));
        }
        self.read_so_far += got;
        Ok(Some(columns(&self.buffer)))
    }

    /// Read every remaining point into one set (for small files and the direct simulation mode).
    pub fn read_all(mut self) -> Result<AlsPoints> {
        let mut all = AlsPoints::with_capacity(self.header.number_of_points.min(1 << 28) as usize);
        while let Some(chunk) = self.next_chunk(CHUNK_POINTS)? {
            all.extend_from(&chunk);
        }
        Ok(all)
    }
}

/// Check what the header, VLRs, EVLRs and LAZ chunk table announce against the file's size before
/// the `las` crate trusts them (a hostile count overflows its arithmetic or allocates unbounded
/// memory): scale factors finite and non-zero, offsets finite, every record inside the file, and
/// the point count equal to what the point bytes hold (LAS) or within the chunk table's capacity
/// (LAZ; an understatement smaller than one chunk of a fixed-chunk file is not detectable here).
/// Leaves `file` at its start.
pub(crate) fn check_layout<R: std::io::Read + std::io::Seek>(
    path: &Path,
    file: &mut R,
    file_len: u64,
) -> Result<Layout> {
    use std::io::SeekFrom;
    let bad = |field: &str, msg: String| Error::field(path, field, msg);
    let io = |e: std::io::Error| Error::field(path, "header", format!("cannot read: {e}"));
    let h = las::raw::Header::read_from(std::io::BufReader::new(&mut *file)).map_err(|e| {
        bad("header", format!("not a LAS/LAZ header (truncated?): {}", crate::error::one_line(&e.to_string())))
    })?;
    for (name, v) in [
        ("x_scale_factor", h.x_scale_factor),
        ("y_scale_factor", h.y_scale_factor),
        ("z_scale_factor", h.z_scale_factor),
    ] {
        if !(v.is_finite() && v != 0.0) {
            return Err(bad(name, format!("{v}: must be a finite non-zero number")));
        }
    }
    for (name, v) in [("x_offset", h.x_offset), ("y_offset", h.y_offset), ("z_offset", h.z_offset)] {
        if !v.is_finite() {
            return Err(bad(name, format!("{v}: must be finite")));
        }
    }
    let data_start = u64::from(h.offset_to_point_data);
    if data_start < u64::from(h.header_size) || data_start > file_len {
        return Err(bad(
            "offset_to_point_data",
            format!("{data_start} lies outside [header_size {}, file size {file_len}]", h.header_size),
        ));
    }
    // VLRs: between the header and the points.
    file.seek(SeekFrom::Start(u64::from(h.header_size))).map_err(io)?;
    let mut at = u64::from(h.header_size);
    let mut laszip = None;
    for i in 0..h.number_of_variable_length_records {
        if at + 54 > data_start {
            return Err(bad(
                "number_of_variable_length_records",
                format!(
                    "{}: VLR {i} would start at byte {at}, past the point data at {data_start}",
                    h.number_of_variable_length_records
                ),
            ));
        }
        let vlr = las::raw::Vlr::read_from(&mut *file, false)
            .map_err(|e| bad("VLR", crate::error::one_line(&e.to_string())))?;
        at += 54 + vlr.data.len() as u64;
        if at > data_start {
            return Err(bad("VLR", format!("VLR {i} ends at byte {at}, past the point data at {data_start}")));
        }
        let user = String::from_utf8_lossy(&vlr.user_id);
        // The first LASzip VLR, as the `las` crate uses.
        if laszip.is_none() && user.trim_end_matches('\0') == "laszip encoded" && vlr.record_id == 22204 {
            laszip = Some(vlr.data);
        }
    }
    // EVLRs: after the points, each inside the file.
    let mut points_end = file_len;
    let mut copc_hierarchy = Vec::new();
    let mut wkt_evlr = None;
    if let Some(evlr) = h.evlr.filter(|e| e.number_of_evlrs > 0) {
        let mut at = evlr.start_of_first_evlr;
        if at < data_start || at > file_len {
            return Err(bad(
                "start_of_first_evlr",
                format!("{at} lies outside [point data {data_start}, file size {file_len}]"),
            ));
        }
        points_end = at;
        for i in 0..evlr.number_of_evlrs {
            let mut head = [0u8; 60];
            file.seek(SeekFrom::Start(at)).map_err(io)?;
            file.read_exact(&mut head).map_err(|_| {
                bad(
                    "number_of_evlrs",
                    format!("{}: EVLR {i} at byte {at} is past the end of the file", evlr.number_of_evlrs),
                )
            })?;
            let len = u64::from_le_bytes(head[20..28].try_into().expect("8 bytes"));
            let user = String::from_utf8_lossy(&head[2..18]);
            if user.trim_end_matches('\0') == "copc" && head[18..20] == 1000u16.to_le_bytes() {
                copc_hierarchy.push((at + 60, len));
            }
            let wkt = user.trim_end_matches('\0') == "LASF_Projection" && head[18..20] == 2112u16.to_le_bytes();
            if wkt && wkt_evlr.is_none() && len <= MAX_WKT_BYTES && at + 60 + len <= file_len {
                let mut data = vec![0u8; len as usize];
                file.read_exact(&mut data).map_err(io)?;
                wkt_evlr = Some(data);
            }
            at = at.checked_add(60).and_then(|a| a.checked_add(len)).filter(|&a| a <= file_len).ok_or_else(|| {
                bad("EVLR", format!("EVLR {i} announces {len} bytes, past the end of the file ({file_len} bytes)"))
            })?;
        }
    }
    let legacy = u64::from(h.number_of_point_records);
    let count = match h.large_file {
        Some(lf) if legacy != 0 && legacy != lf.number_of_point_records => {
            return Err(bad(
                "number_of_point_records",
                format!("legacy count {legacy} differs from the 64-bit count {}", lf.number_of_point_records),
            ))
        }
        Some(lf) => lf.number_of_point_records,
        None => legacy,
    };
    let record = u64::from(h.point_data_record_length);
    let point_bytes = points_end - data_start;
    let compressed = h.point_data_record_format & 0x80 != 0 || h.point_data_record_format & 0x40 != 0;
    if record == 0 {
        return Err(bad("point_data_record_length", "0 bytes".into()));
    }
    if count.checked_mul(record).is_none() {
        return Err(bad(
            "number_of_point_records",
            format!("header announces {count} points, more than any file holds"),
        ));
    }
    match laszip {
        None if compressed => return Err(bad("laszip VLR", "compressed point format without a LASzip VLR".into())),
        None => {
            let holds = point_bytes / record;
            if holds != count {
                return Err(bad(
                    "number_of_point_records",
                    format!("header announces {count} points but the file holds {holds}"),
                ));
            }
        }
        Some(data) => {
            let vlr = laz::LazVlr::read_from(data.as_slice())
                .map_err(|e| bad("laszip VLR", crate::error::one_line(&e.to_string())))?;
            let item_bytes: u64 = vlr.items().iter().map(|i| u64::from(i.size())).sum();
            if vlr.items().is_empty() || item_bytes != record {
                return Err(bad(
                    "laszip VLR",
                    format!("its items describe {item_bytes}-byte points, the header {record}-byte points"),
                ));
            }
            file.seek(SeekFrom::Start(data_start)).map_err(io)?;
            let mut offset = [0u8; 8];
            file.read_exact(&mut offset)
                .map_err(|_| bad("points", "no LAZ chunk table offset after the header".into()))?;
            let table_at = i64::from_le_bytes(offset);
            // A table stored at the end (the writer could not seek back) is found by the reader;
            // only a table announced inside the file is checked here.
            if table_at > data_start as i64 && (table_at as u64) < points_end {
                let mut head = [0u8; 8];
                file.seek(SeekFrom::Start(table_at as u64)).map_err(io)?;
                file.read_exact(&mut head).map_err(|_| bad("chunk table", "truncated".into()))?;
                let chunks = u64::from(u32::from_le_bytes(head[4..8].try_into().expect("4 bytes")));
                if chunks > table_at as u64 - data_start {
                    return Err(bad(
                        "chunk table",
                        format!("{chunks} chunks cannot fit in {} bytes of points", table_at as u64 - data_start),
                    ));
                }
                file.seek(SeekFrom::Start(data_start)).map_err(io)?;
                let table = laz::laszip::ChunkTable::read_from(&mut *file, &vlr)
                    .map_err(|e| bad("chunk table", crate::error::one_line(&e.to_string())))?;
                let capacity =
                    table.as_ref().iter().try_fold(0u64, |sum, c| sum.checked_add(c.point_count)).ok_or_else(|| {
                        bad("chunk table", "its point counts add up to more than any file holds".into())
                    })?;
                let smallest = if vlr.uses_variable_size_chunks() {
                    capacity
                } else {
                    capacity.saturating_sub(u64::from(vlr.chunk_size())) + 1
                };
                if chunks > 0 && !(smallest..=capacity).contains(&count) {
                    return Err(bad(
                        "number_of_point_records",
                        format!(
                            "header announces {count} points but the LAZ chunk table holds {}",
                            if smallest == capacity {
                                capacity.to_string()
                            } else {
                                format!("{smallest} to {capacity}")
                            }
                        ),
                    ));
                }
            }
        }
    }
    file.seek(SeekFrom::Start(0)).map_err(io)?;
    Ok(Layout { data_start, file_len, copc_hierarchy, wkt_evlr })
}

/// Read every point (every class) of a LAS/LAZ file.
pub fn read_points(path: &Path) -> Result<AlsPoints> {
    TileReader::open(path)?.read_all()
}

/// Copy the columns gedisim uses out of a decoded block.
pub(crate) fn columns(pd: &PointData) -> AlsPoints {
    let n = pd.len();
    let mut p = AlsPoints::with_capacity(n);
    p.x.extend(pd.x());
    p.y.extend(pd.y());
    p.z.extend(pd.z());
    p.intensity.extend(pd.intensity());
    p.return_number.extend(pd.return_number());
    p.number_of_returns.extend(pd.number_of_returns());
    p.classification.extend(pd.classification());
    p.scan_angle_deg.extend(pd.scan_angle_degrees());
    match pd.gps_time() {
        Some(t) => p.gps_time.extend(t),
        None => p.gps_time.resize(n, f64::NAN),
    }
    p.point_source_id.extend(pd.point_source_id());
    p
}

pub(crate) fn tile_header(path: &Path, h: &las::Header, layout: &Layout) -> Result<TileHeader> {
    let b = h.bounds();
    let crs_wkt = h
        .get_wkt_crs_bytes()
        .or(layout.wkt_evlr.as_deref())
        .map(|bytes| String::from_utf8_lossy(bytes).trim_end_matches('\0').trim().to_string())
        .filter(|s| !s.is_empty());
    // A vertical CRS alone (EPSG:5720, NGF-IGN69 heights) says nothing of x and y.
    let mut epsg = crs_wkt.as_deref().filter(|w| !is_vertical_only(w)).and_then(epsg_from_wkt);
    if epsg.is_none() {
        let geotiff = h.get_geotiff_crs().map_err(|e| las_error(path, "GeoKeyDirectory", e))?;
        if let Some(g) = geotiff {
            epsg = g
                .get_projected_crs_geo_key_value()
                .or_else(|| g.get_geodetic_crs_geo_key_value())
                .filter(|&v| (1024..=32766).contains(&v))
                .map(u32::from);
        }
    }
    let version = h.version();
    let format = h.point_format();
    let extra_bytes = h
        .all_vlrs()
        .filter(|v| v.user_id == "LASF_Spec" && v.record_id == 4)
        .flat_map(|v| extra_bytes_names(&v.data))
        .collect();
    Ok(TileHeader {
        path: path.to_path_buf(),
        version: format!("{}.{}", version.major, version.minor),
        point_format: format.to_u8().map_err(|e| las_error(path, "point_format", e))?,
        compressed: format.is_compressed,
        number_of_points: h.number_of_points(),
        bounds: [b.min.x, b.min.y, b.min.z, b.max.x, b.max.y, b.max.z],
        epsg,
        crs_wkt,
        extra_bytes,
        n_evlrs: h.evlrs().len(),
        copc: h.copc_info_vlr().is_some(),
    })
}

/// Names of the extra-bytes dimensions in a LASF_Spec/4 record (192 bytes per dimension).
fn extra_bytes_names(data: &[u8]) -> Vec<String> {
    data.chunks_exact(192).map(|d| String::from_utf8_lossy(&d[4..36]).trim_end_matches('\0').to_string()).collect()
}

/// Whether a WKT string's outermost CRS is a vertical one (WKT1 `VERT_CS`, WKT2 `VERTCRS` or
/// `VERTICALCRS`): heights only, no horizontal CRS.
pub fn is_vertical_only(wkt: &str) -> bool {
    let head = wkt.trim_start().get(..12).unwrap_or(wkt).to_ascii_uppercase();
    ["VERT_CS[", "VERTCRS[", "VERTICALCRS["].iter().any(|k| head.starts_with(k))
}

/// The EPSG code of the outermost CRS of a WKT string (WKT1 `AUTHORITY["EPSG","n"]` or WKT2
/// `ID["EPSG",n]`): the last such clause at nesting depth 1.
pub fn epsg_from_wkt(wkt: &str) -> Option<u32> {
    let bytes = wkt.as_bytes();
    let mut depth = 0i32;
    let mut found = None;
    let mut i = 0;
    while i < bytes.len() {
        match bytes[i] {
            b'[' | b'(' => depth += 1,
            b']' | b')' => depth -= 1,
            _ => {
                if depth == 1 && wkt.is_char_boundary(i) {
                    let rest = &wkt[i..];
                    let upper = rest.get(..10).unwrap_or(rest).to_ascii_uppercase();
                    if upper.starts_with("AUTHORITY[") || upper.starts_with("ID[") {
                        let open = rest.find('[').unwrap();
                        if let Some(close) = rest[open..].find(']') {
                            let inner = &rest[open + 1..open + close];
                            let mut parts = inner.split(',').map(|s| s.trim().trim_matches('"'));
                            if parts.next().map(|a| a.eq_ignore_ascii_case("EPSG")) == Some(true) {
                                found = parts.next().and_then(|c| c.parse().ok()).or(found);
                            }
                        }
                    }
                }
            }
        }
        i += 1;
    }
    found
}

fn las_error(path: &Path, field: &str, e: las::Error) -> Error {
    Error::field(path, field, crate::error::one_line(&e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn epsg_of_lambert93_wkt1_and_wkt2() {
        let wkt1 = concat!(
            r#"PROJCS["RGF93 v1 / Lambert-93",GEOGCS["RGF93 v1",AUTHORITY["EPSG","4171"]],"#,
            r#"PROJECTION["Lambert_Conformal_Conic_2SP"],AUTHORITY["EPSG","2154"]]"#
        );
        assert_eq!(epsg_from_wkt(wkt1), Some(2154));
        let wkt2 = r#"PROJCRS["RGF93 v1 / Lambert-93",BASEGEOGCRS["RGF93 v1",ID["EPSG",4171]],ID["EPSG",2154]]"#;
        assert_eq!(epsg_from_wkt(wkt2), Some(2154));
        assert_eq!(epsg_from_wkt("LOCAL_CS[\"x\"]"), None);
    }
}
