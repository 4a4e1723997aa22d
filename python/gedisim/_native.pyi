"""Type hints of the extension module (python/src/lib.rs): the operations of the ``gedisim`` command."""

from typing import Callable, Optional

import pyarrow

ProgressCallback = Callable[[str, str, str, int], None]

__version__: str

class GedisimError(Exception):
    """A gedisim operation failed: the command line's one-line message."""

def sql(dataset: str, query: str) -> pyarrow.Table: ...
def run(
    dataset: str,
    als: list[str],
    l1b: list[str],
    l2a: list[str],
    epsg: Optional[int] = None,
    landcover: Optional[str] = None,
    geoid_offset: Optional[float] = None,
    all_shots: bool = False,
    progress: Optional[ProgressCallback] = None,
) -> str: ...
def report(dataset: str, diagnosis: Optional[str] = None, progress: Optional[ProgressCallback] = None) -> str: ...
def diagnose(
    dataset: str,
    out: str,
    twins: Optional[int] = None,
    effects: Optional[list[str]] = None,
    ranked_shots: Optional[int] = None,
    force: bool = False,
    progress: Optional[ProgressCallback] = None,
) -> str: ...
def simulate(
    als: list[str],
    footprints: str,
    out: str,
    points: Optional[pyarrow.Table] = None,
    als_crs: Optional[int] = None,
    profile: str = "default",
    fsigma: Optional[float] = None,
    crs: Optional[int] = None,
    pulse: str = "gaussian",
    progress: Optional[ProgressCallback] = None,
) -> tuple[int, int]: ...
def l2a(l1b: str, algorithms: list[int], out: str) -> tuple[int, int, list[str]]: ...
def l2a_table(shots: pyarrow.Table, algorithms: list[int], out: Optional[str] = None) -> pyarrow.Table: ...
def read_granules_with(exe: str) -> None: ...
