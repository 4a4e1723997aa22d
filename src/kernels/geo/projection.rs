//! Geographic (WGS84 longitude/latitude, degrees) to projected coordinates, in pure Rust (proj4rs).
//!
//! proj4rs has no EPSG database unless its `crs-definitions` feature pulls one in, so the
//! projected systems gedisim needs are defined here by their PROJ strings (as published by
//! EPSG/IGN). Adding a system is one arm in [`proj_string`].

use proj4rs::adaptors::transform_xy;
use proj4rs::Proj;

use crate::error::{Error, Result};

/// WGS84 geographic coordinates, the CRS of every GEDI latitude/longitude.
const WGS84: &str = "+proj=longlat +ellps=WGS84 +datum=WGS84 +no_defs";

/// The PROJ string of a supported EPSG code, or `None`.
///
/// Supported: 2154 (RGF93 / Lambert-93), 3942–3950 (RGF93 / CC42–CC50), 3035 (ETRS89 / LAEA
/// Europe), 3857 (Web Mercator), 25828–25838 (ETRS89 / UTM 28N–38N), 32601–32660 and
/// 32701–32760 (WGS84 / UTM north and south). RGF93 and ETRS89 are taken as equal to WGS84
/// (`towgs84=0`), as PROJ does without a grid: the difference is well below a GEDI footprint.
pub fn proj_string(epsg: u32) -> Option<String> {
    const GRS80: &str = "+ellps=GRS80 +towgs84=0,0,0,0,0,0,0 +units=m +no_defs";
    let s = match epsg {
        2154 => format!("+proj=lcc +lat_0=46.5 +lon_0=3 +lat_1=49 +lat_2=44 +x_0=700000 +y_0=6600000 {GRS80}"),
        3942..=3950 => {
            // Conic conformal zones CC42..CC50: latitude of origin = zone, standard parallels ±0.75°.
            let zone = (epsg - 3900) as f64;
            let y0 = 1_200_000.0 + (zone - 42.0) * 1_000_000.0;
            format!(
                "+proj=lcc +lat_0={zone} +lon_0=3 +lat_1={} +lat_2={} +x_0=1700000 +y_0={y0} {GRS80}",
                zone - 0.75,
                zone + 0.75
            )
        }
        3035 => format!("+proj=laea +lat_0=52 +lon_0=10 +x_0=4321000 +y_0=3210000 {GRS80}"),
        3857 => {
            "+proj=merc +a=6378137 +b=6378137 +lat_ts=0 +lon_0=0 +x_0=0 +y_0=0 +k=1 +units=m +nadgrids=@null +no_defs"
                .to_string()
        }
        25828..=25838 => format!("+proj=utm +zone={} {GRS80}", epsg - 25800),
        32601..=32660 => format!("+proj=utm +zone={} +datum=WGS84 +units=m +no_defs", epsg - 32600),
        32701..=32760 => format!("+proj=utm +zone={} +south +datum=WGS84 +units=m +no_defs", epsg - 32700),
        _ => return None,
    };
    Some(s)
}

/// Projects WGS84 longitude/latitude (degrees) into one projected CRS.
pub struct Projector {
    epsg: u32,
    src: Proj,
    dst: Proj,
}

impl std::fmt::Debug for Projector {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Projector").field("epsg", &self.epsg).finish()
    }
}

impl Projector {
    /// A projector from WGS84 degrees to `EPSG:epsg`; an unsupported code is a usage error.
    pub fn new(epsg: u32) -> Result<Self> {
        let def = proj_string(epsg).ok_or_else(|| {
            Error::Usage(format!(
                "EPSG:{epsg} is not a supported projected CRS (supported: 2154, 3942-3950, 3035, 3857, 25828-25838, \
                    32601-32660, 32701-32760)"
            ))
        })?;
        let dst = Proj::from_proj_string(&def).map_err(|e| Error::Usage(format!("EPSG:{epsg}: {e}")))?;
        let src = Proj::from_proj_string(WGS84).map_err(|e| Error::Usage(format!("WGS84: {e}")))?;
        Ok(Projector { epsg, src, dst })
    }

    /// The target EPSG code.
    pub fn epsg(&self) -> u32 {
        self.epsg
    }

    /// Project one point given in degrees; the error text says what failed (the caller adds the field).
    pub fn project(&self, lon_deg: f64, lat_deg: f64) -> std::result::Result<(f64, f64), String> {
        if !lon_deg.is_finite() || !lat_deg.is_finite() {
            return Err(format!("non-finite coordinate (lon {lon_deg}, lat {lat_deg})"));
        }
        if !(-90.0..=90.0).contains(&lat_deg) || !(-540.0..=540.0).contains(&lon_deg) {
            return Err(format!("coordinate out of range (lon {lon_deg}, lat {lat_deg})"));
        }
        // proj4rs works in radians for geographic systems.
        let (x, y) = transform_xy(&self.src, &self.dst, lon_deg.to_radians(), lat_deg.to_radians())
            .map_err(|e| format!("cannot project (lon {lon_deg}, lat {lat_deg}) to EPSG:{}: {e}", self.epsg))?;
        if x.is_finite() && y.is_finite() {
            Ok((x, y))
        } else {
            Err(format!("(lon {lon_deg}, lat {lat_deg}) has no finite EPSG:{} coordinate", self.epsg))
        }
    }
    /// Inverse of [`Projector::project`]: projected (x, y) to WGS84 (longitude, latitude) in degrees.
    pub fn unproject(&self, x: f64, y: f64) -> std::result::Result<(f64, f64), String> {
        if !x.is_finite() || !y.is_finite() {
            return Err(format!("non-finite coordinate (x {x}, y {y})"));
        }
        let (lon, lat) = transform_xy(&self.dst, &self.src, x, y)
            .map_err(|e| format!("cannot unproject (x {x}, y {y}) from EPSG:{}: {e}", self.epsg))?;
        let (lon, lat) = (lon.to_degrees(), lat.to_degrees());
        if lon.is_finite() && lat.is_finite() {
            Ok((lon, lat))
        } else {
            Err(format!("(x {x}, y {y}) has no finite WGS84 coordinate"))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unproject_inverts_project() {
        let p = Projector::new(2154).unwrap();
        let (lon, lat) = p.unproject(368528.1, 6807456.8).unwrap();
        let (x, y) = p.project(lon, lat).unwrap();
        // The inverse Lambert projection iterates on latitude: the round trip is within 10 µm.
        assert!((x - 368528.1).abs() < 1e-5 && (y - 6807456.8).abs() < 1e-5, "{x} {y}");
        assert!((lon + 1.47).abs() < 0.01 && (lat - 48.28).abs() < 0.01, "{lon} {lat}");
    }

    #[test]
    fn lambert93_origin_is_exact() {
        let p = Projector::new(2154).unwrap();
        let (x, y) = p.project(3.0, 46.5).unwrap();
        assert!((x - 700_000.0).abs() < 1e-6 && (y - 6_600_000.0).abs() < 1e-6, "{x} {y}");
    }

    #[test]
    fn laea_europe_origin_is_exact() {
        let p = Projector::new(3035).unwrap();
        let (x, y) = p.project(10.0, 52.0).unwrap();
        assert!((x - 4_321_000.0).abs() < 1e-6 && (y - 3_210_000.0).abs() < 1e-6, "{x} {y}");
    }

    #[test]
    fn cc_zone_origin() {
        // CC46 (EPSG:3946): origin (3°E, 46°N) -> (1 700 000, 5 200 000).
        let (x, y) = Projector::new(3946).unwrap().project(3.0, 46.0).unwrap();
        assert!((x - 1_700_000.0).abs() < 1e-6 && (y - 5_200_000.0).abs() < 1e-6, "{x} {y}");
    }

    #[test]
    fn utm_central_meridian_false_easting() {
        let (x, _) = Projector::new(32631).unwrap().project(3.0, 45.0).unwrap();
        assert!((x - 500_000.0).abs() < 1e-6);
    }

    #[test]
    fn unproject_round_trip_and_nan() {
        let p = Projector::new(2154).unwrap();
        let (x, y) = p.project(4.4991, 45.23664).unwrap();
        let (lon, lat) = p.unproject(x, y).unwrap();
        assert!((lon - 4.4991).abs() < 1e-9 && (lat - 45.23664).abs() < 1e-9, "{lon} {lat}");
        assert!(p.unproject(f64::NAN, 0.0).is_err());
    }

    #[test]
    fn unsupported_and_nan_are_errors() {
        assert!(Projector::new(1234).is_err());
        let p = Projector::new(2154).unwrap();
        assert!(p.project(f64::NAN, 46.0).is_err());
        assert!(p.project(3.0, 95.0).is_err());
    }
}
