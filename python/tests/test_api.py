"""The Python API against the command line, on the same inputs (run on the installed wheel; .ci/run).

A small world (`gedisim scenario`: the bundled LiDAR HD tiles and generated GEDI granules) is built once by the
installed command; every API call is then compared with the command it wraps, table by table.
"""

from __future__ import annotations

import doctest
import json
import os
import subprocess
from pathlib import Path

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.dataset as pads
import pyarrow.parquet as pq
import pytest

import gedisim

CLI = gedisim.command()


def cli(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    """The installed `gedisim` command, quiet."""
    return subprocess.run([CLI, *args, "-q"], capture_output=True, text=True, check=check)


def sorted_table(t: pa.Table) -> pa.Table:
    """Rows in a stable order: by every sortable column, as files may list them in any order."""
    # pyarrow's sort cannot take rows of view columns: compare them as plain strings and bytes.
    plain = {pa.string_view(): pa.string(), pa.binary_view(): pa.binary()}
    t = t.cast(pa.schema([f.with_type(plain.get(f.type, f.type)) for f in t.schema])).combine_chunks()
    sortable = (pa.types.is_integer, pa.types.is_floating, pa.types.is_string, pa.types.is_large_string,
                pa.types.is_boolean, pa.types.is_temporal)
    keys = [(f.name, "ascending") for f in t.schema if any(is_(f.type) for is_ in sortable)]
    return t.sort_by(keys) if keys and t.num_rows else t


def read_table(folder: Path) -> pa.Table:
    return pads.dataset(folder, format="parquet").to_table()


@pytest.fixture(scope="session")
def world(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("world")
    cli("scenario", "--effect", "datum", "--seed", "2", "--passes", "2", "--out", str(root))
    return root


@pytest.fixture(scope="session")
def datasets(world, tmp_path_factory) -> tuple[Path, Path]:
    """The same run through the API (first) and the command (second)."""
    root = tmp_path_factory.mktemp("datasets")
    api, cmd = root / "api", root / "cli"
    ran = gedisim.Dataset(api).run(als=world / "als", l1b=world / "gedi", l2a=world / "gedi", progress=False)
    said = cli("run", "--als", str(world / "als"), "--l1b", str(world / "gedi"), "--l2a", str(world / "gedi"),
               "--dataset", str(cmd), "--json")
    # What each run did: the same object, but for the dataset's own paths.
    printed = json.loads(said.stdout.strip().splitlines()[-1])
    for d, root in ((ran, api), (printed, cmd)):
        text = json.dumps(d).replace(str(root), "<dataset>")
        d.clear()
        d.update(json.loads(text))
    assert ran == printed and ran["simulation"]["shots_simulated"] > 0
    return api, cmd


def test_the_command_is_the_installed_binary():
    assert CLI is not None and os.access(CLI, os.X_OK)
    out = subprocess.run([CLI, "--version"], capture_output=True, text=True, check=True).stdout
    assert gedisim.__version__ in out


def test_run_writes_the_tables_of_the_command(datasets):
    api, cmd = datasets
    tables = sorted(p.name for p in cmd.iterdir() if p.is_dir() and any(p.glob("*.parquet")))
    assert {"shots", "sim", "results", "offsets", "tiles"} <= set(tables), tables
    for name in tables:
        a, c = read_table(api / name), read_table(cmd / name)
        # Paths the run was given are the same; the dataset's own path is not a column.
        assert a.schema == c.schema, name
        assert sorted_table(a).equals(sorted_table(c)), name


def test_sql_and_table_equal_the_command(datasets, tmp_path):
    api, _ = datasets
    # Row by row (a float aggregate's sum order follows the engine's partitions, run to run).
    query = ("SELECT shot_number, weighting, algorithm, gedi_ground - als_ground AS ground_bias, rh(rh_sim, 98) "
             "AS rh98_sim FROM results ORDER BY shot_number, weighting, algorithm")
    out = tmp_path / "q.parquet"
    cli("sql", "--dataset", str(api), "--out", str(out), query)
    assert gedisim.Dataset(api).sql(query).equals(pq.read_table(out))
    # A whole table: its files are read in parallel, rows in any order.
    shots = gedisim.Dataset(api).table("shots")
    cli("sql", "--dataset", str(api), "--out", str(tmp_path / "s.parquet"), "SELECT * FROM shots")
    assert sorted_table(shots).equals(sorted_table(pq.read_table(tmp_path / "s.parquet")))
    assert shots.num_rows == read_table(api / "shots").num_rows > 0


def test_simulate_equals_the_command(world, datasets, tmp_path):
    api, _ = datasets
    shots = gedisim.Dataset(api).sql("SELECT footprint_id, x, y FROM sim WHERE weighting = 'int' "
                                     "ORDER BY footprint_id LIMIT 5")
    footprints = {"id": shots.column("footprint_id").to_pylist(),
                  "x": shots.column("x").to_pylist(), "y": shots.column("y").to_pylist()}
    table = gedisim.simulate(world / "als", footprints, progress=False)
    csv = tmp_path / "footprints.csv"
    csv.write_text("id,x,y\n" + "".join(f"{i},{x!r},{y!r}\n" for i, x, y in zip(*footprints.values())))
    out = tmp_path / "cli.parquet"
    cli("simulate", "--als", str(world / "als"), "--footprints", str(csv), "--out", str(out))
    assert table.equals(pq.read_table(out))
    assert table.num_rows == 5 * 3
    only = gedisim.simulate(world / "als", footprints, weighting="int", progress=False)
    assert set(only.column("weighting").to_pylist()) == {"int"} and only.num_rows == 5
    with_rh = gedisim.rh(only, 50, 98)
    assert with_rh.column("rh98").to_pylist() == [r[98] for r in only.column("rh").to_pylist()]


def test_simulate_on_a_points_table_equals_the_command(world, datasets, tmp_path):
    """The dataset's `als/` points as a table (in any order, columns of other types) give the rows of
    `gedisim simulate --als <the tiles>`."""
    ds = gedisim.Dataset(datasets[0])
    shots = ds.sql("SELECT footprint_id AS id, x, y FROM sim WHERE weighting = 'int' ORDER BY id LIMIT 6")
    csv = tmp_path / "footprints.csv"
    csv.write_text("id,x,y\n" + "".join(f"{r['id']},{r['x']!r},{r['y']!r}\n" for r in shots.to_pylist()))
    out = tmp_path / "cli.parquet"
    cli("simulate", "--als", str(world / "als"), "--footprints", str(csv), "--out", str(out))
    expected = pq.read_table(out)
    columns = ["x", "y", "z", "intensity", "return_number", "number_of_returns", "classification",
               "scan_angle_deg", "gps_time", "point_source_id"]
    points = ds.sql(f"SELECT {', '.join(columns)} FROM als")
    assert gedisim.simulate(points, csv, als_crs=2154, progress=False).equals(expected)
    # Reversed, with int64 intensities: the same rows.
    reversed_ = points.take(pa.array(range(points.num_rows - 1, -1, -1)))
    reversed_ = reversed_.set_column(3, "intensity", reversed_.column("intensity").cast(pa.int64()))
    assert gedisim.simulate(reversed_, shots, als_crs=2154, progress=False).equals(expected)
    # Without the optional columns: no scan angle is 0°, the waveforms are the same.
    bare = gedisim.simulate(points.select(columns[:7]), shots, als_crs=2154, progress=False)
    assert set(bare.column("mean_scan_angle_deg").to_pylist()) == {0.0}
    assert bare.drop_columns(["mean_scan_angle_deg"]).equals(expected.drop_columns(["mean_scan_angle_deg"]))
    # Bad points: one line naming the column, nothing written.
    negative = points.set_column(3, "intensity", pa.array([-1] * points.num_rows, pa.int32()))
    for bad, said in ((points.drop_columns(["z"]), "z: column missing from the table"),
                      (negative, "intensity: Int32 cannot be read as UInt16 (Can't cast value -1"),
                      (points.slice(0, 0), "the points table has no point")):
        with pytest.raises(gedisim.GedisimError) as e:
            gedisim.simulate(bad, shots, als_crs=2154, out=tmp_path / "bad.parquet", progress=False)
        assert said in str(e.value) and "\n" not in str(e.value), str(e.value)
        assert not (tmp_path / "bad.parquet").exists()


def test_l2a_of_a_shots_table_equals_the_command(world, datasets, tmp_path):
    """The waveforms of the dataset's `shots/` give the rows `gedisim l2a` writes for those shots."""
    shots = gedisim.Dataset(datasets[0]).table("shots")
    table = gedisim.l2a(shots, algorithm=[1, 3], out=tmp_path / "api.parquet")
    assert table.equals(pq.read_table(tmp_path / "api.parquet"))
    files = []
    for i, l1b in enumerate(sorted((world / "gedi").glob("*GEDI01_B*.h5"))):
        files.append(tmp_path / f"cli{i}.parquet")
        cli("l2a", "--l1b", str(l1b), "--algorithms", "1,3", "--out", str(files[-1]))
    by_command = pa.concat_tables(pq.read_table(f) for f in files)
    mine = by_command.filter(pc.is_in(by_command.column("shot_number"), value_set=table.column("shot_number")))
    order = [("shot_number", "ascending"), ("algorithm", "ascending")]
    assert table.num_rows > 0 and table.sort_by(order).equals(mine.sort_by(order))
    with pytest.raises(gedisim.GedisimError, match="rx_waveform: column missing"):
        gedisim.l2a(shots.drop_columns(["rx_waveform"]))


def test_l2a_equals_the_command(world, tmp_path):
    l1b = sorted((world / "gedi").glob("*GEDI01_B*.h5"))[0]
    table = gedisim.l2a(l1b, algorithm=[1, 5])
    out = tmp_path / "l2a.parquet"
    cli("l2a", "--l1b", str(l1b), "--algorithms", "1,5", "--out", str(out))
    assert table.equals(pq.read_table(out))
    assert set(table.column("algorithm").to_pylist()) == {1, 5}


def test_diagnose_and_report_equal_the_command(datasets, tmp_path):
    api, _ = datasets
    quick = dict(twins=0, effects=["datum"], ranked_shots=60)
    d = gedisim.Dataset(api).diagnose(tmp_path / "api", progress=False, **quick)
    cli("diagnose", "--dataset", str(api), "--out", str(tmp_path / "cli"), "--twins", "0", "--effects", "datum",
        "--ranked-shots", "60", "--force")
    c = json.loads((tmp_path / "cli" / "diagnosis.json").read_text())
    assert d == json.loads((tmp_path / "api" / "diagnosis.json").read_text())
    for key in ("baseline", "configuration", "effects", "verdict", "summary"):
        assert d[key] == c[key], key
    html = gedisim.Dataset(api).report(diagnosis=tmp_path / "api", progress=False)
    assert html.name == "report.html" and html.stat().st_size > 0


def test_errors_are_the_commands_one_line(tmp_path):
    missing = tmp_path / "no-such-dataset"
    with pytest.raises(gedisim.GedisimError) as e:
        gedisim.Dataset(missing).sql("SELECT 1")
    said = cli("sql", "--dataset", str(missing), "SELECT 1", check=False)
    assert said.returncode != 0
    assert said.stderr.strip() == f"error: {e.value}"
    assert "\n" not in str(e.value)
    # A footprint CSV without coordinates: the same message, and no output left behind.
    bad = tmp_path / "bad.csv"
    bad.write_text("id,z\n1,2\n")
    out = tmp_path / "out.parquet"
    with pytest.raises(gedisim.GedisimError) as e:
        gedisim.simulate(tmp_path, bad, out=out, progress=False)
    said = cli("simulate", "--als", str(tmp_path), "--footprints", str(bad), "--out", str(out), check=False)
    assert said.stderr.strip() == f"error: {e.value}"
    assert not out.exists() and list(tmp_path.iterdir()) == [bad]


def test_sql_returns_one_table(datasets):
    ds = gedisim.Dataset(datasets[0])
    with pytest.raises(gedisim.GedisimError, match="second statement with a result"):
        ds.sql("SELECT 1 AS a; SELECT 2 AS b")
    with pytest.raises(gedisim.GedisimError, match="read-only"):
        ds.sql("CREATE TABLE t AS SELECT 1")


def test_tables_reach_pyarrow_without_a_copy(datasets):
    api, _ = datasets
    before = pa.total_allocated_bytes()
    t = gedisim.Dataset(api).sql("SELECT value FROM range(10000000)")
    assert t.num_rows == 10_000_000 and t.nbytes >= 80_000_000
    # The column's buffers are the Rust ones, imported through the C data interface: pyarrow allocated nothing.
    assert pa.total_allocated_bytes() - before < 1_000_000
    assert pc.sum(t.column("value")).as_py() == 10_000_000 * 9_999_999 // 2
    duckdb = pytest.importorskip("duckdb")
    assert duckdb.sql("SELECT count(*) FROM t").fetchall()[0][0] == 10_000_000


def test_the_docstring_examples_run(world, datasets, tmp_path):
    api, _ = datasets
    at = gedisim.Dataset(api).sql("SELECT x, y FROM sim WHERE status = 'ok' ORDER BY footprint_id LIMIT 1")
    names = dict(gedisim=gedisim, pa=pa, world=world, dataset=api, ds=gedisim.Dataset(api), tmp=tmp_path,
                 x0=at.column("x")[0].as_py(), y0=at.column("y")[0].as_py())
    failed, attempted = doctest.testmod(gedisim, extraglobs=names, report=True)
    assert attempted >= 15 and failed == 0, (failed, attempted)
