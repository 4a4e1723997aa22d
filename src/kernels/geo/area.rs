//! Which shots of a granule an ingest keeps (docs/gedi-products.md, "Shots kept"): the dataset's ALS
//! coverage by default, a box or polygons when the user names one, or every shot.

use geo::{Intersects, MultiPolygon, Point};
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

    /// Whether a shot at `lon`, `lat` (degrees), projected to `xy`, is kept.
    pub fn contains(&self, lon: f64, lat: f64, xy: Option<(f64, f64)>) -> bool {
        match self {
            ShotArea::All => true,
            ShotArea::Tiles { extents, margin_m } => xy.is_some_and(|(x, y)| {
                extents.iter().any(|e| {
                    x >= e[0] - margin_m && x <= e[2] + margin_m && y >= e[1] - margin_m && y <= e[3] + margin_m
                })
            }),
            ShotArea::LonLatBox([w, s, e, n]) => {
                let lon = wrap_lon(lon);
                let in_lon = if w <= e { lon >= *w && lon <= *e } else { lon >= *w || lon <= *e };
                in_lon && lat >= *s && lat <= *n
            }
            // A point on the boundary is inside.
            ShotArea::Polygons { polygons, .. } => polygons.intersects(&Point::new(wrap_lon(lon), lat)),
        }
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
    use geo::{polygon, MultiPolygon};

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
    fn keys_change_with_the_area() {
        let t = |m| ShotArea::Tiles { extents: vec![[0.0, 0.0, 1.0, 1.0]], margin_m: m };
        assert_eq!(t(1.0).key(), t(1.0).key());
        assert_ne!(t(1.0).key(), t(2.0).key());
        assert_eq!(ShotArea::All.key(), "all");
    }
}
