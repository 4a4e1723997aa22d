//! `--within <file>`: the polygons whose shots an ingest keeps (docs/gedi-products.md, "Shots kept"),
//! read from GeoJSON (RFC 7946: WGS84 longitude, latitude).

use std::path::Path;

use geo::{MultiPolygon, Polygon};
use geojson::GeoJson;

use crate::error::{Error, Result};
use crate::kernels::geo::area::ShotArea;

/// The polygons and multipolygons of a GeoJSON file (a geometry, a feature or a feature collection);
/// other geometries are refused, as is a file without any polygon or whose coordinates are not degrees.
pub fn read_within(path: &Path) -> Result<ShotArea> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    if ext == "gpkg" {
        return Err(Error::file(
            path,
            "GeoPackage is not read yet: convert it, e.g. `ogr2ogr -f GeoJSON -t_srs EPSG:4326 area.geojson <file>`, \
             and give the GeoJSON",
        ));
    }
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
        match geo::Geometry::<f64>::try_from(g.clone()) {
            Ok(geo::Geometry::Polygon(p)) => polygons.push(p),
            Ok(geo::Geometry::MultiPolygon(m)) => polygons.extend(m.0),
            Ok(other) => {
                let kind = match other {
                    geo::Geometry::Point(_) | geo::Geometry::MultiPoint(_) => "a point",
                    geo::Geometry::LineString(_) | geo::Geometry::MultiLineString(_) => "a line",
                    _ => "a geometry other than a polygon",
                };
                return Err(Error::file(path, format!("{kind}: --within takes polygons")));
            }
            Err(e) => return Err(Error::file(path, format!("not a valid geometry: {e}"))),
        }
        Ok(())
    };
    match &geojson {
        GeoJson::Geometry(g) => add(g)?,
        GeoJson::Feature(f) => f.geometry.iter().try_for_each(&mut add)?,
        GeoJson::FeatureCollection(c) => c.features.iter().flat_map(|f| f.geometry.iter()).try_for_each(&mut add)?,
    }
    if polygons.is_empty() {
        return Err(Error::file(path, "no polygon: --within takes polygons"));
    }
    use geo::CoordsIter;
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
        assert!(read_within(&gpkg).unwrap_err().to_string().contains("ogr2ogr"));
    }
}
