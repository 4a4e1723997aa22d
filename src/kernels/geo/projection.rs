//! Geographic (WGS84 longitude/latitude, degrees) to projected coordinates and back, in pure Rust
//! (proj4rs), for any projected CRS of the EPSG database (its PROJ strings from the
//! `crs-definitions` crate).

use proj4rs::adaptors::transform_xy;
use proj4rs::Proj;

use crate::error::{Error, Result};

/// WGS84 geographic coordinates, the CRS of every GEDI latitude/longitude.
const WGS84: &str = "+proj=longlat +ellps=WGS84 +datum=WGS84 +no_defs";

/// The PROJ string of EPSG code `epsg` when it is a projected CRS, else why not.
pub fn proj_string(epsg: u32) -> std::result::Result<&'static str, String> {
    let def = u16::try_from(epsg).ok().and_then(crs_definitions::from_code);
    match def.map(|d| d.proj4) {
        None => Err(format!("EPSG:{epsg} is not in the EPSG database")),
        Some("") => Err(format!("EPSG:{epsg} has no PROJ definition in the EPSG database")),
        Some(p) if p.contains("+proj=longlat") || p.contains("+proj=geocent") => {
            Err(format!("EPSG:{epsg} is not a projected CRS"))
        }
        Some(p) => Ok(p),
    }
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
        let def = proj_string(epsg).map_err(Error::Usage)?;
        let dst = Proj::from_proj_string(def).map_err(|e| Error::Usage(format!("EPSG:{epsg}: {e}")))?;
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
    fn any_projected_epsg_code_of_the_database() {
        // NTF (Paris) / Lambert zone II étendu, Gauss-Boaga, NZTM: none was in gedisim's earlier list.
        for (epsg, lon, lat) in [(27572, 2.3, 46.8), (3003, 12.5, 42.0), (2193, 174.8, -41.3)] {
            let p = Projector::new(epsg).unwrap();
            let (x, y) = p.project(lon, lat).unwrap();
            let (lo, la) = p.unproject(x, y).unwrap();
            assert!((lo - lon).abs() < 1e-7 && (la - lat).abs() < 1e-7, "EPSG:{epsg}: {lo} {la}");
        }
        // Lambert II étendu: Paris (Panthéon, 2.3458°E 48.8463°N) at ≈ (600 km, 2 428 km).
        let (x, y) = Projector::new(27572).unwrap().project(2.3458, 48.8463).unwrap();
        assert!((x - 600_000.0).abs() < 2_000.0 && (y - 2_428_000.0).abs() < 2_000.0, "{x} {y}");
    }

    #[test]
    fn unsupported_and_nan_are_errors() {
        assert!(Projector::new(1234).unwrap_err().to_string().contains("not in the EPSG database"));
        assert!(Projector::new(4326).unwrap_err().to_string().contains("not a projected CRS"));
        let p = Projector::new(2154).unwrap();
        assert!(p.project(f64::NAN, 46.0).is_err());
        assert!(p.project(3.0, 95.0).is_err());
    }
}
