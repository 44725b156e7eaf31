"""lyapsweep.run against the command line: the same scene gives the same
numbers to the bit, however it is given; overrides, errors and the output
set behave as the command line's."""

import csv
import os
import subprocess
from pathlib import Path

import numpy
import pandas
import pytest

import lyapsweep
from lyapsweep._run import read_csv

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "scenes" / "impact-pair.toml"
# A few values and iterations: the tests compare bits, not accuracy.
SMALL = {
    "sweep.count": 9,
    "integration.transient": 100,
    "integration.iterations": 100,
    "run.backend": "cpu",
}


def command_line(tmp_path, scene, sets):
    """Runs the release binary on `scene` with `sets`; returns its folder."""
    binary = Path(os.environ.get("LYAPSWEEP_BIN", ROOT / "target" / "release" / "lyapsweep"))
    if not binary.exists():
        pytest.fail(f"{binary} is missing: build it with `cargo build --release` first")
    out = tmp_path / "command-line"
    args = [str(binary), "run", str(scene), "--quiet", "--out", str(out)]
    for key, value in sets.items():
        args += ["--set", f"{key}={toml_value(value)}"]
    subprocess.run(args, check=True, capture_output=True)
    return out


def toml_value(value):
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {toml_value(v)}" for k, v in value.items()) + " }"
    return str(value)


def column_as_written(path, name):
    """A column's numbers as Python reads the file's text: float() of the
    shortest text that round-trips is the number's exact bits."""
    with open(path, newline="") as f:
        return [float(row[name]) for row in csv.DictReader(f)]


def test_exponents_are_the_command_lines_to_the_bit(tmp_path):
    run = lyapsweep.run(SCENE, set=SMALL, progress=False)
    cli = command_line(tmp_path, SCENE, SMALL)

    assert (cli / "spectrum.csv").read_bytes() == (run.folder / "spectrum.csv").read_bytes()
    expected = read_csv(cli / "spectrum.csv")
    pandas.testing.assert_frame_equal(run.spectrum, expected, check_exact=True)
    for name in ["eta", "lambda_1", "lambda_2", "lambda_sum", "expected_sum"]:
        written = numpy.array(column_as_written(cli / "spectrum.csv", name))
        assert run.spectrum[name].to_numpy().view(numpy.int64).tolist() == written.view(numpy.int64).tolist()
    pandas.testing.assert_frame_equal(
        run.bifurcation,
        read_csv(cli / "bifurcation.csv"),
        check_exact=True,
    )

    assert len(run.spectrum) == 9
    assert run.spectrum["eta"].iloc[0] == 0.4 and run.spectrum["eta"].iloc[-1] == 2.0
    assert (run.spectrum["status"] == "ok").all()
    # Two exponents, both negative on these periodic orbits, summing to
    # the sum rule's value (damping and the impacts' losses) within 1e-6.
    assert (run.spectrum["lambda_1"] < 0).all()
    assert numpy.allclose(run.spectrum["lambda_sum"], run.spectrum["expected_sum"], rtol=0, atol=1e-6)
    assert run.spectrum["lambda_1"].iloc[0] == pytest.approx(-0.0920, abs=5e-3)

    assert run.summary["backend"] == "cpu"
    assert run.summary["precision"] == "f64"
    assert run.summary["lanes"] == 9
    assert run.summary["flagged"] == 0
    assert run.summary["failures"] == {}
    assert run.summary["flagged_by_status"] == {}
    assert run.summary["max_sum_error"] < 1e-6
    assert run.scene["sweep"] == {"parameter": "eta", "from": 0.4, "to": 2.0, "count": 9}
    assert run.attractors is None


def test_flagged_lanes_are_counted_by_status():
    # η = 1e-9: a forcing period beyond any step budget; its lane alone fails.
    sets = {**SMALL, "sweep": {"parameter": "eta", "values": [1e-9, 0.8]}}
    run = lyapsweep.run(SCENE, set=sets, progress=False)
    assert run.summary["flagged"] == 1
    assert run.summary["flagged_by_status"] == {"too-many-steps": 1}
    assert run.summary["failures"] == {"too-many-steps": 1}
    assert run.spectrum["status"].iloc[0].startswith("too-many-steps(")
    assert run.spectrum["status"].iloc[1] == "ok"
    assert numpy.isfinite(run.spectrum["lambda_1"].iloc[1])


def test_write_is_the_command_lines_set(tmp_path):
    run = lyapsweep.run(SCENE, set=SMALL, progress=False)
    cli = command_line(tmp_path, SCENE, SMALL)
    written = run.write(tmp_path / "written")

    assert sorted(p.name for p in written) == sorted(p.name for p in cli.iterdir())
    # The manifest lists every data file's size and SHA-256.
    assert (tmp_path / "written" / "manifest.toml").read_text() == (cli / "manifest.toml").read_text()
    # A folder holding someone else's files is refused, as by the command line.
    (tmp_path / "notes").mkdir()
    (tmp_path / "notes" / "notes.txt").write_text("mine")
    with pytest.raises(lyapsweep.SceneError, match="holds files lyapsweep does not write"):
        run.write(tmp_path / "notes")
    assert os.listdir(tmp_path / "notes") == ["notes.txt"]


def test_text_and_dict_scenes_give_the_files_numbers(tmp_path, monkeypatch):
    tomllib = pytest.importorskip("tomllib")
    from_file = lyapsweep.run(SCENE, set=SMALL, progress=False)
    # The scene's model = "../models/impact-pair.toml" is relative to the
    # current folder for text and dicts.
    monkeypatch.chdir(SCENE.parent)
    text = SCENE.read_text()
    from_text = lyapsweep.run(text, set=SMALL, progress=False)
    from_dict = lyapsweep.run(tomllib.loads(text), set=SMALL, progress=False)

    for run in (from_text, from_dict):
        pandas.testing.assert_frame_equal(run.spectrum, from_file.spectrum, check_exact=True)
        pandas.testing.assert_frame_equal(run.bifurcation, from_file.bifurcation, check_exact=True)
        assert run.scene == from_file.scene


def test_set_overrides_keys_and_a_bad_key_is_named(tmp_path):
    run = lyapsweep.run(SCENE, set={**SMALL, "sweep.count": 3, "model.parameters.zeta": 0.1}, progress=False)
    # The values are from + i·(to - from)/(count - 1).
    assert run.spectrum["eta"].tolist() == [0.4, 0.4 + 1 * (2.0 - 0.4) / 2, 2.0]
    assert run.scene["sweep"]["count"] == 3
    # The sum rule follows the damping: -2ζ per unit time without impacts.
    assert run.scene["model"]["parameters"]["zeta"] == 0.1
    assert run.spectrum["expected_sum"].iloc[0] < -0.2

    out = tmp_path / "never"
    with pytest.raises(lyapsweep.SceneError, match="unknown field `cont`") as bad:
        lyapsweep.run(SCENE, set={"sweep.cont": 5}, out=out, progress=False)
    assert bad.value.key == "sweep.cont"
    assert isinstance(bad.value, ValueError)
    with pytest.raises(lyapsweep.SceneError, match="sweep.count") as bad:
        lyapsweep.run(SCENE, set={"sweep.count": -5}, out=out, progress=False)
    assert bad.value.key == "sweep.count"
    with pytest.raises(lyapsweep.SceneError, match="unknown variant `gpux`") as bad:
        lyapsweep.run(SCENE, backend="gpux", out=out, progress=False)
    assert bad.value.key == "run.backend"
    assert not out.exists()


BAD_MODEL = {
    "model": {
        "name": "bad",
        "states": ["x", "v"],
        "parameters": {"zeta": 0.1},
        "equations": {"x": "v", "v": "-x + zeta2"},
        "map": {"period": "1"},
    },
    "sweep": {"parameter": "zeta", "values": [0.1]},
}


def test_a_malformed_model_raises_model_error_with_its_column(tmp_path):
    out = tmp_path / "never"
    with pytest.raises(lyapsweep.ModelError) as bad:
        lyapsweep.run(BAD_MODEL, out=out, progress=False)
    assert bad.value.key == "model.equations.v"
    assert bad.value.column == 6
    assert str(bad.value) == "model.equations.v: unknown name 'zeta2' (column 6)"
    assert isinstance(bad.value, lyapsweep.SceneError)
    assert not out.exists()

    with pytest.raises(lyapsweep.ModelError) as checked:
        lyapsweep.check_model(BAD_MODEL["model"])
    assert (checked.value.key, checked.value.column) == ("model.equations.v", 6)


def test_check_model_is_the_command_lines_description(tmp_path):
    model = ROOT / "models" / "impact-pair.toml"
    description = lyapsweep.check_model(model)
    assert description.startswith("model impact-pair: 2 states (x, v), parameters e = 0.8, eta = 0.8")
    assert "piecewise linear" in description
    assert lyapsweep.check_model(model.read_text()) == description
    # A scene naming its model file has that file checked.
    assert lyapsweep.check_model(SCENE) == description


def test_attractors_give_basin_fractions(tmp_path):
    sets = {
        **SMALL,
        "sweep.count": 5,
        "attractors.grid": [2, 2],
        "attractors.box": {"x": [-0.9, 0.9], "v": [-1, 1]},
        "attractors.continuation": "both",
    }
    run = lyapsweep.run(SCENE, set=sets, progress=False)
    cli = command_line(tmp_path, SCENE, sets)
    expected = read_csv(cli / "attractors.csv")
    pandas.testing.assert_frame_equal(run.attractors, expected, check_exact=True)

    basins = run.attractors.groupby("eta")["basin_fraction"].sum()
    assert basins.tolist() == [1.0] * 5
    # η = 0.4 holds two attractors, each from half of the four starts.
    assert run.attractors.loc[run.attractors["eta"] == 0.4, "basin_fraction"].tolist() == [0.5, 0.5]
    assert run.summary["attractors"] == len(run.attractors)


def test_basins_are_the_label_files_as_arrays():
    sets = {
        **SMALL,
        "sweep.count": 2,
        "attractors.grid": [6, 4],
        "attractors.box": {"x": [-0.9, 0.9], "v": [-1, 1]},
        "attractors.basins": 1,
        "attractors.basin_box": 2,
    }
    run = lyapsweep.run(SCENE, set=sets, progress=False)
    image = run.basins(0)
    assert image.shape == (4, 6) and image.dtype == numpy.int32
    assert numpy.array_equal(image, numpy.load(run.folder / "basins-0.npy"))
    # Each attractor's fraction is its share of the image's labels.
    first = run.attractors[run.attractors["eta"] == run.attractors["eta"].iloc[0]]
    first = first[first["branch"].notna()]
    for branch, fraction in zip(first["branch"], first["basin_fraction"]):
        assert (image == branch).mean() == fraction
    with pytest.raises(ValueError, match="no basin image of value 1"):
        run.basins(1)


def test_plot_without_matplotlib_says_how_to_get_it(monkeypatch):
    run = lyapsweep.run(SCENE, set={**SMALL, "sweep.count": 3}, progress=False)
    monkeypatch.setitem(__import__("sys").modules, "matplotlib", None)
    monkeypatch.setitem(__import__("sys").modules, "matplotlib.pyplot", None)
    with pytest.raises(ImportError, match="pip install matplotlib"):
        run.plot()


def test_plot_draws_the_exponents():
    pytest.importorskip("matplotlib")
    import matplotlib

    matplotlib.use("Agg")
    run = lyapsweep.run(SCENE, set=SMALL, progress=False)
    fig = run.plot()
    points, exponents = fig.axes
    assert [line.get_label() for line in exponents.get_lines()[:2]] == ["λ1", "λ2"]
    assert exponents.get_lines()[0].get_ydata().tolist() == run.spectrum["lambda_1"].tolist()
    assert len(points.get_lines()[0].get_xdata()) == len(run.bifurcation)


def test_devices_lists_adapters_as_dicts():
    for adapter in lyapsweep.devices():
        assert {"name", "backend", "f64"} <= adapter.keys()
        assert isinstance(adapter["f64"], bool)


@pytest.mark.parametrize("second", [None, {"parameter": "f", "values": [0.8, 1.0]}])
def test_orbits_and_bifurcations_are_the_files_to_the_bit(tmp_path, second):
    seed = ROOT / "scenes" / "seed-fig3.toml"
    sets = {"sweep.count": 5, "run.backend": "cpu", "orbits": {"max_points": 200}}
    if second is not None:
        # Two parameters: each row also names its value of f.
        sets["sweep.second"] = second
    run = lyapsweep.run(seed, set=sets, progress=False)
    if second is not None:
        assert list(run.orbits.columns[:3]) == ["branch", "eta", "f"]
        assert list(run.bifurcations.columns[:4]) == ["branch", "kind", "eta", "f"]
        assert set(run.orbits["f"]) == {0.8, 1.0}
    cli = command_line(tmp_path, seed, sets)
    for name, table in [("orbits.csv", run.orbits), ("bifurcations.csv", run.bifurcations)]:
        pandas.testing.assert_frame_equal(table, read_csv(cli / name), check_exact=True)
        # float() of each cell's text is the DataFrame's number, bit for bit.
        with open(cli / name, newline="") as f:
            rows = list(csv.DictReader(f))
        for column in table.columns:
            if table[column].dtype == numpy.float64:
                written = [float(r[column]) if r[column] else numpy.nan for r in rows]
                assert numpy.array_equal(written, table[column].to_numpy(), equal_nan=True), column
    assert set(run.bifurcations["kind"]) >= {"grazing"}
    assert run.summary["orbit_branches"] > 0
    assert run.summary["bifurcations"] == len(run.bifurcations)
