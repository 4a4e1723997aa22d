"""Study check on the output of `gedisim demo` (bundled tiles, generated granules with GEDI's ground
planted 0.5 m too high): read with duckdb and pyarrow, independently of gedisim,
- the two table contracts: `ground_detection` and `msd` columns and types;
- the MSD identity: SB + SDSD + LCS = msd = mean over RH1..RH99 and rows of (rh_aligned - rh_sim)^2,
  recomputed from results/ (to 1e-9);
- the alignment sign: rh_aligned = rh_gedi + (gedi_ground - als_ground) on every row, and the planted
  +0.5 m shows as a positive ground bias (GEDI ground above the ALS ground) for every algorithm.
Usage: study.py <dataset>"""
import pathlib
import sys

import duckdb
import pyarrow.parquet as pq

ds = pathlib.Path(sys.argv[1])
report = ds / "report"
results = f"read_parquet('{ds / 'results'}/*.parquet')"

gd = pq.read_table(report / "ground_detection.parquet")
want = [("algorithm", "string"), ("sensitivity_group", "string"), ("n", "int64"), ("bias", "double"), ("rmse", "double")]
got = [(f.name, str(f.type)) for f in gd.schema]
assert got == want, f"ground_detection columns {got}"
msd = pq.read_table(report / "msd.parquet")
want = [("weighting", "string"), ("algorithm", "string"), ("sensitivity_group", "string"), ("sb", "double"),
        ("sdsd", "double"), ("lcs", "double"), ("msd", "double"), ("n", "int64")]
got = [(f.name, str(f.type)) for f in msd.schema]
assert got == want, f"msd columns {got}"
print(f"contracts: ground_detection ({gd.num_rows} rows) and msd ({msd.num_rows} rows) columns and types as documented")

n = duckdb.sql(f"select count(*) from {results}").fetchall()[0][0]
assert n > 0, "results/ is empty"
worst = duckdb.sql(f"""
    select max(abs(a - (g + (gedi_ground - als_ground)))) from (
      select unnest(rh_aligned) as a, unnest(rh_gedi) as g, gedi_ground, als_ground from {results})""").fetchall()[0][0]
assert worst < 1e-3, f"rh_aligned - rh_gedi differs from gedi_ground - als_ground by {worst} m"
for alg, bias in duckdb.sql(f"""select algorithm, avg(gedi_ground - als_ground) from {results}
                                where weighting = 'count' group by algorithm order by algorithm""").fetchall():
    assert bias > 0, f"{alg}: GEDI - ALS ground {bias:.3f} m, planted +0.5 m"
print(f"alignment: rh_aligned = rh_gedi + (gedi_ground - als_ground) on {n} rows (max error {worst:.1e} m); "
      "GEDI ground above the ALS ground for every algorithm (planted +0.5 m)")

direct = {}
for w, a, g, m, k in duckdb.sql(f"""
    with r as (select weighting, algorithm, sensitivity_group, rh_aligned, rh_sim from {results}),
    p as (select weighting, algorithm, sensitivity_group, k,
                 (cast(rh_aligned[k + 1] as double) - cast(rh_sim[k + 1] as double)) ^ 2 as d2
          from r cross join range(1, 100) t(k))
    select weighting, algorithm, coalesce(sensitivity_group, 'all'), avg(d2), count(*) / 99
    from p group by grouping sets ((weighting, algorithm, sensitivity_group), (weighting, algorithm))""").fetchall():
    direct[(w, a, g)] = (m, k)
checked = 0
for row in msd.to_pylist():
    key = (row["weighting"], row["algorithm"], row["sensitivity_group"])
    m, k = direct[key]
    parts = row["sb"] + row["sdsd"] + row["lcs"]
    assert abs(parts - m) < 1e-9 and abs(row["msd"] - m) < 1e-9, f"{key}: SB+SDSD+LCS {parts}, msd {row['msd']}, direct {m}"
    assert row["n"] == k, (key, row["n"], k)
    checked += 1
assert checked == len(direct), (checked, len(direct))
print(f"MSD identity: SB + SDSD + LCS = msd = mean((rh_aligned - rh_sim)^2) over RH1..RH99 on {checked} rows (1e-9)")
