//! Which shots of a granule an ingest keeps (docs/gedi-products.md, "Shots kept"): the dataset's ALS
//! coverage by default, a box or polygons when the user names one, or every shot.

use geo::{BoundingRect, Intersects, MultiPolygon, Point};
use rstar::primitives::{GeomWithData, Rectangle};
use rstar::RTree;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

/// The area whose shots an ingest keeps. A shot is placed as its row's `x`, `y` are (L2A lowest
/// mode, else the mean of L1B bin0 and lastbin); a shot with no valid position is never inside.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub enum ShotArea {
    /// Every shot (`--all-shots`, or a dataset without ALS tiles).
    #[default]
    All,
    /// ALS tile extents `[xmin, ymin, xmax, ymax]` in the shots' projected CRS, each grown by
    /// `margin_m` (the collocation's search and the footprint's reach).
    Tiles { extents: Vec<[f64; 4]>, margin_m: f64 },
    /// A box in degrees (WGS84): west, south, east, north, as `--bbox` and NASA's CMR take it; west
    /// above east crosses the antimeridian.
    LonLatBox([f64; 4]),
    /// Polygons in degrees (WGS84 longitude, latitude), from `--within <file>`; `source` names it.
    Polygons { source: String, polygons: MultiPolygon<f64> },
}

impl ShotArea {
    /// A `--bbox` value `west,south,east,north` (degrees), checked.
    pub fn lon_lat_box(text: &str) -> Result<ShotArea, String> {
        let v: Vec<f64> = text
            .split(',')
            .map(|p| p.trim().parse::<f64>().map_err(|_| format!("`{}` is not a number", p.trim())))
            .collect::<Result<_, _>>()?;
        let [w, s, e, n] = v[..] else {
            return Err(format!("{} values; give four: west,south,east,north (degrees)", v.len()));
        };
        if ![w, e].iter().all(|x| (-180.0..=180.0).contains(x)) {
            return Err("west and east must lie within −180…180°".into());
        }
        if !((-90.0..=90.0).contains(&s) && (-90.0..=90.0).contains(&n) && s < n) {
            return Err("south and north must lie within −90…90° with south below north".into());
        }
        Ok(ShotArea::LonLatBox([w, s, e, n]))
    }

    /// Whether every shot is kept.
    pub fn is_all(&self) -> bool {
        matches!(self, ShotArea::All)
    }

    /// Whether the test needs the shot's projected position (else only its longitude, latitude).
    pub fn needs_xy(&self) -> bool {
        matches!(self, ShotArea::Tiles { .. })
    }

    /// Whether a shot at `lon`, `lat` (degrees), projected to `xy`, is kept. One test: a loop over
    /// the shots of a granule tests through [`ShotArea::index`], built once.
    pub fn contains(&self, lon: f64, lat: f64, xy: Option<(f64, f64)>) -> bool {
        self.index().contains(lon, lat, xy)
    }

    /// The area ready for many tests: tile extents and polygons' bounding boxes in an R-tree, so
    /// that a shot is tested against the few rectangles around it, not against every tile of a
    /// national dataset (half a million LiDAR HD tiles) or every plot of an inventory.
    pub fn index(&self) -> AreaIndex<'_> {
        let rectangles: Vec<[f64; 4]> = match self {
            ShotArea::Tiles { extents, margin_m: m } => {
                extents.iter().map(|e| [e[0] - m, e[1] - m, e[2] + m, e[3] + m]).collect()
            }
            ShotArea::Polygons { polygons, .. } => polygons
                .0
                .iter()
                .map(|p| p.bounding_rect().map_or([f64::NAN; 4], |r| [r.min().x, r.min().y, r.max().x, r.max().y]))
                .collect(),
            ShotArea::All | ShotArea::LonLatBox(_) => Vec::new(),
        };
        let boxes = rectangles
            .into_iter()
            .enumerate()
            .filter(|(_, r)| r.iter().all(|v| v.is_finite()) && r[0] <= r[2] && r[1] <= r[3])
            .map(|(i, r)| GeomWithData::new(Rectangle::from_corners([r[0], r[1]], [r[2], r[3]]), i))
            .collect();
        AreaIndex { area: self, boxes: RTree::bulk_load(boxes) }
    }

    /// What the area is, for messages: "the 3 ALS tiles (+ 26.5 m)", "the box …", "the polygons of …".
    pub fn describe(&self) -> String {
        match self {
            ShotArea::All => "every shot".into(),
            ShotArea::Tiles { extents, margin_m } => {
                format!("the extents of the dataset's {} ALS tile(s) grown by {margin_m:.1} m", extents.len())
            }
            ShotArea::LonLatBox([w, s, e, n]) => format!("--bbox {w},{s},{e},{n}"),
            ShotArea::Polygons { source, polygons } => format!("--within {source} ({} polygon(s))", polygons.0.len()),
        }
    }

    /// A short key of the area, recorded with each granule: a granule read with another area is
    /// read again. `all` for every shot; otherwise a kind and a SHA-256 prefix of the geometry.
    pub fn key(&self) -> String {
        let digest = |text: String| hex::encode(&Sha256::digest(text.as_bytes())[..8]);
        match self {
            ShotArea::All => "all".into(),
            ShotArea::Tiles { extents, margin_m } => format!("tiles:{}", digest(format!("{extents:?} {margin_m}"))),
            ShotArea::LonLatBox(b) => format!("bbox:{}", digest(format!("{b:?}"))),
            ShotArea::Polygons { polygons, .. } => format!("within:{}", digest(format!("{polygons:?}"))),
        }
    }
}

/// A [`ShotArea`] with its rectangles (tile extents grown by the margin, polygons' bounding boxes)
/// in an R-tree: [`ShotArea::index`].
pub struct AreaIndex<'a> {
    area: &'a ShotArea,
    /// Each rectangle with the index of its tile extent or polygon.
    boxes: RTree<GeomWithData<Rectangle<[f64; 2]>, usize>>,
}

impl AreaIndex<'_> {
    /// Whether the test needs the shot's projected position ([`ShotArea::needs_xy`]).
    pub fn needs_xy(&self) -> bool {
        self.area.needs_xy()
    }

    /// Whether a shot at `lon`, `lat` (degrees), projected to `xy`, is kept; a point on a tile's
    /// edge or a polygon's boundary is inside.
    pub fn contains(&self, lon: f64, lat: f64, xy: Option<(f64, f64)>) -> bool {
        match self.area {
            ShotArea::All => true,
            ShotArea::Tiles { .. } => xy.is_some_and(|(x, y)| self.boxes.locate_at_point(&[x, y]).is_some()),
            ShotArea::LonLatBox([w, s, e, n]) => {
                let lon = wrap_lon(lon);
                let in_lon = if w <= e { lon >= *w && lon <= *e } else { lon >= *w || lon <= *e };
                in_lon && lat >= *s && lat <= *n
            }
            ShotArea::Polygons { polygons, .. } => {
                let lon = wrap_lon(lon);
                let point = Point::new(lon, lat);
                self.boxes.locate_all_at_point(&[lon, lat]).any(|b| polygons.0[b.data].intersects(&point))
            }
        }
    }
}

/// A longitude in −180…180° (GEDI's are; a granule in 0…360° is brought back).
fn wrap_lon(lon: f64) -> f64 {
    if lon > 180.0 {
        lon - 360.0
    } else {
        lon
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use geo::{polygon, MultiPolygon, Polygon};

    #[test]
    fn tiles_keep_what_lies_within_the_margin() {
        let a = ShotArea::Tiles { extents: vec![[0.0, 0.0, 100.0, 100.0], [500.0, 0.0, 600.0, 100.0]], margin_m: 10.0 };
        assert!(a.contains(0.0, 0.0, Some((-9.9, 50.0))));
        assert!(!a.contains(0.0, 0.0, Some((-10.1, 50.0))));
        assert!(a.contains(0.0, 0.0, Some((605.0, 105.0))));
        assert!(!a.contains(0.0, 0.0, Some((300.0, 50.0))));
        assert!(!a.contains(0.0, 0.0, None), "a shot without a position is never inside");
    }

    #[test]
    fn a_box_across_the_antimeridian() {
        let a = ShotArea::lon_lat_box("170,-10,-170,10").unwrap();
        assert!(a.contains(175.0, 0.0, None));
        assert!(a.contains(-175.0, 0.0, None));
        assert!(a.contains(185.0, 0.0, None), "0…360° longitudes are wrapped");
        assert!(!a.contains(0.0, 0.0, None));
        assert!(!a.contains(175.0, 11.0, None));
    }

    #[test]
    fn bad_boxes_are_refused_with_the_reason() {
        assert!(ShotArea::lon_lat_box("1,2,3").unwrap_err().contains("3 values"));
        assert!(ShotArea::lon_lat_box("1,x,3,4").unwrap_err().contains("`x`"));
        assert!(ShotArea::lon_lat_box("1,5,3,4").unwrap_err().contains("south"));
        assert!(ShotArea::lon_lat_box("1,2,200,4").unwrap_err().contains("east"));
    }

    #[test]
    fn polygons_keep_their_inside_and_boundary() {
        let p = polygon![(x: 0.0, y: 0.0), (x: 2.0, y: 0.0), (x: 2.0, y: 2.0), (x: 0.0, y: 0.0)];
        let a = ShotArea::Polygons { source: "t".into(), polygons: MultiPolygon(vec![p]) };
        assert!(a.contains(1.5, 0.5, None));
        assert!(a.contains(1.0, 1.0, None), "on the boundary");
        assert!(!a.contains(0.5, 1.5, None));
    }

    #[test]
    fn the_index_keeps_what_a_test_of_every_rectangle_and_polygon_keeps() {
        use rand_chacha::rand_core::{RngCore, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut u = |scale: f64| (rng.next_u32() as f64 / u32::MAX as f64) * scale;
        // 2,000 tiles of 1 km on a 100 km square, some touching, and 300 triangles.
        let extents: Vec<[f64; 4]> = (0..2000)
            .map(|_| {
                let (x, y) = ((u(100.0).floor()) * 1000.0, (u(100.0).floor()) * 1000.0);
                [x, y, x + 1000.0, y + 1000.0]
            })
            .collect();
        let tiles = ShotArea::Tiles { extents: extents.clone(), margin_m: 28.4 };
        let triangles: Vec<Polygon<f64>> = (0..300)
            .map(|_| {
                let (x, y) = (u(10.0), u(10.0));
                polygon![(x: x, y: y), (x: x + u(0.5), y: y), (x: x, y: y + u(0.5)), (x: x, y: y)]
            })
            .collect();
        let plots = ShotArea::Polygons { source: "t".into(), polygons: MultiPolygon(triangles.clone()) };
        let (tiles_index, plots_index) = (tiles.index(), plots.index());
        let (mut in_tiles, mut in_plots) = (0, 0);
        for _ in 0..20_000 {
            let (x, y) = (u(101_000.0) - 500.0, u(101_000.0) - 500.0);
            // Some points exactly on an edge grown by the margin.
            let x = if u(1.0) < 0.05 { (x / 1000.0).floor() * 1000.0 - 28.4 } else { x };
            let all =
                extents.iter().any(|e| x >= e[0] - 28.4 && x <= e[2] + 28.4 && y >= e[1] - 28.4 && y <= e[3] + 28.4);
            assert_eq!(tiles_index.contains(0.0, 0.0, Some((x, y))), all, "({x}, {y})");
            in_tiles += all as usize;
            let (lon, lat) = (u(10.5), u(10.5));
            let all = triangles.iter().any(|t| t.intersects(&Point::new(lon, lat)));
            assert_eq!(plots_index.contains(lon, lat, None), all, "({lon}, {lat})");
            in_plots += all as usize;
        }
        // Both answers occur often enough for the comparison to mean something.
        assert!((2000..18_000).contains(&in_tiles) && (100..19_000).contains(&in_plots), "{in_tiles} {in_plots}");
    }

    #[test]
    fn keys_change_with_the_area() {
        let t = |m| ShotArea::Tiles { extents: vec![[0.0, 0.0, 1.0, 1.0]], margin_m: m };
        assert_eq!(t(1.0).key(), t(1.0).key());
        assert_ne!(t(1.0).key(), t(2.0).key());
        assert_eq!(ShotArea::All.key(), "all");
    }
}
