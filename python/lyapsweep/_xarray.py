"""Run.to_xarray's labelled arrays: a run's tables on the grid its lanes
cover, and Run.write_netcdf's file. xarray (and h5netcdf for the file) is
an optional extra, imported only here, only when called."""

from __future__ import annotations

import os
from typing import Optional, Union

import numpy
import pandas

# What installs what this module needs.
_EXTRA = "pip install 'lyapsweep[xarray]'"
# The netCDF engine: h5netcdf on h5py writes netCDF-4 files (groups, 64-bit
# integers, strings) and is the smallest install that does (about 5 MB,
# against netCDF4's 12 MB and scipy's 35 MB, whose netCDF-3 has no groups).
_ENGINE = "h5netcdf"
# The group of the file that holds the attractors' table.
ATTRACTORS_GROUP = "attractors"


def import_xarray():
    """xarray, or an ImportError naming the extra that installs it."""
    try:
        import xarray
    except ImportError as e:
        raise ImportError(
            f"Run.to_xarray() and Run.write_netcdf() need xarray, which is not installed: {_EXTRA}",
            name="xarray",
        ) from e
    return xarray


def _require_engine() -> None:
    try:
        import h5netcdf  # noqa: F401
        import h5py  # noqa: F401
    except ImportError as e:
        raise ImportError(
            f"Run.write_netcdf() writes with h5netcdf and h5py, which are not installed: {_EXTRA}",
            name=e.name,
        ) from e


def spectrum(run) -> "xarray.Dataset":
    """The spectrum (a two-parameter sweep's grid) on the sweep's grid:
    dimensions the swept parameters (named and labelled after them), the
    start (with ``[attractors]``) and the exponent; ``lambda`` over all of
    them, every other column of the file over the first ones."""
    xarray = import_xarray()
    table = run.spectrum
    if table is None:
        raise ValueError(
            'the run kept no exponents (output.lyapunov = "none"): it has no spectrum to label'
        )
    axes = _axes(run)
    parameters = [name for name, _ in axes]
    exponents = _exponent_columns(table)
    cell, starts = _cells(table, axes)
    shape = tuple(len(values) for _, values in axes) + (starts,)
    filled = numpy.zeros(shape, dtype=bool)
    filled[cell] = True
    every_cell = bool(filled.all())

    dims = parameters + ["start"]
    variables = {}
    lam = numpy.full(shape + (len(exponents),), numpy.nan)
    for i, column in enumerate(exponents):
        lam[cell + (i,)] = table[column].to_numpy()
    variables["lambda"] = (dims + ["exponent"], lam)
    skipped = set(parameters) | set(exponents) | {"start"}
    for column in table.columns:
        if column not in skipped:
            variables[column] = (dims, _spread(table[column], cell, shape, every_cell))
    coords = {name: numpy.asarray(values, dtype=float) for name, values in axes}
    coords["start"] = numpy.arange(starts)
    coords["exponent"] = numpy.arange(1, len(exponents) + 1)
    dataset = xarray.Dataset(variables, coords=coords, attrs=_attrs(run))
    if "start" not in table.columns:
        # One lane per value: no start to label.
        dataset = dataset.squeeze("start", drop=True)
    _describe(dataset, every_cell)
    return dataset


def attractors(run) -> "xarray.Dataset":
    """The attractors' table as a dataset: a row per value and attractor
    (dimension ``attractor``), its exponents over ``exponent`` in
    ``lambda``, every other column a variable of the row."""
    xarray = import_xarray()
    table = run.attractors
    if table is None:
        raise ValueError("the run has no attractors' table: its scene has no [attractors]")
    exponents = _exponent_columns(table)
    variables = {"lambda": (["attractor", "exponent"], table[exponents].to_numpy(dtype=float))}
    for column in table.columns:
        if column not in exponents:
            variables[column] = (["attractor"], _column(table[column]))
    coords = {
        "attractor": numpy.arange(len(table)),
        "exponent": numpy.arange(1, len(exponents) + 1),
    }
    dataset = xarray.Dataset(variables, coords=coords, attrs=_attrs(run))
    dataset["lambda"].attrs["description"] = "the attractor's exponents, λ1 first"
    return dataset


def write_netcdf(run, path: Union[str, "os.PathLike[str]"]) -> "os.PathLike[str]":
    """Writes the spectrum's dataset to ``path`` and, with ``[attractors]``,
    the attractors' in the group ``attractors``; returns the path."""
    _require_engine()
    path = os.fspath(path)
    spectrum(run).to_netcdf(path, mode="w", engine=_ENGINE)
    if run.attractors is not None:
        attractors(run).to_netcdf(path, mode="a", group=ATTRACTORS_GROUP, engine=_ENGINE)
    return path


def _axes(run) -> "list[tuple[str, list[float]]]":
    axes = getattr(run, "axes", None)
    if not axes:
        raise ValueError("this Run does not know its sweep's axes: run the scene with lyapsweep.run")
    return [(name, list(values)) for name, values in axes]


def _exponent_columns(table: pandas.DataFrame) -> "list[str]":
    numbered = [c for c in table.columns if c.startswith("lambda_") and c[7:].isdigit()]
    return sorted(numbered, key=lambda c: int(c[7:]))


def _cells(table: pandas.DataFrame, axes) -> "tuple[tuple, int]":
    """Each row's cell of the grid, as index arrays (one per parameter,
    then the start), and the number of starts a cell has room for.

    The file lists every value's starts in sweep order (a grid's first
    parameter fastest), then any continuation lanes, each numbered from
    the number of starts up; those are placed by their values."""
    sizes = [len(values) for _, values in axes]
    points = int(numpy.prod(sizes))
    parameters = [name for name, _ in axes]
    if "start" in table.columns:
        start = table["start"].to_numpy()
        starts = _leading_starts(start, points)
    else:
        start = numpy.zeros(len(table), dtype=int)
        starts = 1
    first = points * starts
    if len(table) < first or not numpy.array_equal(start[:first], numpy.tile(numpy.arange(starts), points)):
        raise ValueError(
            f"the spectrum's rows are not the sweep's {points} values × {starts} starts in order: "
            "is the set the one this Run ran?"
        )
    # The values the first rows must hold: position k is the grid's cell
    # (k mod n1, k div n1), the first parameter fastest.
    index = numpy.unravel_index(numpy.arange(points), sizes, order="F")
    position_values = numpy.stack(
        [numpy.asarray(values, dtype=float)[i] for (_, values), i in zip(axes, index)], axis=1
    )
    written = table[parameters].to_numpy(dtype=float)
    if not numpy.array_equal(written[:first:starts], position_values):
        raise ValueError("the spectrum's values are not the sweep's: is the set the one this Run ran?")
    position = numpy.empty(len(table), dtype=int)
    position[:first] = numpy.arange(first) // starts
    later = written[first:]
    if len(later):
        position[first:] = _positions_of(later, position_values, parameters)
        width = int(start.max()) + 1
    else:
        width = starts
    cell = numpy.unravel_index(position, sizes, order="F") + (start,)
    flat = numpy.ravel_multi_index(cell, tuple(sizes) + (width,))
    if len(numpy.unique(flat)) != len(flat):
        raise ValueError("two rows of the spectrum share a value and a start")
    return cell, width


def _leading_starts(start: numpy.ndarray, points: int) -> int:
    """The starts per value: the rows of the first value, numbered 0 up."""
    if points > 1:
        zeros = numpy.flatnonzero(start == 0)
        if len(zeros) < 2:
            raise ValueError("the spectrum has fewer values than the sweep")
        return int(zeros[1] - zeros[0])
    run_length = 0
    while run_length < len(start) and start[run_length] == run_length:
        run_length += 1
    return run_length


def _positions_of(values: numpy.ndarray, position_values: numpy.ndarray, parameters) -> numpy.ndarray:
    """The sweep positions of continuation lanes, by their values."""
    index = pandas.MultiIndex.from_arrays([position_values[:, i] for i in range(len(parameters))])
    if not index.is_unique:
        raise ValueError(
            "the sweep repeats a value, so its continuation lanes cannot be placed on the grid: "
            "use Run.spectrum, whose rows keep them apart"
        )
    found = index.get_indexer(pandas.MultiIndex.from_arrays([values[:, i] for i in range(len(parameters))]))
    if (found < 0).any():
        raise ValueError("a continuation lane's value is not one of the sweep's")
    return found


def _column(series: pandas.Series) -> numpy.ndarray:
    """A column's numbers as they are, text as str (netCDF's strings)."""
    if series.dtype == object or pandas.api.types.is_string_dtype(series.dtype):
        return numpy.array(["" if pandas.isna(v) else str(v) for v in series], dtype=object)
    return series.to_numpy()


def _spread(series: pandas.Series, cell: tuple, shape: tuple, every_cell: bool) -> numpy.ndarray:
    """A column over the grid; a cell no lane filled (a value with fewer
    continuation lanes than another) is NaN, or "" for text; integers there
    become floats, for the NaN."""
    values = _column(series)
    if values.dtype == object:
        out = numpy.full(shape, "", dtype=object)
    elif every_cell:
        out = numpy.zeros(shape, dtype=values.dtype)
    else:
        out = numpy.full(shape, numpy.nan)
    out[cell] = values
    return out


def _attrs(run) -> dict:
    """The run's identity, as netCDF attributes (text and numbers)."""
    summary = run.summary
    attrs = {}
    for key in ("name", "system", "backend", "precision", "adapter", "lanes", "time"):
        value = summary.get(key)
        if value is not None:
            attrs[key] = value
    scene = os.path.join(run.folder, "scene.toml")
    if os.path.exists(scene):
        with open(scene, encoding="utf-8") as f:
            attrs["scene"] = f.read()
    return attrs


def _describe(dataset, every_cell: bool) -> None:
    descriptions = {
        "lambda": "the Lyapunov exponents, λ1 first, per unit time (per iteration for maps)",
        "status": "ok, or why the lane is not to be trusted (README's statuses)"
        + ("" if every_cell else "; empty where the value has no such lane"),
        "period": "the orbit's period in map iterations; NaN when aperiodic"
        + ("" if every_cell else " or where the value has no such lane"),
    }
    for name, text in descriptions.items():
        if name in dataset:
            dataset[name].attrs["description"] = text
