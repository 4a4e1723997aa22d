"""Hand-off check: every table of a dataset opens in pyarrow and duckdb with the same row count;
GeoParquet files given after --geoparquet open in pyarrow (valid `geo` metadata), duckdb and
geopandas (points in OGC:CRS84, same row count)."""
import json
import pathlib
import sys

import duckdb
import pyarrow.parquet as pq

args = sys.argv[1:]
geo_files = []
if "--geoparquet" in args:
    k = args.index("--geoparquet")
    geo_files = [pathlib.Path(p) for p in args[k + 1:]]
    args = args[:k]
root = pathlib.Path(args[0])
tables = sorted(d for d in root.iterdir() if d.is_dir() and any(d.glob("*.parquet")) and d.name != "report")
assert tables, f"no table in {root}"
for table in tables:
    first = sorted(table.glob("*.parquet"))[0]
    t = pq.read_table(first)
    n = duckdb.sql(f"select count(*) from read_parquet('{first}')").fetchall()[0][0]
    assert n == t.num_rows, (table.name, n, t.num_rows)
    print(f"{table.name}: {first.name}: {t.num_rows} rows, {len(t.schema)} columns: pyarrow and duckdb agree")

if geo_files:
    import geopandas

for path in geo_files:
    meta = pq.read_metadata(path).metadata
    assert b"geo" in meta, f"{path}: no `geo` key-value metadata"
    geo = json.loads(meta[b"geo"])
    assert geo["version"].startswith("1.1"), geo["version"]
    col = geo["columns"][geo["primary_column"]]
    assert col["encoding"] == "WKB" and col["geometry_types"] == ["Point"], col
    assert col["covering"]["bbox"]["xmin"] == ["bbox", "xmin"], col
    t = pq.read_table(path)
    assert t.schema.field("bbox").type.num_fields == 4
    n = duckdb.sql(f"select count(*), count(geometry) from read_parquet('{path}')").fetchall()[0]
    assert n[0] == t.num_rows, (path, n, t.num_rows)
    assert t.num_rows > 0, f"{path}: no rows to check"
    g = geopandas.read_parquet(path)
    assert len(g) == t.num_rows, (path, len(g), t.num_rows)
    assert g.crs is not None and g.crs.to_string() in ("OGC:CRS84", "EPSG:4326"), g.crs
    types = set(g.geometry.dropna().geom_type)
    assert types <= {"Point"}, types
    xmin, ymin, xmax, ymax = g.total_bounds
    assert -180 <= xmin <= xmax <= 180 and -90 <= ymin <= ymax <= 90, g.total_bounds
    print(f"{path.name}: {len(g)} rows, {n[1]} points, CRS {g.crs.to_string()}: GeoParquet opens in pyarrow, duckdb and geopandas")
