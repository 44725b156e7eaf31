"""Run.to_xarray and Run.write_netcdf: the run's tables labelled by the
swept parameters, the start and the exponent, every value the CSV file's
to the bit, in a netCDF file that reads back the same; and without
xarray, an ImportError that names the extra."""

import csv
import math
import sys
from pathlib import Path

import numpy
import pytest
import xarray

import lyapsweep

ROOT = Path(__file__).resolve().parents[2]
SEED = ROOT / "scenes" / "seed-fig3.toml"
MAP = ROOT / "scenes" / "million-map.toml"
# The seed's sweep from a 2 × 2 grid of starts, continued both ways: the
# values differ in how many continuation lanes they get, so the grid has
# cells no lane fills.
SEED_ATTRACTORS = {
    "sweep.count": 6,
    "integration.steps_per_period": 200,
    "integration.transient": 100,
    "integration.iterations": 200,
    "attractors.grid": [2, 2],
    "attractors.box": {"x": [-3, 1.9], "v": [-3, 3]},
    "attractors.continuation": "both",
    "output.bifurcation_points": 5,
    "run.backend": "cpu",
}
# The million-lane map at 5 × 4.
SMALL_MAP = {
    "sweep.count": 5,
    "sweep.second.count": 4,
    "integration.steps_per_period": 100,
    "integration.transient": 20,
    "integration.iterations": 40,
    "run.backend": "cpu",
}


def rows_as_written(path):
    """The file's rows, each field as its text."""
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def bits(x):
    """A number's bits (all NaNs alike), to compare to the bit."""
    return "nan" if math.isnan(x) else numpy.float64(x).view(numpy.int64).item()


def number(text):
    """A field as Python reads its text: float() of the shortest text that
    round-trips is the number's exact bits; an empty field is NaN."""
    return math.nan if text == "" else float(text)


def assert_cell_is_the_row(cell, row, exponents):
    """One cell of the dataset (a dataset indexed down to one lane) holds
    the row's every field."""
    for k in range(1, exponents + 1):
        assert bits(float(cell["lambda"].sel(exponent=k))) == bits(number(row[f"lambda_{k}"])), k
    for name, text in row.items():
        if name.startswith("lambda_") and name[7:].isdigit():
            continue
        if name in cell.coords:
            assert bits(float(cell[name])) == bits(number(text)), name
        elif name == "status":
            assert str(cell[name].item()) == text
        else:
            assert bits(float(cell[name])) == bits(number(text)), name


def test_the_seed_sweep_with_attractors_is_labelled_to_the_bit(tmp_path):
    run = lyapsweep.run(SEED, set=SEED_ATTRACTORS, progress=False)
    ds = run.to_xarray()
    rows = rows_as_written(run.folder / "spectrum.csv")
    starts = 4
    widest = max(int(r["start"]) for r in rows) + 1
    assert widest > starts, "the scene must have continuation lanes"

    assert dict(ds.sizes) == {"eta": 6, "start": widest, "exponent": 2}
    assert ds["lambda"].dims == ("eta", "start", "exponent")
    for name in ["status", "period", "branch", "lambda_sum", "expected_sum", "lambda_error"]:
        assert ds[name].dims == ("eta", "start"), name
    # The coordinates: the sweep's values in its order (the first rows,
    # one per value and start), the starts, the exponents' numbers.
    first = [number(r["eta"]) for r in rows[: 6 * starts : starts]]
    assert [bits(x) for x in ds["eta"].values] == [bits(x) for x in first]
    assert ds["start"].values.tolist() == list(range(widest))
    assert ds["exponent"].values.tolist() == [1, 2]

    # Every row is its cell; every other cell is empty.
    filled = numpy.zeros((6, widest), dtype=bool)
    for row in rows:
        i = first.index(number(row["eta"]))
        s = int(row["start"])
        assert not filled[i, s]
        filled[i, s] = True
        assert_cell_is_the_row(ds.isel(eta=i, start=s), row, 2)
    assert not filled.all(), "the scene must leave cells no lane fills"
    assert (ds["status"].values[~filled] == "").all()
    assert numpy.isnan(ds["lambda"].values[~filled]).all()
    assert numpy.isnan(ds["period"].values[~filled]).all()

    # The attractors: a row each, the file's to the bit.
    found = run.to_xarray("attractors")
    attractor_rows = rows_as_written(run.folder / "attractors.csv")
    assert dict(found.sizes) == {"attractor": len(attractor_rows), "exponent": 2}
    for a, row in enumerate(attractor_rows):
        assert_cell_is_the_row(found.isel(attractor=a), row, 2)

    # The netCDF file reads back the same, the attractors in their group.
    path = run.write_netcdf(tmp_path / "seed.nc")
    assert path == tmp_path / "seed.nc"
    with xarray.open_dataset(path) as back:
        xarray.testing.assert_identical(back.load(), ds)
    with xarray.open_dataset(path, group="attractors") as back:
        xarray.testing.assert_identical(back.load(), found)


def test_a_two_parameter_map_is_a_grid_of_its_parameters_to_the_bit(tmp_path):
    run = lyapsweep.run(MAP, set=SMALL_MAP, progress=False)
    ds = run.to_xarray()
    rows = rows_as_written(run.folder / "grid.csv")
    assert len(rows) == 20

    assert dict(ds.sizes) == {"eta": 5, "f": 4, "exponent": 2}
    assert ds["lambda"].dims == ("eta", "f", "exponent")
    assert ds["status"].dims == ("eta", "f") and ds["period"].dims == ("eta", "f")
    # The grid's rows have the first parameter fastest.
    assert [bits(x) for x in ds["eta"].values] == [bits(number(r["eta"])) for r in rows[:5]]
    assert [bits(x) for x in ds["f"].values] == [bits(number(r["f"])) for r in rows[::5]]
    assert ds["eta"].values[0] == 0.5 and ds["eta"].values[-1] == 1.5
    assert ds["f"].values[0] == 0.5 and ds["f"].values[-1] == 2.5
    for r, row in enumerate(rows):
        assert_cell_is_the_row(ds.isel(eta=r % 5, f=r // 5), row, 2)
    with pytest.raises(ValueError, match=r"\[attractors\]"):
        run.to_xarray("attractors")

    path = run.write_netcdf(tmp_path / "map.nc")
    with xarray.open_dataset(path) as back:
        xarray.testing.assert_identical(back.load(), ds)


def test_a_sweep_keeps_its_order_and_its_repeated_values(tmp_path):
    # Downwards, with a value twice: the coordinate is the sweep as run,
    # neither sorted nor merged.
    scene = {
        "name": "repeated",
        "system": {"kind": "impact-oscillator"},
        "sweep": {"parameter": "eta", "values": [1.2, 0.8, 0.8, 0.6]},
        "integration": {"transient": 10, "iterations": 20, "steps_per_period": 100},
        "run": {"backend": "cpu"},
    }
    run = lyapsweep.run(scene, progress=False)
    ds = run.to_xarray()
    assert ds["eta"].values.tolist() == [1.2, 0.8, 0.8, 0.6]
    assert dict(ds.sizes) == {"eta": 4, "exponent": 2}
    for i, row in enumerate(rows_as_written(run.folder / "spectrum.csv")):
        assert_cell_is_the_row(ds.isel(eta=i), row, 2)


def test_a_run_without_exponents_has_nothing_to_label():
    run = lyapsweep.run(
        SEED,
        set={"sweep.count": 3, "integration.transient": 10, "integration.iterations": 20,
             "output.lyapunov": "none", "output.bifurcation_points": 5, "run.backend": "cpu"},
        progress=False,
    )
    with pytest.raises(ValueError, match=r"output\.lyapunov"):
        run.to_xarray()
    with pytest.raises(ValueError, match="spectrum"):
        run.to_xarray("orbits")


def test_without_xarray_the_error_names_the_extra(tmp_path, monkeypatch):
    run = lyapsweep.run(SEED, set=SMALL_SEED, progress=False)
    # A module set to None in sys.modules is one `import` cannot find.
    monkeypatch.setitem(sys.modules, "xarray", None)
    with pytest.raises(ImportError) as raised:
        run.to_xarray()
    message = str(raised.value)
    assert "Run.to_xarray()" in message and "pip install 'lyapsweep[xarray]'" in message
    assert raised.value.name == "xarray"
    with pytest.raises(ImportError, match=r"lyapsweep\[xarray\]"):
        run.write_netcdf(tmp_path / "x.nc")
    assert not (tmp_path / "x.nc").exists()


def test_without_h5netcdf_nothing_is_written_and_the_error_names_the_extra(tmp_path, monkeypatch):
    run = lyapsweep.run(SEED, set=SMALL_SEED, progress=False)
    monkeypatch.setitem(sys.modules, "h5netcdf", None)
    with pytest.raises(ImportError) as raised:
        run.write_netcdf(tmp_path / "x.nc")
    assert "h5netcdf" in str(raised.value) and "pip install 'lyapsweep[xarray]'" in str(raised.value)
    assert not (tmp_path / "x.nc").exists()
    # The dataset itself needs no engine.
    assert dict(run.to_xarray().sizes) == {"eta": 3, "exponent": 2}


SMALL_SEED = {
    "sweep.count": 3,
    "integration.steps_per_period": 100,
    "integration.transient": 10,
    "integration.iterations": 20,
    "run.backend": "cpu",
}
