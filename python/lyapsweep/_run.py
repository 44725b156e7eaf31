"""Runs of a scene: ``run`` and the ``Run`` it returns."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any, Callable, Mapping, Optional, Union

import pandas

from . import _lyapsweep

Scene = Union[str, "os.PathLike[str]", Mapping[str, Any]]

# The files of a set, as the command line names them (a two-parameter
# sweep's exponents are in grid.csv).
_SPECTRUM_FILES = ("spectrum.csv", "grid.csv")
_BIFURCATION_FILE = "bifurcation.csv"
_ATTRACTORS_FILE = "attractors.csv"


def run(
    scene: Scene,
    *,
    set: Optional[Mapping[str, Any]] = None,
    backend: Optional[str] = None,
    precision: Optional[str] = None,
    out: Union[str, "os.PathLike[str]", None] = None,
    progress: Union[bool, Callable[[int, int], Any]] = True,
) -> "Run":
    """Runs a scene as ``lyapsweep run`` does and returns its results.

    ``scene`` is a path (a ``pathlib.Path``, or a str without a newline and
    without ``=``), TOML text, or a dict of the same tables. A file's
    ``model = "file.toml"`` is relative to the file; text's and a dict's are
    relative to the current directory.

    ``set`` overrides scene keys by their dotted names, as the command
    line's ``--set`` does: ``{"sweep.count": 101, "run.backend": "cpu"}``;
    values are Python's (str, int, float, bool, lists, dicts). ``backend``
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
    nothing is then written.
    """
    overrides = list((set or {}).items())
    if backend is not None:
        overrides.append(("run.backend", backend))
    if precision is not None:
        overrides.append(("run.precision", precision))
    scratch = None
    if out is None:
        scratch = tempfile.TemporaryDirectory(prefix="lyapsweep-")
        folder = Path(scratch.name) / "set"
    else:
        folder = Path(out)
    bar = _Bar() if progress is True and _tqdm() is not None else None
    try:
        ran = _lyapsweep.run(_source(scene), overrides, folder, bar or progress)
    except BaseException:
        if scratch is not None:
            scratch.cleanup()
        raise
    finally:
        if bar is not None:
            bar.close()
    return Run(folder, ran["summary"], ran["scene"], scratch)


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
        return dict(scene)
    if isinstance(scene, str):
        return scene if "\n" in scene or "=" in scene else Path(scene)
    if isinstance(scene, os.PathLike):
        return Path(scene)
    raise TypeError(
        f"a scene is a path, TOML text or a dict, not {type(scene).__name__}"
    )


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

    ``spectrum`` (a two-parameter sweep's grid.csv), ``bifurcation`` and
    ``attractors`` are DataFrames with the columns of the CSV files, or None
    where the run wrote no such file. ``summary`` is what the command line
    prints (backend, precision, lanes, time, max_sum_error, max_error, flagged, the
    flagged lanes by status in ``flagged_by_status``, of which those with no
    exponents in ``failures``), ``scene`` the scene as run, and ``folder`` where
    the set lies (``out``, or a temporary folder removed with the Run).
    """

    def __init__(
        self,
        folder: Path,
        summary: dict,
        scene: dict,
        scratch: Optional[tempfile.TemporaryDirectory] = None,
    ):
        self.folder = folder
        self.summary = summary
        self.scene = scene
        # Kept so that the temporary folder lasts as long as the Run.
        self._scratch = scratch
        spectrum = [folder / name for name in _SPECTRUM_FILES]
        self.spectrum = next((_read(p) for p in spectrum if p.exists()), None)
        self.bifurcation = _read(folder / _BIFURCATION_FILE)
        self.attractors = _read(folder / _ATTRACTORS_FILE)

    def __repr__(self) -> str:
        s = self.summary
        return (
            f"<lyapsweep.Run {s['name']}: {s['lanes']} lanes on {s['backend']} "
            f"({s['precision']}) in {s['time']:.3f} s, {s['flagged']} flagged>"
        )

    def write(self, folder: Union[str, "os.PathLike[str]"]) -> list:
        """Writes the run's output set into ``folder`` as the command line
        does: staged beside it and swapped in whole, with its manifest; the
        folder must be new, empty or a lyapsweep output folder. Returns the
        paths written."""
        written = _lyapsweep.copy_set(self.folder, Path(folder))
        return [Path(p) for p in written]

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
