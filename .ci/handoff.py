"""Hand-off check: every table of a dataset opens in pyarrow and duckdb with the same row count."""
import pathlib
import sys

import duckdb
import pyarrow.parquet as pq

root = pathlib.Path(sys.argv[1])
tables = sorted(d for d in root.iterdir() if d.is_dir() and any(d.glob("*.parquet")))
assert tables, f"no table in {root}"
for table in tables:
    first = sorted(table.glob("*.parquet"))[0]
    t = pq.read_table(first)
    n = duckdb.sql(f"select count(*) from read_parquet('{first}')").fetchall()[0][0]
    assert n == t.num_rows, (table.name, n, t.num_rows)
    print(f"{table.name}: {first.name}: {t.num_rows} rows, {len(t.schema)} columns: pyarrow and duckdb agree")
