//! Footprint lists: a CSV with an identifier and a position, as x, y (projected) or lon, lat
//! (WGS84 degrees) columns, found by their usual names (`io::csv_table`). Where the positions
//! are put in the tiles' CRS is `ops::simulate::place_footprints`.

use std::path::Path;

use crate::error::{Error, Result};
use crate::io::csv_table::CsvTable;

/// Names the identifier column may have.
pub const ID_COLUMNS: [&str; 7] = ["id", "footprint_id", "plot_id", "plot", "shot_number", "name", "site"];
const X_COLUMNS: [&str; 2] = ["x", "easting"];
const Y_COLUMNS: [&str; 2] = ["y", "northing"];
const LON_COLUMNS: [&str; 4] = ["lon", "longitude", "long", "lng"];
const LAT_COLUMNS: [&str; 2] = ["lat", "latitude"];

/// How a footprint CSV gives its positions.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Coordinates {
    /// `x`, `y` in a projected CRS (metres).
    Projected,
    /// `lon`, `lat` in WGS84 degrees (EPSG:4326).
    LonLat,
}

/// The footprints of a CSV as given: (id, x or lon, y or lat).
#[derive(Debug, Clone, PartialEq)]
pub struct FootprintTable {
    pub rows: Vec<(String, f64, f64)>,
    pub coordinates: Coordinates,
}

/// Read a footprint CSV: an id column and either x, y or lon, lat (any order, other columns
/// ignored); ids must be unique.
pub fn read_footprints_csv(path: &Path) -> Result<FootprintTable> {
    let t = CsvTable::read(path, "id,x,y")?;
    let id = t.require(&ID_COLUMNS)?;
    let (coordinates, a, b, names) = match (t.column(&X_COLUMNS), t.column(&Y_COLUMNS)) {
        (Some(x), Some(y)) => (Coordinates::Projected, x, y, ["x", "y"]),
        _ => match (t.column(&LON_COLUMNS), t.column(&LAT_COLUMNS)) {
            (Some(lon), Some(lat)) => (Coordinates::LonLat, lon, lat, ["lon", "lat"]),
            _ => {
                return Err(Error::field(
                    path,
                    "x",
                    format!("no `x`, `y` (or easting, northing; lon, lat) columns in the header `{}`", t.header()),
                ));
            }
        },
    };
    let mut rows = Vec::with_capacity(t.rows().len());
    let mut seen = std::collections::HashSet::new();
    for row in t.rows() {
        let name = t.field(row, id, "id")?.to_string();
        if !seen.insert(name.clone()) {
            return Err(Error::field(path, "id", format!("line {}: duplicate id `{name}`", row.0)));
        }
        let (u, v) = (t.number(row, a, names[0])?, t.number(row, b, names[1])?);
        if coordinates == Coordinates::LonLat && !((-180.0..=180.0).contains(&u) && (-90.0..=90.0).contains(&v)) {
            return Err(Error::field(path, "lon", format!("line {}: ({u}, {v}) is not a longitude, latitude", row.0)));
        }
        rows.push((name, u, v));
    }
    Ok(FootprintTable { rows, coordinates })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_any_column_order_and_rejects_bad_values() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("fp.csv");
        std::fs::write(&f, "x,id,y,extra\n1.5,a,2.5,z\n3,b,4,z\n").unwrap();
        let t = read_footprints_csv(&f).unwrap();
        assert_eq!(t.rows[1], ("b".into(), 3.0, 4.0));
        assert_eq!(t.coordinates, Coordinates::Projected);
        std::fs::write(&f, "id,x,y\na,1,nan\n").unwrap();
        let e = read_footprints_csv(&f).unwrap_err().to_string();
        assert!(e.contains("fp.csv") && e.contains("y"), "{e}");
        std::fs::write(&f, "id,x\na,1\n").unwrap();
        assert!(read_footprints_csv(&f).unwrap_err().to_string().contains("no `x`, `y`"));
        std::fs::write(&f, "id,x,y\na,1,2\na,3,4\n").unwrap();
        assert!(read_footprints_csv(&f).unwrap_err().to_string().contains("line 3: duplicate id `a`"));
    }

    #[test]
    fn plots_in_lon_lat_with_a_semicolon_and_a_bom() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("plots.csv");
        std::fs::write(&f, "\u{feff}plot_id;Latitude;Longitude\nP1;45.5;5.25\n\"P 2\";46;6\n").unwrap();
        let t = read_footprints_csv(&f).unwrap();
        assert_eq!(t.coordinates, Coordinates::LonLat);
        assert_eq!(t.rows, vec![("P1".into(), 5.25, 45.5), ("P 2".into(), 6.0, 46.0)]);
        std::fs::write(&f, "plot_id;lat;lon\nP1;145;5\n").unwrap();
        assert!(read_footprints_csv(&f).unwrap_err().to_string().contains("not a longitude, latitude"));
    }
}
