"""Writes the GeoPackages of the `--within` tests with GDAL (through geopandas and pyogrio), the library
users' GIS tools write them with: `python3 make.py` here (geopandas 1.2.0, pyogrio 0.13.0, GDAL 3.12.4 made
the committed files). src/io/within.rs reads them; gedisim did not write them."""

import geopandas as gpd
from shapely.geometry import LineString, MultiPolygon, Polygon


def square(x0, y0, side):
    return Polygon([(x0, y0), (x0 + side, y0), (x0 + side, y0 + side), (x0, y0 + side)])


def write(frame, name, layer):
    frame.to_file(name, layer=layer, driver="GPKG", engine="pyogrio", SPATIAL_INDEX="NO")


# Two feature tables in one file: forest stands in Lambert-93 (EPSG:2154) and a zone in WGS84 degrees.
stands = gpd.GeoDataFrame(
    {"stand": ["a", "b"]},
    geometry=[square(650000, 6860000, 1000),
              MultiPolygon([square(660000, 6870000, 500), square(661000, 6870000, 500)])],
    crs="EPSG:2154",
)
write(stands, "areas.gpkg", "stands")
zone = gpd.GeoDataFrame({"zone": ["z"]}, geometry=[square(5.0, 45.0, 0.1)], crs="EPSG:4326")
write(zone, "areas.gpkg", "zone")
# A track, not an area; and an area whose CRS is not said.
write(gpd.GeoDataFrame({"id": [1]}, geometry=[LineString([(2, 48), (3, 49)])], crs="EPSG:4326"), "line.gpkg", "track")
write(gpd.GeoDataFrame({"id": [1]}, geometry=[square(0, 0, 10)]), "no_crs.gpkg", "area")
