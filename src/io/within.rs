//! `--within <file>`: the polygons whose shots an ingest keeps (docs/gedi-products.md, "Shots kept"),
//! read from GeoJSON (RFC 7946: WGS84 longitude, latitude) or from a GeoPackage (OGC 12-128r18: every
//! feature table, each in its own CRS, taken back to WGS84 degrees).

use std::path::Path;

use geo::{CoordsIter, MultiPolygon, Polygon};
use geojson::GeoJson;
use geozero::ToGeo;

use crate::error::{Error, Result};
use crate::kernels::geo::area::ShotArea;
use crate::kernels::geo::projection::Projector;

/// The polygons of `path`: a GeoPackage (`.gpkg`) or a GeoJSON file (any other name). Other
/// geometries are refused, as is a file without any polygon or whose coordinates are not degrees.
pub fn read_within(path: &Path) -> Result<ShotArea> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    let polygons = if ext == "gpkg" { geopackage_polygons(path)? } else { geojson_polygons(path)? };
    if polygons.is_empty() {
        return Err(Error::file(path, "no polygon: --within takes polygons"));
    }
    if let Some(c) = polygons.iter().flat_map(|p| p.coords_iter()).find(|c| c.x.abs() > 360.0 || c.y.abs() > 90.0) {
        return Err(Error::file(
            path,
            format!(
                "coordinate ({}, {}) is not longitude, latitude in degrees: give the polygons in WGS84 (RFC 7946)",
                c.x, c.y
            ),
        ));
    }
    let source = path.display().to_string();
    Ok(ShotArea::Polygons { source, polygons: MultiPolygon(polygons) })
}

/// A geometry's polygons appended to `polygons`; any other geometry is refused (`what` names it).
fn add_polygons(polygons: &mut Vec<Polygon<f64>>, g: geo::Geometry<f64>, path: &Path, what: &str) -> Result<()> {
    match g {
        geo::Geometry::Polygon(p) => polygons.push(p),
        geo::Geometry::MultiPolygon(m) => polygons.extend(m.0),
        other => {
            let kind = match other {
                geo::Geometry::Point(_) | geo::Geometry::MultiPoint(_) => "a point",
                geo::Geometry::LineString(_) | geo::Geometry::MultiLineString(_) => "a line",
                _ => "a geometry other than a polygon",
            };
            return Err(Error::field(path, what, format!("{kind}: --within takes polygons")));
        }
    }
    Ok(())
}

/// The polygons and multipolygons of a GeoJSON file (a geometry, a feature or a feature collection).
fn geojson_polygons(path: &Path) -> Result<Vec<Polygon<f64>>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::file(path, e))?;
    let json: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| Error::file(path, format!("not JSON: {e}")))?;
    // RFC 7946 has no `crs` member; an old-style one naming anything but WGS84 degrees is refused.
    if let Some(name) = json.pointer("/crs/properties/name").and_then(|v| v.as_str()) {
        let wgs84 = ["CRS84", "EPSG::4326", "EPSG:4326"].iter().any(|c| name.ends_with(c));
        if !wgs84 {
            return Err(Error::field(
                path,
                "crs",
                format!("{name}: give the polygons in WGS84 longitude, latitude (RFC 7946)"),
            ));
        }
    }
    let geojson: GeoJson = serde_json::from_value(json).map_err(|e| Error::file(path, format!("not GeoJSON: {e}")))?;
    let mut polygons: Vec<Polygon<f64>> = Vec::new();
    let mut add = |g: &geojson::Geometry| -> Result<()> {
        let g = geo::Geometry::<f64>::try_from(g.clone())
            .map_err(|e| Error::file(path, format!("not a valid geometry: {e}")))?;
        add_polygons(&mut polygons, g, path, "geometry")
    };
    match &geojson {
        GeoJson::Geometry(g) => add(g)?,
        GeoJson::Feature(f) => f.geometry.iter().try_for_each(&mut add)?,
        GeoJson::FeatureCollection(c) => c.features.iter().flat_map(|f| f.geometry.iter()).try_for_each(&mut add)?,
    }
    Ok(polygons)
}

/// A feature table of a GeoPackage: its geometry column and the CRS it declares.
struct Layer {
    table: String,
    column: String,
    srs_id: i64,
    srs_name: String,
    organization: String,
    code: i64,
}

/// The polygons of every feature table of a GeoPackage (read-only), each taken from the CRS its
/// `gpkg_geometry_columns` row declares (an EPSG code, `gpkg_spatial_ref_sys`) to WGS84 degrees.
/// An undefined CRS (srs_id 0 or −1) or another organisation than EPSG is refused; null geometries are
/// skipped.
fn geopackage_polygons(path: &Path) -> Result<Vec<Polygon<f64>>> {
    use rusqlite::{Connection, OpenFlags};
    let sql = |e: rusqlite::Error| Error::file(path, format!("not a readable GeoPackage: {e}"));
    let db = Connection::open_with_flags(path, OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX)
        .map_err(sql)?;
    let mut statement = db
        .prepare(
            "SELECT g.table_name, g.column_name, g.srs_id, s.srs_name, s.organization, s.organization_coordsys_id \
             FROM gpkg_geometry_columns g JOIN gpkg_spatial_ref_sys s ON s.srs_id = g.srs_id ORDER BY g.table_name",
        )
        .map_err(sql)?;
    let layers = statement
        .query_map([], |r| {
            let (table, column, srs_id, srs_name) = (r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?);
            Ok(Layer { table, column, srs_id, srs_name, organization: r.get(4)?, code: r.get(5)? })
        })
        .map_err(sql)?
        .collect::<std::result::Result<Vec<_>, _>>()
        .map_err(sql)?;
    if layers.is_empty() {
        return Err(Error::file(path, "a GeoPackage without a feature table (gpkg_geometry_columns is empty)"));
    }
    let mut polygons = Vec::new();
    for layer in &layers {
        let what = format!("{}.{}", layer.table, layer.column);
        let epsg = match (layer.organization.to_ascii_uppercase().as_str(), layer.code) {
            _ if layer.srs_id == 0 || layer.srs_id == -1 => {
                let why = format!("undefined CRS (srs_id {}): give the polygons a CRS", layer.srs_id);
                return Err(Error::field(path, what, why));
            }
            ("EPSG", code) if (1..=i64::from(u32::MAX)).contains(&code) => code as u32,
            (org, code) => {
                let why = format!("CRS `{}` ({org}:{code}): give the polygons an EPSG CRS", layer.srs_name);
                return Err(Error::field(path, what, why));
            }
        };
        let projector =
            if epsg == 4326 { None } else { Some(Projector::new(epsg).map_err(|e| Error::field(path, &what, e))?) };
        let quote = |name: &str| format!("\"{}\"", name.replace('"', "\"\""));
        let query = format!("SELECT {} FROM {}", quote(&layer.column), quote(&layer.table));
        let mut rows = db.prepare(&query).map_err(sql)?;
        let blobs = rows.query_map([], |r| r.get::<_, Option<Vec<u8>>>(0)).map_err(sql)?;
        for blob in blobs {
            let Some(blob) = blob.map_err(sql)? else { continue };
            let g = geozero::wkb::GpkgWkb(blob)
                .to_geo()
                .map_err(|e| Error::field(path, &what, format!("not a GeoPackage geometry: {e}")))?;
            let g = match &projector {
                None => g,
                Some(p) => {
                    use geo::MapCoords;
                    g.try_map_coords(|c| p.unproject(c.x, c.y).map(|(x, y)| geo::coord! { x: x, y: y }))
                        .map_err(|e| Error::field(path, &what, e))?
                }
            };
            add_polygons(&mut polygons, g, path, &what)?;
        }
    }
    Ok(polygons)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(name: &str, text: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("gedisim-within-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    #[test]
    fn a_feature_collection_of_polygons() {
        let p = write(
            "fc.geojson",
            r#"{"type":"FeatureCollection","features":[
              {"type":"Feature","properties":{},
               "geometry":{"type":"Polygon","coordinates":[[[0,0],[1,0],[1,1],[0,1],[0,0]]]}},
              {"type":"Feature","properties":{},
               "geometry":{"type":"MultiPolygon","coordinates":[[[[5,5],[6,5],[6,6],[5,5]]]]}}]}"#,
        );
        let a = read_within(&p).unwrap();
        assert!(a.contains(0.5, 0.5, None));
        assert!(a.contains(5.9, 5.1, None));
        assert!(!a.contains(3.0, 3.0, None));
    }

    #[test]
    fn what_is_not_a_polygon_in_degrees_is_refused() {
        let point = write("pt.geojson", r#"{"type":"Point","coordinates":[1,2]}"#);
        assert!(read_within(&point).unwrap_err().to_string().contains("a point"));
        let projected = write(
            "l93.geojson",
            r#"{"type":"Polygon",
                "coordinates":[[[650000,6860000],[651000,6860000],[651000,6861000],[650000,6860000]]]}"#,
        );
        assert!(read_within(&projected).unwrap_err().to_string().contains("not longitude, latitude"));
        let crs = write(
            "crs.geojson",
            r#"{"type":"Polygon","crs":{"type":"name","properties":{"name":"urn:ogc:def:crs:EPSG::2154"}},
                "coordinates":[[[0,0],[1,0],[1,1],[0,0]]]}"#,
        );
        assert!(read_within(&crs).unwrap_err().to_string().contains("EPSG::2154"));
        let gpkg = write("a.gpkg", "");
        assert!(read_within(&gpkg).unwrap_err().to_string().contains("GeoPackage"));
    }

    /// GeoPackages written by GDAL (tests/data/within/make.py).
    fn gdal(name: &str) -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/within").join(name)
    }

    #[test]
    fn a_geopackage_s_feature_tables_each_from_its_crs() {
        let a = read_within(&gdal("areas.gpkg")).unwrap();
        let l93 = Projector::new(2154).unwrap();
        let at = |x: f64, y: f64| {
            let (lon, lat) = l93.unproject(x, y).unwrap();
            a.contains(lon, lat, None)
        };
        // `stands` (EPSG:2154): a 1 km square and a multipolygon of two 500 m squares 500 m apart.
        assert!(at(650_500.0, 6_860_500.0) && at(650_010.0, 6_860_990.0));
        assert!(!at(651_100.0, 6_860_500.0) && !at(649_900.0, 6_860_500.0));
        assert!(at(660_250.0, 6_870_250.0) && at(661_250.0, 6_870_250.0) && !at(660_750.0, 6_870_250.0));
        // `zone` (EPSG:4326).
        assert!(a.contains(5.05, 45.05, None) && !a.contains(5.15, 45.05, None));
    }

    #[test]
    fn a_geopackage_of_lines_or_without_a_crs_is_refused() {
        let said = read_within(&gdal("line.gpkg")).unwrap_err().to_string();
        assert!(said.contains("track.geom") && said.contains("a line"), "{said}");
        let said = read_within(&gdal("no_crs.gpkg")).unwrap_err().to_string();
        assert!(said.contains("area.geom") && said.contains("Undefined") && said.contains("EPSG CRS"), "{said}");
        let not_sqlite = write("b.gpkg", "not a database");
        assert!(read_within(&not_sqlite).unwrap_err().to_string().contains("not a readable GeoPackage"));
    }
}
