"""gedisim from Python: the study's dataset, the simulator, L2A and the diagnosis over Arrow.

Every call is a thin wrapper over the operation the ``gedisim`` command runs (the same Rust code,
in the extension module ``gedisim._native``), with the command line's defaults; tables come back
as ``pyarrow.Table`` through the Arrow C data interface (no copy), so pandas, polars and DuckDB take
them directly. Errors raise :class:`GedisimError` with the command line's one-line message.
docs/python.md in the repository describes the API; ``examples/study.ipynb`` runs the study. The examples of the
docstrings run in the package's tests (python/tests), on a world of ``gedisim scenario``: ``world`` (its folder),
``dataset`` (a dataset ``run`` made from it), ``ds`` (``Dataset(dataset)``), ``tmp`` (an empty folder), ``x0, y0``
(a footprint's position over its tiles).

>>> import gedisim
>>> gedisim.__version__
'0.1.0'
"""

from __future__ import annotations

import json
import os
import sys
import sysconfig
import tempfile
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence, Union

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from . import _native
from ._native import GedisimError
from ._progress import progress_callback

__version__: str = _native.__version__
__all__ = ["Dataset", "GedisimError", "simulate", "l2a", "rh", "command", "__version__"]

PathLike = Union[str, "os.PathLike[str]"]


def command() -> str | None:
    """Path of the ``gedisim`` command installed with this package, in the environment's scripts folder (``None``
    if it is missing: another ``gedisim`` on the PATH may be another version).

    >>> import os
    >>> os.access(gedisim.command(), os.X_OK)
    True
    """
    exe = "gedisim.exe" if sys.platform == "win32" else "gedisim"
    scripts = Path(sysconfig.get_path("scripts")) / exe
    if scripts.is_file():
        return str(scripts)
    beside = Path(sys.executable).parent / exe
    return str(beside) if beside.is_file() else None


# Granules are read in child processes of the installed command, as the command line reads them: a corrupt granule
# that crashes the HDF5 library becomes a GedisimError instead of ending the Python process.
_cmd = command()
if _cmd is not None:
    _native.read_granules_with(_cmd)


def _paths(p: PathLike | Iterable[PathLike] | None) -> list[str]:
    if p is None:
        return []
    if isinstance(p, (str, os.PathLike)):
        return [os.fspath(p)]
    return [os.fspath(x) for x in p]


def _progress(progress: bool | None):
    return progress_callback() if progress in (None, True) else None


class Dataset:
    """A gedisim dataset: a directory of Parquet tables (docs/schemas.md), created by :meth:`run`.

    >>> ds = gedisim.Dataset(dataset)
    >>> ds.sql("SELECT count(*) AS n FROM shots").column("n")[0].as_py() > 0
    True
    """

    def __init__(self, path: PathLike):
        self.path = Path(path)

    def __repr__(self) -> str:
        return f"gedisim.Dataset({str(self.path)!r})"

    def __fspath__(self) -> str:
        return str(self.path)

    def sql(self, query: str) -> pa.Table:
        """The result of ``query`` on the dataset's tables, with gedisim's SQL functions (read-only, as
        ``gedisim sql``). Statements are separated by ``;``; exactly one may have a result.

        >>> ds.sql("SELECT weighting, count(*) AS n FROM results GROUP BY weighting ORDER BY weighting").num_rows
        3
        """
        return _native.sql(str(self.path), query)

    def table(self, name: str) -> pa.Table:
        """A whole table of the dataset (``shots``, ``sim``, ``results``, …; docs/schemas.md).

        >>> ds.table("tiles").num_rows > 0
        True
        """
        quoted = '"' + name.replace('"', '""') + '"'
        return self.sql(f"SELECT * FROM {quoted}")

    def run(
        self,
        als: PathLike | Iterable[PathLike] | None = None,
        l1b: PathLike | Iterable[PathLike] | None = None,
        l2a: PathLike | Iterable[PathLike] | None = None,
        *,
        epsg: int | None = None,
        landcover: PathLike | None = None,
        geoid_offset: float | None = None,
        all_shots: bool = False,
        progress: bool | None = None,
    ) -> dict[str, Any]:
        """``gedisim run``: ingest ALS tiles and GEDI granules (files or folders), collocate, simulate
        and write the study's tables into the dataset (created if needed). Returns what it did: the object
        ``gedisim run --json`` prints (ingested, collocated, simulated, the rows each filter removed).

        >>> ran = gedisim.Dataset(tmp / "ds").run(als=world / "als", l1b=world / "gedi", l2a=world / "gedi")
        >>> ran["simulation"]["shots_simulated"] > 0
        True
        """
        text = _native.run(
            str(self.path),
            _paths(als),
            _paths(l1b),
            _paths(l2a),
            epsg=epsg,
            landcover=None if landcover is None else os.fspath(landcover),
            geoid_offset=geoid_offset,
            all_shots=all_shots,
            progress=_progress(progress),
        )
        return json.loads(text)

    def report(self, diagnosis: PathLike | None = None, *, progress: bool | None = None) -> Path:
        """``gedisim report``: the study's tables, figures and ``report.html`` under ``<dataset>/report/``
        (with a diagnosis folder's verdict when ``diagnosis`` is given). Returns the page's path.

        >>> ds.report().name
        'report.html'
        """
        html = _native.report(
            str(self.path),
            diagnosis=None if diagnosis is None else os.fspath(diagnosis),
            progress=_progress(progress),
        )
        return Path(html)

    def diagnose(
        self,
        out: PathLike,
        *,
        twins: int | None = None,
        effects: Sequence[str] | None = None,
        ranked_shots: int | None = None,
        force: bool = False,
        progress: bool | None = None,
    ) -> dict[str, Any]:
        """``gedisim diagnose --dataset … --out out``: where the sim-to-real gap lies, which effect causes it
        and how far it shrinks (docs/diagnosis.md). Returns ``diagnosis.json`` as Python objects; its
        tables and figures are in ``out``. ``twins`` (self-test), ``effects`` and ``ranked_shots``
        default to the command line's.

        >>> d = ds.diagnose(tmp / "diagnosis", twins=0, effects=["datum"], ranked_shots=60)
        >>> d["effects"][0]["name"], d["configuration"]["chosen"] != ""
        ('datum', True)
        """
        text = _native.diagnose(
            str(self.path),
            os.fspath(out),
            twins=twins,
            effects=None if effects is None else list(effects),
            ranked_shots=ranked_shots,
            force=force,
            progress=_progress(progress),
        )
        return json.loads(text)


def _table(x: Any) -> pa.Table | None:
    """``x`` as a pyarrow Table when it is a table (pyarrow, anything with ``__arrow_c_stream__`` such as polars,
    pandas, a mapping of columns); ``None`` when it is not (a path, or a list of paths)."""
    if isinstance(x, pa.Table):
        return x
    if isinstance(x, (str, os.PathLike)):
        return None
    if isinstance(x, Mapping):
        return pa.table(dict(x))
    if hasattr(x, "__arrow_c_stream__"):
        return pa.table(x)
    if hasattr(x, "to_arrow"):
        return x.to_arrow()
    if hasattr(x, "columns") and hasattr(x, "to_dict"):
        return pa.Table.from_pandas(x, preserve_index=False)
    return None


def _footprints_csv(footprints: Any, directory: str) -> str:
    """``footprints`` as a CSV file the simulator reads: a path is used as it is; a table is written to
    ``directory``."""
    if isinstance(footprints, (str, os.PathLike)):
        return os.fspath(footprints)
    table = _table(footprints)
    if table is None:
        raise TypeError(
            "footprints: a CSV path, a pyarrow Table, a pandas or polars DataFrame or a dict of columns "
            "(an id, and x, y or lon, lat)"
        )
    # The CSV writer takes no view columns (the strings of Dataset.sql are views).
    plain = {pa.string_view(): pa.string(), pa.binary_view(): pa.binary()}
    table = table.cast(pa.schema([f.with_type(plain.get(f.type, f.type)) for f in table.schema]))
    path = os.path.join(directory, "footprints.csv")
    pacsv.write_csv(table, path)
    return path


def simulate(
    als: PathLike | Iterable[PathLike] | Any,
    footprints: Any,
    *,
    als_crs: int | None = None,
    weighting: str | None = None,
    profile: str = "default",
    fsigma: float | None = None,
    crs: int | None = None,
    pulse: str = "gaussian",
    out: PathLike | None = None,
    progress: bool | None = None,
) -> pa.Table:
    """Simulated GEDI waveforms and RH metrics at ``footprints``: ``gedisim simulate --als … --footprints … --out …``,
    one row per footprint × weighting (``count``, ``frac``, ``int``; docs/schemas.md, ``sim/``).

    ``als``: LAS/LAZ/COPC files or folders; or a points table with the columns of ``als/`` (docs/schemas.md: x, y,
    z, intensity, return_number, number_of_returns, classification; scan_angle_deg, gps_time and point_source_id may be
    missing), e.g. ``ds.sql("SELECT * FROM als WHERE …")`` or a laspy/PDAL array as a DataFrame, in EPSG ``als_crs``
    (default: a frame of its own). ``footprints``: a CSV path, or a table (pyarrow, pandas, polars, dict of columns)
    with an id and ``x, y`` (in ``crs``, default the ALS CRS) or ``lon, lat``. ``weighting`` keeps one weighting's
    rows. ``profile``: ``default`` or ``gedirat`` (Hancock's gediRat exactly); ``fsigma``: the footprint σ (m,
    default GEDI's 5.5). ``out``: also keep the Parquet file there (written atomically); otherwise it is written to
    a temporary folder.

    >>> t = gedisim.simulate(world / "als", {"id": ["p1"], "x": [x0], "y": [y0]}, weighting="int")
    >>> t.column("weighting").to_pylist(), t.column("status").to_pylist()
    (['int'], ['ok'])
    >>> points = ds.sql(f"SELECT * FROM als WHERE abs(x - {x0}) < 30 AND abs(y - {y0}) < 30")
    >>> u = gedisim.simulate(points, {"id": ["p1"], "x": [x0], "y": [y0]}, als_crs=2154, weighting="int")
    >>> u.column("rh").to_pylist() == t.column("rh").to_pylist()
    True
    """
    points = _table(als)
    with tempfile.TemporaryDirectory(prefix="gedisim-") as tmp:
        target = os.fspath(out) if out is not None else os.path.join(tmp, "simulated.parquet")
        _native.simulate(
            [] if points is not None else _paths(als),
            _footprints_csv(footprints, tmp),
            target,
            points=points,
            als_crs=als_crs,
            profile=profile,
            fsigma=None if fsigma is None else float(fsigma),
            crs=crs,
            pulse=pulse,
            progress=_progress(progress),
        )
        table = pq.read_table(target)
    if weighting is not None:
        table = table.filter(pc.equal(table.column("weighting"), weighting))
    return table


def l2a(
    waveforms: PathLike | Any,
    *,
    algorithm: int | Sequence[int] = (1, 2, 3, 4, 5, 6),
    out: PathLike | None = None,
) -> pa.Table:
    """GEDI's L2A processing (``gedisim l2a``, docs/l2a.md): ground, RH0…RH100 and the flags of each algorithm asked
    for (1–6), one row per shot × algorithm (docs/schemas.md, ``l2a``). ``waveforms``: an L1B granule, or a table
    with the L1B columns of ``shots/`` (shot_number, beam, rx_waveform, noise_mean_corrected, noise_stddev_corrected,
    elevation_bin0/lastbin, latitude_bin0/lastbin, longitude_bin0/lastbin), e.g. ``ds.table("shots")``; rows
    without ``elevation_bin0`` (no L1B) are skipped. ``out``: also write the Parquet file there (atomically).

    >>> t = gedisim.l2a(next((world / "gedi").glob("*GEDI01_B*.h5")), algorithm=[1, 5])
    >>> sorted(set(t.column("algorithm").to_pylist()))
    [1, 5]
    >>> u = gedisim.l2a(ds.sql("SELECT * FROM shots WHERE rx_waveform IS NOT NULL"), algorithm=[1, 5])
    >>> u.num_rows > 0, sorted(set(u.column("algorithm").to_pylist()))
    (True, [1, 5])
    """
    algorithms = [algorithm] if isinstance(algorithm, int) else list(algorithm)
    shots = _table(waveforms)
    if shots is not None:
        return _native.l2a_table(shots, algorithms, None if out is None else os.fspath(out))
    with tempfile.TemporaryDirectory(prefix="gedisim-") as tmp:
        target = os.fspath(out) if out is not None else os.path.join(tmp, "l2a.parquet")
        _native.l2a(os.fspath(waveforms), algorithms, target)
        return pq.read_table(target)


def rh(table: pa.Table, *percentiles: int, column: str = "rh") -> pa.Table:
    """The RH percentiles of a table with a 101-value ``rh`` list column (RH0…RH100, m), as columns
    ``rh<N>``: ``gedisim.rh(sim, 50, 98)`` adds ``rh50`` and ``rh98`` (all 101 without percentiles).

    >>> gedisim.rh(pa.table({"rh": [[float(i) for i in range(101)]]}), 98).column("rh98").to_pylist()
    [98.0]
    """
    wanted = percentiles or tuple(range(101))
    for p in wanted:
        if not 0 <= p <= 100:
            raise ValueError(f"rh: percentile {p} is not within 0–100")
    values = table.column(column)
    for p in wanted:
        table = table.append_column(f"rh{p}", pc.list_element(values, p))
    return table
