"""Runs of a scene: ``run`` and the ``Run`` it returns."""

from __future__ import annotations

import os
import tempfile
import threading
import warnings
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Mapping, Optional, Union

import numpy
import pandas

from . import _lyapsweep
from ._errors import InterpreterWarning, RunError

Scene = Union[str, "os.PathLike[str]", Mapping[str, Any]]

# The files of a set, as the command line names them (a two-parameter
# sweep's exponents are in grid.csv).
_SPECTRUM_FILES = ("spectrum.csv", "grid.csv")
_BIFURCATION_FILE = "bifurcation.csv"
_ATTRACTORS_FILE = "attractors.csv"
_ORBITS_FILE = "orbits.csv"
_BIFURCATIONS_FILE = "bifurcations.csv"


def run(
    scene: Scene,
    *,
    set: Union[Mapping[str, Any], "list[tuple[str, Any]]", None] = None,
    backend: Optional[str] = None,
    precision: Optional[str] = None,
    out: Union[str, "os.PathLike[str]", None] = None,
    progress: Union[bool, Callable[[int, int], Any]] = True,
) -> "Run":
    """Runs a scene as ``lyapsweep run`` does and returns its results.

    ``scene`` is a path, TOML text, or a dict of the same tables. A
    ``pathlib.Path`` (any ``os.PathLike``) is a path; a str is a path when
    it names an existing file, or has no newline and ends in ``.toml``, and
    TOML text otherwise. A file's
    ``model = "file.toml"`` is relative to the file; text's and a dict's are
    relative to the current directory.

    ``set`` overrides scene keys by their dotted names, as the command
    line's ``--set`` does: ``{"sweep.count": 101, "run.backend": "cpu"}``,
    or a list of such ``(key, value)`` pairs, applied in order; values are
    Python's (str, int, float, bool, lists, dicts) or numpy's (numbers, and
    arrays of integers or floats). ``backend``
    ("auto", "cpu", "gpu", "exact") and ``precision`` ("f64", "f32")
    override ``run.backend`` and ``run.precision`` after them; left at None,
    the scene's own choice stands.

    The run writes the command line's output set: into ``out`` when given
    (a new or empty folder, or a lyapsweep output folder, replaced whole),
    otherwise into a temporary folder that lasts as long as the ``Run``.

    ``progress=True`` shows a progress bar: tqdm's (``tqdm.auto``, a widget
    in a notebook) when tqdm is installed, else the command line's display
    on stderr. A callable is called with ``(done, total)`` lane-iterations
    a few times a second instead; ``False`` shows nothing.

    Raises ``SceneError`` (``ModelError`` for the model) with the command
    line's message before anything is written, and ``RunError`` when the
    files cannot be written or every lane failed. The GIL is released while
    the lanes run. Ctrl-C (or any exception from the progress callable)
    stops the run within about a second and is raised once it has stopped;
    nothing is then written, unless it came after the lanes had finished,
    while the set was being written: the set is then written whole (the
    previous one in ``out`` replaced), and the exception says so in its
    ``lyapsweep_written`` attribute (the paths written; ``[]`` for a
    temporary folder, removed) and, from Python 3.11, in a note.

    Runs in threads of one program each stage their set in a folder of
    their own; two at once into the same ``out`` are refused: the second
    raises ``RunError`` at once, and the first writes its set whole.
    """
    overrides = [(key, value, "set") for key, value in _pairs(set)]
    if backend is not None:
        overrides.append(("run.backend", backend, "backend"))
    if precision is not None:
        overrides.append(("run.precision", precision, "precision"))
    if not (isinstance(progress, bool) or callable(progress)):
        raise TypeError(
            f"progress is True, False or a callable of (done, total), not {type(progress).__name__}"
        )
    source = _source(scene)
    scratch = None
    if out is None:
        scratch = tempfile.TemporaryDirectory(prefix="lyapsweep-")
        folder = Path(scratch.name) / "set"
    else:
        folder = Path(out)
    bar = _Bar() if progress is True and _tqdm() is not None else None
    try:
        with _writing(folder):
            ran = _lyapsweep.run(source, overrides, folder, bar or progress)
            result = Run(folder, ran["summary"], ran["scene"], scratch, axes=ran["axes"])
    except BaseException as e:
        written = getattr(e, "lyapsweep_written", None)
        if scratch is not None:
            scratch.cleanup()
            if written is not None:
                e.lyapsweep_written = []
        elif written:
            _note(e, f"lyapsweep: the lanes had finished; the new set was written to {folder} before this was raised")
        raise
    finally:
        if bar is not None:
            bar.close()
    _warn_interpreted(result.summary)
    return result


def _warn_interpreted(summary: dict) -> None:
    """The command line's warning that the model ran on the interpreter,
    as a Python warning: a wheel installs without a C compiler, and its
    results are then right but slower."""
    fallback = summary.get("interpreter_fallback")
    if fallback:
        warnings.warn(
            InterpreterWarning(
                f"lyapsweep: {fallback}. The results are the same to the bit. This package "
                "needs no C compiler, but with one (gcc or clang on PATH as cc, or named "
                "by CC) the CPU path runs models at full speed"
            ),
            stacklevel=3,
        )


def _tqdm() -> Optional[type]:
    """tqdm's bar for this front end (a notebook's widget, or a
    terminal's), or None when tqdm is not installed."""
    try:
        from tqdm.auto import tqdm
    except ImportError:
        return None
    return tqdm


class _Bar:
    """A tqdm bar following a run's ``(done, total)`` lane-iterations; it
    appears once the run has counted its work."""

    def __init__(self):
        self._bar = None

    def __call__(self, done: int, total: int) -> None:
        if self._bar is None:
            self._bar = _tqdm()(total=total, unit="lane-it", unit_scale=True, dynamic_ncols=True)
        # A continuation pass adds lanes to the run as it goes.
        if total != self._bar.total:
            self._bar.total = total
            self._bar.refresh()
        self._bar.update(done - self._bar.n)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()


def _source(scene: Scene) -> Any:
    """What the extension reads a scene (or a model) from: a Path for a
    file, the text, or the dict."""
    if isinstance(scene, Mapping):
        # The dict itself, so that one holding itself is named as it is.
        return scene if isinstance(scene, dict) else dict(scene)
    if isinstance(scene, str):
        # TOML text has a newline or an `=`, and so may a file's name: a
        # name is told by the file it names, or by its ending.
        one_line = "\n" not in scene and "\r" not in scene
        if one_line and (scene.endswith(".toml") or _is_file(scene)):
            return Path(scene)
        return scene
    if isinstance(scene, os.PathLike):
        return Path(scene)
    raise TypeError(
        f"a scene is a path, TOML text or a dict, not {type(scene).__name__}"
    )


def _is_file(name: str) -> bool:
    try:
        return os.path.isfile(name)
    except (ValueError, OSError):  # a NUL, a name too long
        return False


def _pairs(overrides: Any) -> list:
    """``set=`` as (key, value) pairs: a mapping's items, or a list (any
    iterable but a str) of pairs."""
    if overrides is None:
        return []
    if isinstance(overrides, Mapping):
        return list(overrides.items())
    if isinstance(overrides, (str, bytes)) or not hasattr(overrides, "__iter__"):
        raise TypeError(
            f"set is a dict of dotted keys and values, or a list of (key, value) pairs, not {type(overrides).__name__}"
        )
    pairs = []
    for i, pair in enumerate(overrides):
        if not (isinstance(pair, (tuple, list)) and len(pair) == 2 and isinstance(pair[0], str)):
            raise TypeError(f"set[{i}] is not a (key, value) pair with a str key: {pair!r:.80}")
        pairs.append(tuple(pair))
    return pairs


# The output folders runs of this process are writing, so that two threads
# never write (and read back) the same one at once.
_busy: "set[str]" = set()
_busy_lock = threading.Lock()
# A child started by fork has none of its parent's runs.
if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_busy.clear)


@contextmanager
def _writing(folder: Path):
    """Claims ``folder`` for one run (or write) of this process until its
    set is written and read back; another at the same time raises
    RunError."""
    key = os.path.realpath(folder)
    with _busy_lock:
        if key in _busy:
            raise RunError(
                f"{folder}: another run of this program is writing it now; wait for it, or give another out",
                key=None,
            )
        _busy.add(key)
    try:
        yield
    finally:
        with _busy_lock:
            _busy.discard(key)


def _note(exception: BaseException, note: str) -> None:
    # add_note is Python 3.11's; before it the attribute alone says so.
    if hasattr(exception, "add_note"):
        exception.add_note(note)


# Each number must be the file's to the bit: pandas before 3 parses with a
# faster parser that may miss the last bit unless asked for round trips;
# from 3 on that is the default, and asking is deprecated.
_EXACT = {} if int(pandas.__version__.split(".")[0]) >= 3 else {"float_precision": "round_trip"}


def read_csv(path: Path) -> pandas.DataFrame:
    """A CSV file of a set as a DataFrame, its numbers the file's."""
    return pandas.read_csv(path, **_EXACT)


def _read(path: Path) -> Optional[pandas.DataFrame]:
    return read_csv(path) if path.exists() else None


class Run:
    """The results of one run: its output set's tables and summary.

    ``spectrum`` (a two-parameter sweep's grid.csv), ``bifurcation``,
    ``attractors``, and with ``[orbits]`` ``orbits`` (a row per point of
    every branch) and ``bifurcations`` (a row per bifurcation located on
    them; with two swept parameters, both are columns) are DataFrames with the columns of the CSV files, or None where
    the run wrote no such file. ``summary`` is what the command line
    prints (backend, precision, lanes, time, max_sum_error, max_error, flagged, the
    flagged lanes by status in ``flagged_by_status``, of which those with no
    exponents in ``failures``), ``scene`` the scene as run, and ``folder`` where
    the set lies (``out``, or a temporary folder removed with the Run).
    ``to_xarray()`` labels the tables by the swept parameters, the start and
    the exponent; ``write_netcdf(path)`` writes them to a file. With
    ``attractors.basins``, ``basins(k)`` is value k's image of labels.
    """

    def __init__(
        self,
        folder: Path,
        summary: dict,
        scene: dict,
        scratch: Optional[tempfile.TemporaryDirectory] = None,
        axes: Optional[list] = None,
    ):
        self.folder = folder
        self.summary = summary
        self.scene = scene
        # Each swept parameter's name and values, as the library made them:
        # the labels of to_xarray's grid.
        self.axes = axes
        # Kept so that the temporary folder lasts as long as the Run.
        self._scratch = scratch
        spectrum = [folder / name for name in _SPECTRUM_FILES]
        self.spectrum = next((_read(p) for p in spectrum if p.exists()), None)
        self.bifurcation = _read(folder / _BIFURCATION_FILE)
        self.attractors = _read(folder / _ATTRACTORS_FILE)
        self.orbits = _read(folder / _ORBITS_FILE)
        self.bifurcations = _read(folder / _BIFURCATIONS_FILE)

    def __repr__(self) -> str:
        s = self.summary
        return (
            f"<lyapsweep.Run {s['name']}: {s['lanes']} lanes on {s['backend']} "
            f"({s['precision']}) in {s['time']:.3f} s, {s['flagged']} flagged>"
        )

    def basins(self, value: int = 0) -> numpy.ndarray:
        """The basin image of the ``value``-th value (in the sweep's order) of a
        scene with ``attractors.basins``: a 2-D array of int32, rows along the
        grid's second state and columns along its first, each start's label
        the branch of the attractor its lane ended on (as attractors.csv's
        ``branch``), -1 where the lane failed, -2 where the start lies outside
        the admissible states (behind a wall; not run). Read from
        ``basins-<value>.npy``."""
        path = self.folder / f"basins-{int(value)}.npy"
        if not path.exists():
            raise ValueError(
                f"the run has no basin image of value {value}: its scene's attractors.basins "
                "covers fewer values, or is not set"
            )
        return numpy.load(path, allow_pickle=False)

    def write(self, folder: Union[str, "os.PathLike[str]"]) -> list:
        """Writes the run's output set into ``folder`` as the command line
        does: staged beside it and swapped in whole, with its manifest; the
        folder must be new, empty or a lyapsweep output folder. Returns the
        paths written."""
        with _writing(Path(folder)):
            written = _lyapsweep.copy_set(self.folder, Path(folder))
        return [Path(p) for p in written]

    def to_xarray(self, table: str = "spectrum"):
        """The run as an ``xarray.Dataset`` (xarray is the extra
        ``lyapsweep[xarray]``, imported only here).

        ``table="spectrum"``: the exponents on the sweep's grid. Its
        dimensions are the swept parameters (named after them, their values
        as coordinates, in sweep order), ``start`` (with ``[attractors]``:
        the start's index, continuation lanes from the number of starts
        up) and ``exponent`` (1 to N). ``lambda`` holds the exponents over
        all of them; every other column of spectrum.csv (grid.csv), such as
        ``status``, ``period``, ``branch`` and ``lambda_sum``, is a variable
        over the grid and the start, its values the file's to the bit. A
        value with fewer continuation lanes than another leaves cells no
        lane filled: NaN there (integer columns become floats then), and
        ``""`` for ``status``.

        ``table="attractors"``: attractors.csv's rows along ``attractor``,
        their exponents in ``lambda`` over ``exponent``, every other column
        a variable of the row.
        """
        from . import _xarray

        if table == "spectrum":
            return _xarray.spectrum(self)
        if table == "attractors":
            return _xarray.attractors(self)
        raise ValueError(f'table is "spectrum" or "attractors", not {table!r}')

    def write_netcdf(self, path: Union[str, "os.PathLike[str]"]) -> Path:
        """Writes ``to_xarray()`` to the netCDF-4 file ``path`` and, with
        ``[attractors]``, ``to_xarray("attractors")`` to its group
        ``attractors`` (``xarray.open_dataset(path, group="attractors")``
        reads it). It writes with h5netcdf, installed by the extra
        ``lyapsweep[xarray]``. Returns the path."""
        from . import _xarray

        return Path(_xarray.write_netcdf(self, path))

    def plot(self):
        """A matplotlib figure of the sweep: the bifurcation diagram (when
        points were kept) above the exponents against the swept parameter;
        for two parameters, a map of the largest exponent."""
        try:
            import matplotlib.pyplot as plt
        except ImportError as e:
            raise ImportError(
                "Run.plot() draws with matplotlib, which is not installed: "
                "pip install matplotlib"
            ) from e
        from ._plot import draw

        return draw(plt, self)
