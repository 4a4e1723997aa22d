//! COPC tiles (`*.copc.laz`, as IGN publishes LiDAR HD): a LAZ 1.4 file whose points are an octree
//! of LAZ chunks, with a hierarchy saying where each node's chunk lies. Only the nodes whose
//! bounds meet the cells the work needs are decoded, at every level of detail (docs/copc.md).
//!
//! The hierarchy is read here, on top of the `las` crate (header, VLRs, point records) and the
//! `laz` crate (one node's chunk decoded with its layered decompressor). The `las` crate's own COPC
//! reader (0.11) reads only the first hierarchy EVLR, but copclib writes one EVLR per page, so it
//! cannot read the deep tiles of tests/data/als-copc. Every page, node key, offset and count is
//! checked before it is used: a hostile hierarchy could otherwise loop, shift out of range or
//! allocate without bound.

use std::collections::HashSet;
use std::path::Path;

use std::io::{Read, Seek, SeekFrom};

use laz::record::{LayeredPointRecordDecompressor, RecordDecompressor};
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::io::las::{check_layout, columns, tile_header, TileHeader};
use crate::io::source;
use crate::kernels::geo::cells::Cells;
use crate::kernels::sim::AlsPoints;

/// Deepest octree level accepted (a 1 km tile at level 24 has 0.06 mm nodes).
const MAX_LEVEL: i32 = 24;

/// Most compressed bytes of the nodes fetched at once from a remote object: the memory a remote
/// read holds beyond its points.
const REMOTE_BATCH_BYTES: u64 = 64 << 20;

/// Size of one hierarchy entry (COPC 1.0: key 16, offset 8, byte size 4, point count 4).
const ENTRY_BYTES: usize = 32;

/// The point attributes a read decodes. Each attribute is a layer of its own in a COPC chunk, and a
/// layer not asked for is skipped, not decoded (`laz`'s selective decompression).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Attributes {
    /// Every attribute of [`AlsPoints`].
    All,
    /// All but the pulse identity: GPS time (NaN) and point source (0), which only density
    /// normalisation by pulse uses. GPS time is the costliest layer to decode.
    WithoutPulseIdentity,
}

impl Attributes {
    fn selection(self) -> laz::DecompressionSelection {
        let s = laz::DecompressionSelection::base()
            .decompress_z()
            .decompress_classification()
            .decompress_intensity()
            .decompress_scan_angle();
        match self {
            Attributes::All => s.decompress_point_source_id().decompress_gps_time(),
            Attributes::WithoutPulseIdentity => s,
        }
    }
}

/// An opened COPC tile: its header facts and its octree's data nodes, checked.
#[derive(Debug, Clone)]
pub struct CopcTile {
    header: TileHeader,
    las_header: las::Header,
    laz: laz::LazVlr,
    /// Bytes of one point record.
    record: usize,
    /// Layers in a chunk (COPC's point formats 6–8: 9 for the point, 1 for RGB, 1 for NIR, 1 per
    /// extra byte).
    layers: usize,
    /// The octree's cube: centre (x, y, z) and half the side.
    cube: [f64; 4],
    /// The cube was not recorded in the COPC info VLR and was taken from the header bounds.
    cube_inferred: bool,
    nodes: Vec<Node>,
    /// Half of the coordinates' resolution (m): node bounds are widened by it.
    slack: f64,
}

/// What reading a COPC tile touched.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct CopcRead {
    /// Data nodes decoded, of `nodes_in_tile`.
    pub nodes: usize,
    pub nodes_in_tile: usize,
    /// Points decoded, of `points_in_tile`.
    pub points_decoded: u64,
    pub points_in_tile: u64,
    /// Compressed bytes of the nodes decoded.
    pub bytes_decoded: u64,
    /// Points kept (inside the cells asked for).
    pub points_kept: u64,
    /// The node bounds could not be trusted (a point outside its node), so every node was decoded.
    pub read_whole: bool,
}

impl CopcRead {
    /// Add what another read touched (of another tile).
    pub fn add(&mut self, o: &CopcRead) {
        self.nodes += o.nodes;
        self.nodes_in_tile += o.nodes_in_tile;
        self.points_decoded += o.points_decoded;
        self.points_in_tile += o.points_in_tile;
        self.bytes_decoded += o.bytes_decoded;
        self.points_kept += o.points_kept;
        self.read_whole |= o.read_whole;
    }
}

impl std::fmt::Display for CopcRead {
    /// `N of M octree nodes decoded (a of b points, c compressed bytes)`, and a word when the
    /// node bounds did not hold.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} of {} octree nodes decoded ({} of {} points, {} compressed bytes)",
            self.nodes, self.nodes_in_tile, self.points_decoded, self.points_in_tile, self.bytes_decoded
        )?;
        if self.read_whole {
            write!(f, " (the octree's node bounds did not hold: every node decoded)")?;
        }
        Ok(())
    }
}

impl CopcTile {
    /// Open a COPC file: header, COPC info VLR and hierarchy read and checked.
    pub fn open(path: &Path) -> Result<Self> {
        Self::open_if_copc(path)?.ok_or_else(|| Error::field(path, "COPC info VLR", "missing: not a COPC file"))
    }

    /// Open a LAS/LAZ file as COPC if its header carries the COPC info VLR; `None` otherwise.
    pub fn open_if_copc(path: &Path) -> Result<Option<Self>> {
        let bad = |field: &str, msg: String| Error::field(path, field, msg);
        let (mut file, len) = source::open(path)?;
        let layout = check_layout(path, &mut file, len)?;
        let mut file = std::io::BufReader::new(file);
        let h = las::Header::new(&mut file).map_err(|e| {
            bad("header", format!("cannot read the header or its VLRs: {}", crate::error::one_line(&e.to_string())))
        })?;
        let header = tile_header(path, &h, &layout)?;
        let Some(info) = h.copc_info_vlr() else { return Ok(None) };
        // The root page's place (COPC 1.0 info VLR, bytes 40–55), which the crate keeps private.
        let info_data = &h.vlrs().iter().find(|v| v.is_copc_info()).expect("info VLR found above").data;
        let u64_at = |i: usize| info_data.get(i..i + 8).map(|b| u64::from_le_bytes(b.try_into().expect("8 bytes")));
        let (Some(root_at), Some(root_size)) = (u64_at(40), u64_at(48)) else {
            return Err(bad("COPC info VLR", format!("{} bytes, fewer than 56", info_data.len())));
        };
        if layout.copc_hierarchy.is_empty() {
            return Err(bad("COPC hierarchy EVLR", "missing".into()));
        }
        let read_page = |offset: u64, size: u64| -> std::result::Result<Vec<u8>, String> {
            let inside = layout
                .copc_hierarchy
                .iter()
                .any(|&(at, len)| offset >= at && offset.checked_add(size).is_some_and(|end| end <= at + len));
            if !inside || !size.is_multiple_of(ENTRY_BYTES as u64) {
                return Err(format!("a page of {size} bytes at byte {offset} lies outside the hierarchy records"));
            }
            let mut buf = vec![0u8; size as usize];
            file.seek(SeekFrom::Start(offset)).and_then(|_| file.read_exact(&mut buf)).map_err(|e| e.to_string())?;
            Ok(buf)
        };
        let record = usize::from(h.point_format().len());
        let mut nodes = hierarchy_nodes((root_at, root_size), read_page, |n| {
            check_node(n, record, layout.data_start, layout.file_len)
        })
        .map_err(|m| bad("COPC hierarchy", m))?;
        // In file order: a read then moves forward through the file.
        nodes.sort_by_key(|n| n.offset);
        let announced = header.number_of_points;
        let held: u64 = nodes.iter().map(|n| n.points).sum();
        if held != announced {
            return Err(bad(
                "COPC hierarchy",
                format!("its nodes hold {held} points but the header announces {announced}"),
            ));
        }
        let b = header.bounds;
        let t = h.transforms();
        let slack = 0.5 * t.x.scale.abs().max(t.y.scale.abs()).max(t.z.scale.abs());
        let recorded = [info.center_x, info.center_y, info.center_z, info.halfsize];
        let holds_bounds = recorded.iter().all(|v| v.is_finite())
            && info.halfsize > 0.0
            && (0..3).all(|i| {
                recorded[i] - info.halfsize <= b[i] + slack && b[i + 3] - slack <= recorded[i] + info.halfsize
            });
        let (cube, cube_inferred) = if holds_bounds {
            (recorded, false)
        } else {
            // A cube centred on the header bounds, as COPC writers make it.
            let half = (0..3).map(|i| b[i + 3] - b[i]).fold(0.0, f64::max) / 2.0;
            ([(b[0] + b[3]) / 2.0, (b[1] + b[4]) / 2.0, (b[2] + b[5]) / 2.0, half], true)
        };
        let laz = h.laz_vlr().map_err(|e| bad("laszip VLR", crate::error::one_line(&e.to_string())))?;
        let layers = laz
            .items()
            .iter()
            .map(|item| match item.item_type() {
                laz::LazItemType::Point14 => Some(9),
                laz::LazItemType::RGB14 => Some(1),
                laz::LazItemType::RGBNIR14 => Some(2),
                laz::LazItemType::Byte14(n) => Some(usize::from(n)),
                _ => None,
            })
            .sum::<Option<usize>>()
            .filter(|_| (6..=8).contains(&header.point_format))
            .ok_or_else(|| {
                bad("point_format", format!("{}: COPC stores point formats 6, 7 and 8 only", header.point_format))
            })?;
        Ok(Some(CopcTile { header, las_header: h, laz, record, layers, cube, cube_inferred, nodes, slack }))
    }

    /// The header facts.
    pub fn header(&self) -> &TileHeader {
        &self.header
    }

    /// Number of data nodes in the octree.
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Whether the octree's cube had to be taken from the header bounds (the COPC info VLR records
    /// none, or one that does not hold the points).
    pub fn cube_inferred(&self) -> bool {
        self.cube_inferred
    }

    /// Bounds [xmin, ymin, zmin, xmax, ymax, zmax] of a node, widened by half the resolution.
    fn bounds(&self, n: &Node) -> [f64; 6] {
        let side = 2.0 * self.cube[3] / f64::from(1u32 << n.level);
        let min = |axis: usize| self.cube[axis] - self.cube[3] + side * f64::from(n.key[axis]);
        let s = self.slack;
        let (x0, y0, z0) = (min(0), min(1), min(2));
        [x0 - s, y0 - s, z0 - s, x0 + side + s, y0 + side + s, z0 + side + s]
    }

    /// The points inside `cells` (every point with `None`), decoding only the nodes whose
    /// horizontal bounds meet them, in parallel. Points come node by node, in file order.
    ///
    /// Every decoded point is checked against its node's bounds: if one lies outside, the
    /// hierarchy cannot say where points are, and every node is decoded (`read_whole`).
    pub fn read(&self, cells: Option<&Cells>, attributes: Attributes) -> Result<(AlsPoints, CopcRead)> {
        // A cube that says nothing (header bounds not finite) selects nothing: decode everything.
        let unknown = !self.cube.iter().all(|v| v.is_finite());
        let selected: Vec<Node> = match cells {
            Some(c) if !unknown => self
                .nodes
                .iter()
                .filter(|n| {
                    let b = self.bounds(n);
                    c.meets([b[0], b[1], b[3], b[4]])
                })
                .copied()
                .collect(),
            _ => self.nodes.clone(),
        };
        let (mut points, mut stats, outside) = self.decode(&selected, cells, attributes)?;
        stats.read_whole = unknown;
        if outside && cells.is_some() && !unknown {
            (points, stats, _) = self.decode(&self.nodes, cells, attributes)?;
            stats.read_whole = true;
        }
        stats.nodes_in_tile = self.nodes.len();
        stats.points_in_tile = self.header.number_of_points;
        stats.points_kept = points.len() as u64;
        Ok((points, stats))
    }

    /// Decode `nodes` (in file order, as `self.nodes` keeps them), keeping the points in `cells`;
    /// also says whether a point lay outside its node. A local file is read node by node by each
    /// thread; a remote object in batches of [`REMOTE_BATCH_BYTES`], each batch's ranges fetched at
    /// once (neighbours less than [`source::COALESCE_BYTES`] apart in one request).
    fn decode(
        &self,
        nodes: &[Node],
        cells: Option<&Cells>,
        attributes: Attributes,
    ) -> Result<(AlsPoints, CopcRead, bool)> {
        let path = &self.header.path;
        let read_error = |node: &Node, e: std::io::Error| {
            Error::field(
                path,
                "points",
                format!("cannot read COPC node {node}: {}", crate::error::one_line(&e.to_string())),
            )
        };
        let parts: Vec<Result<(AlsPoints, bool)>> = match source::remote(path)? {
            None => nodes
                .par_iter()
                .map_init(
                    || source::open(path).map(|(file, _)| file),
                    |file, node| {
                        let file = file.as_mut().map_err(|e| Error::file(path, e.to_string()))?;
                        let mut chunk = vec![0u8; node.bytes as usize];
                        file.seek(SeekFrom::Start(node.offset))
                            .and_then(|_| file.read_exact(&mut chunk))
                            .map_err(|e| read_error(node, e))?;
                        self.decode_chunk(&chunk, node, cells, attributes)
                    },
                )
                .collect(),
            Some(remote) => {
                let mut parts = Vec::with_capacity(nodes.len());
                let mut start = 0;
                while start < nodes.len() {
                    let mut end = start;
                    let mut bytes = 0;
                    while end < nodes.len() && (end == start || bytes + nodes[end].bytes <= REMOTE_BATCH_BYTES) {
                        bytes += nodes[end].bytes;
                        end += 1;
                    }
                    let batch = &nodes[start..end];
                    let ranges: Vec<_> = batch.iter().map(|n| n.offset..n.offset + n.bytes).collect();
                    let chunks = remote.fetch_ranges(&ranges).map_err(|e| read_error(&batch[0], e))?;
                    parts.par_extend(
                        batch
                            .par_iter()
                            .zip(chunks)
                            .map(|(node, chunk)| self.decode_chunk(&chunk, node, cells, attributes)),
                    );
                    start = end;
                }
                parts
            }
        };
        let parts = parts.into_iter().collect::<Result<Vec<_>>>()?;
        let mut points = AlsPoints::with_capacity(parts.iter().map(|(p, _)| p.len()).sum());
        let mut outside = false;
        for (p, o) in parts {
            outside |= o;
            points.extend_from(&p);
        }
        let stats = CopcRead {
            nodes: nodes.len(),
            points_decoded: nodes.iter().map(|n| n.points).sum(),
            bytes_decoded: nodes.iter().map(|n| n.bytes).sum(),
            ..Default::default()
        };
        Ok((points, stats, outside))
    }

    /// One node's points in `cells`, from its chunk, and whether one of its points lay outside its
    /// bounds.
    fn decode_chunk(
        &self,
        chunk: &[u8],
        node: &Node,
        cells: Option<&Cells>,
        attributes: Attributes,
    ) -> Result<(AlsPoints, bool)> {
        let cannot =
            |why: String| Error::field(&self.header.path, "points", format!("cannot decode COPC node {node}: {why}"));
        self.check_chunk(chunk, node).map_err(cannot)?;
        let mut buf = vec![0u8; node.points as usize * self.record];
        // A COPC chunk is a LAZ layered chunk of its own, decoded from memory. The `laz` decoder
        // panics on some corrupt streams: caught and reported, as in `io::las`.
        let decoded = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| -> std::io::Result<()> {
            let mut d = LayeredPointRecordDecompressor::new(std::io::Cursor::new(chunk));
            d.set_fields_from(self.laz.items()).map_err(std::io::Error::other)?;
            d.set_selection(attributes.selection());
            d.decompress_many(&mut buf)
        }));
        decoded
            .map_err(|_| cannot("corrupt compressed data (the LAZ decoder failed)".into()))?
            .map_err(|e| cannot(crate::error::one_line(&e.to_string())))?;
        let data = las::PointDataBuilder::new()
            .for_header(&self.las_header)
            .build_from_bytes(buf)
            .map_err(|e| cannot(crate::error::one_line(&e.to_string())))?;
        let mut p = columns(&data);
        if attributes == Attributes::WithoutPulseIdentity {
            // A layer skipped keeps its chunk's first value: cleared so that nothing reads it.
            p.gps_time.fill(f64::NAN);
            p.point_source_id.fill(0);
        }
        let b = self.bounds(node);
        let inside = |i: usize| {
            (b[0]..=b[3]).contains(&p.x[i]) && (b[1]..=b[4]).contains(&p.y[i]) && (b[2]..=b[5]).contains(&p.z[i])
        };
        let outside = !(0..p.len()).all(inside);
        let p = match cells {
            Some(c) => {
                let keep: Vec<u32> =
                    (0..p.len() as u32).filter(|&i| c.contains(p.x[i as usize], p.y[i as usize])).collect();
                if keep.len() == p.len() {
                    p
                } else {
                    p.permuted(&keep)
                }
            }
            None => p,
        };
        Ok((p, outside))
    }
}

impl CopcTile {
    /// A chunk's layout checked before the decoder trusts it: its first point, its point count
    /// (equal to the node's) and its layer sizes (inside the chunk; the decoder allocates what
    /// they announce).
    fn check_chunk(&self, chunk: &[u8], node: &Node) -> std::result::Result<(), String> {
        let head = self.record + 4 + 4 * self.layers;
        if chunk.len() < head {
            return Err(format!("a chunk of {} bytes cannot hold its {head}-byte head", chunk.len()));
        }
        let u32_at = |i: usize| u64::from(u32::from_le_bytes(chunk[i..i + 4].try_into().expect("4 bytes")));
        let count = u32_at(self.record);
        if count != node.points {
            return Err(format!("the chunk holds {count} points, the hierarchy says {}", node.points));
        }
        let layers: u64 = (0..self.layers).map(|l| u32_at(self.record + 4 + 4 * l)).sum();
        if layers > (chunk.len() - head) as u64 {
            return Err(format!("its layers announce {layers} bytes, the chunk holds {}", chunk.len() - head));
        }
        Ok(())
    }
}

/// One data node of the octree: its key, and where its LAZ chunk lies.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Node {
    level: u32,
    /// x, y, z index of the node at its level.
    key: [i32; 3],
    offset: u64,
    bytes: u64,
    points: u64,
}

impl std::fmt::Display for Node {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}-{}-{}-{}", self.level, self.key[0], self.key[1], self.key[2])
    }
}

/// Most point bytes one compressed byte may announce: far above what LAZ achieves (5–10), and a
/// bound on what a node's count makes the reader allocate.
const MAX_EXPANSION: u64 = 1000;

/// A data node checked against the file: its chunk inside the point data, its count within what
/// its bytes can hold (`record`-byte points).
fn check_node(n: &Node, record: usize, data_start: u64, file_len: u64) -> std::result::Result<(), String> {
    let end = n.offset.checked_add(n.bytes);
    if n.bytes == 0 || n.offset < data_start || end.is_none_or(|end| end > file_len) {
        return Err(format!("node {n}: a chunk of {} bytes at byte {} lies outside the point data", n.bytes, n.offset));
    }
    if n.points.saturating_mul(record as u64) > MAX_EXPANSION.saturating_mul(n.bytes) {
        return Err(format!("node {n}: {} points cannot come from {} compressed bytes", n.points, n.bytes));
    }
    Ok(())
}

/// The data nodes of the hierarchy, walking its pages from `root` (file offset, bytes), each read
/// by `read_page`: every page referenced once, every key inside the octree and met once, every
/// count positive, every node checked by `check`.
fn hierarchy_nodes(
    root: (u64, u64),
    mut read_page: impl FnMut(u64, u64) -> std::result::Result<Vec<u8>, String>,
    check: impl Fn(&Node) -> std::result::Result<(), String>,
) -> std::result::Result<Vec<Node>, String> {
    let mut pending = vec![root];
    let mut pages_seen = HashSet::new();
    let mut keys = HashSet::new();
    let mut nodes = Vec::new();
    while let Some((offset, size)) = pending.pop() {
        if !pages_seen.insert(offset) {
            return Err(format!("the page at byte {offset} is referenced twice"));
        }
        for raw in read_page(offset, size)?.chunks_exact(ENTRY_BYTES) {
            let i32_at = |i: usize| i32::from_le_bytes(raw[i..i + 4].try_into().expect("4 bytes"));
            let (l, key) = (i32_at(0), [i32_at(4), i32_at(8), i32_at(12)]);
            let (bytes, count) = (i32_at(24), i32_at(28));
            let name = format!("{l}-{}-{}-{}", key[0], key[1], key[2]);
            if !(0..=MAX_LEVEL).contains(&l) || key.iter().any(|&i| i < 0 || i64::from(i) >= 1i64 << l) {
                return Err(format!("node key {name} lies outside the octree"));
            }
            // A page is referenced under the key of its first node, which the page lists again.
            if count != -1 && !keys.insert((l, key)) {
                return Err(format!("node {name} appears twice"));
            }
            let offset = u64::from_le_bytes(raw[16..24].try_into().expect("8 bytes"));
            match count {
                -1 => pending.push((offset, u64::try_from(bytes).map_err(|_| format!("page {name}: {bytes} bytes"))?)),
                0 => {}
                n if n > 0 => {
                    let node = Node {
                        level: l as u32,
                        key,
                        offset,
                        bytes: u64::try_from(bytes).map_err(|_| format!("node {name}: {bytes} bytes"))?,
                        points: n as u64,
                    };
                    check(&node)?;
                    nodes.push(node);
                }
                n => return Err(format!("node {name}: point count {n}")),
            }
        }
    }
    Ok(nodes)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(l: i32, x: i32, offset: u64, bytes: i32, count: i32) -> Vec<u8> {
        let mut v = Vec::new();
        for i in [l, x, 0, 0] {
            v.extend_from_slice(&i.to_le_bytes());
        }
        v.extend_from_slice(&offset.to_le_bytes());
        v.extend_from_slice(&bytes.to_le_bytes());
        v.extend_from_slice(&count.to_le_bytes());
        v
    }

    /// Pages at file offsets 1000 + 100 i, read from `pages`.
    fn walk(pages: &[Vec<u8>]) -> std::result::Result<Vec<Node>, String> {
        let read = |offset: u64, size: u64| {
            let i = offset.checked_sub(1000).map(|o| o / 100).unwrap_or(u64::MAX) as usize;
            match pages.get(i) {
                Some(p) if p.len() as u64 == size => Ok(p.clone()),
                _ => Err(format!("a page of {size} bytes at byte {offset} lies outside the hierarchy records")),
            }
        };
        hierarchy_nodes((1000, pages[0].len() as u64), read, |n| check_node(n, 30, 100, 900))
    }

    #[test]
    fn pages_are_walked_once_and_bad_entries_refused() {
        // Root page: a node, and a reference to page 1 holding one node.
        let root = [entry(0, 0, 500, 10, 7), entry(1, 1, 1100, 32, -1)].concat();
        let nodes = walk(&[root.clone(), entry(1, 0, 600, 10, 3)]).unwrap();
        assert_eq!(nodes.iter().map(|n| n.points).sum::<u64>(), 10);
        let err = |pages: &[Vec<u8>]| walk(pages).unwrap_err();
        assert!(err(&[entry(0, 0, 1000, 32, -1)]).contains("referenced twice"));
        assert!(err(&[entry(0, 0, 5000, 32, -1)]).contains("outside the hierarchy"));
        assert!(err(&[[entry(0, 0, 500, 10, 7), entry(0, 0, 600, 10, 7)].concat()]).contains("twice"));
        assert!(err(&[entry(2, 4, 500, 10, 1)]).contains("outside the octree")); // x ≥ 2^l
        assert!(err(&[entry(40, 0, 500, 10, 1)]).contains("outside the octree"));
        assert!(err(&[entry(-1, 0, 500, 10, 1)]).contains("outside the octree"));
        assert!(err(&[entry(0, 0, 50, 10, 1)]).contains("outside the point data"));
        assert!(err(&[entry(0, 0, 895, 10, 1)]).contains("outside the point data"));
        assert!(err(&[entry(0, 0, 500, -10, 1)]).contains("bytes"));
        assert!(err(&[entry(0, 0, 500, 10, -7)]).contains("point count"));
        assert!(err(&[entry(0, 0, 500, 10, 400)]).contains("cannot come from"));
        // 12,000 bytes from 10
    }
}
