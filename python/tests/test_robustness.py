"""lyapsweep.run under input no scene has, threads, interrupts and fork:
each call returns a Run or raises the package's exception, a TypeError or
a ValueError; never takes the interpreter down, never hangs, never mixes
two runs' sets."""

import multiprocessing
import os
import subprocess
import sys
import threading
from pathlib import Path

import numpy
import pytest

import lyapsweep

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "scenes" / "impact-pair.toml"
TINY = {
    "sweep.count": 3,
    "integration.transient": 10,
    "integration.iterations": 10,
    "output.bifurcation_points": 5,
    "run.backend": "cpu",
}


def in_subprocess(code: str, timeout: float = 60) -> subprocess.CompletedProcess:
    """Runs `code` in a fresh interpreter: a crash there is an exit code
    here, not the end of the test run."""
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout, cwd=ROOT
    )


# ---- dicts that TOML cannot hold ------------------------------------------


def test_a_dict_nested_ten_thousand_deep_is_refused_not_a_crash():
    done = in_subprocess(
        "import lyapsweep\n"
        "d = {}\n"
        "top = d\n"
        "for _ in range(10000):\n"
        "    d['a'] = {}\n"
        "    d = d['a']\n"
        "try:\n"
        "    lyapsweep.run({'name': 'x', 'sweep': top}, progress=False)\n"
        "except ValueError as e:\n"
        "    print('refused:', e)\n"
    )
    assert done.returncode == 0, (done.returncode, done.stderr[-2000:])
    assert "refused: sweep.a.a" in done.stdout
    assert "nested deeper than 32" in done.stdout


def test_a_dict_that_holds_itself_is_refused_not_a_crash():
    done = in_subprocess(
        "import lyapsweep\n"
        "d = {'name': 'x'}\n"
        "d['sweep'] = d\n"
        "try:\n"
        "    lyapsweep.run(d, progress=False)\n"
        "except ValueError as e:\n"
        "    print('refused:', e)\n"
        "l = []\n"
        "l.append(l)\n"
        "try:\n"
        "    lyapsweep.run({'sweep': {'values': l}}, progress=False)\n"
        "except ValueError as e:\n"
        "    print('refused:', e)\n"
    )
    assert done.returncode == 0, (done.returncode, done.stderr[-2000:])
    assert "refused: sweep: holds itself (it is the dict at the top)" in done.stdout
    assert "refused: sweep.values[0]: holds itself (it is the list at sweep.values)" in done.stdout


def test_an_override_that_holds_itself_names_its_key():
    d = {}
    d["x"] = d
    with pytest.raises(ValueError, match=r"^sweep\.values\.x: holds itself"):
        lyapsweep.run(SCENE, set={"sweep.values": d}, progress=False)


# ---- threads ----------------------------------------------------------------


def test_runs_in_threads_each_write_their_own_set(tmp_path):
    counts = [3, 4, 5, 6]
    results = {}

    def one(count):
        out = tmp_path / f"set-{count}"
        results[count] = lyapsweep.run(SCENE, set={**TINY, "sweep.count": count}, out=out, progress=False)

    threads = [threading.Thread(target=one, args=(c,)) for c in counts]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for count in counts:
        assert len(results[count].spectrum) == count
        assert sorted(p.name for p in (tmp_path / f"set-{count}").iterdir()) == sorted(
            ["bifurcation.csv", "figure.png", "figure.svg", "manifest.toml", "scene.toml", "spectrum.csv"]
        )
    assert not [p.name for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_two_threads_into_one_folder_one_wins_whole(tmp_path):
    out = tmp_path / "shared"
    for attempt in range(5):
        barrier = threading.Barrier(2)
        outcome = {}

        def one(count):
            barrier.wait()
            try:
                outcome[count] = lyapsweep.run(SCENE, set={**TINY, "sweep.count": count}, out=out, progress=False)
            except lyapsweep.RunError as e:
                outcome[count] = e

        threads = [threading.Thread(target=one, args=(c,)) for c in (30, 31)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        runs = {c: r for c, r in outcome.items() if isinstance(r, lyapsweep.Run)}
        assert runs, outcome
        for count, run in runs.items():
            # Its own table, never the other thread's.
            assert len(run.spectrum) == count, (attempt, count, len(run.spectrum))
        for error in (r for r in outcome.values() if not isinstance(r, lyapsweep.Run)):
            assert "another run of this program is writing it" in str(error)
        # Whatever is in the folder is one whole set.
        names = sorted(p.name for p in out.iterdir())
        assert names == ["bifurcation.csv", "figure.png", "figure.svg", "manifest.toml", "scene.toml", "spectrum.csv"]
        assert not [p.name for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_a_long_out_name_is_written(tmp_path):
    # 240 bytes is a legal name; its staging folder's name was not.
    out = tmp_path / ("o" * 240)
    run = lyapsweep.run(SCENE, set=TINY, out=out, progress=False)
    assert len(run.spectrum) == 3
    assert (out / "manifest.toml").exists()


# ---- interrupts after the lanes ---------------------------------------------


def test_an_exception_after_the_lanes_lands_nothing_or_says_the_set_was_written(tmp_path):
    out = tmp_path / "out"
    lyapsweep.run(SCENE, set={**TINY, "sweep.count": 4}, out=out, progress=False)

    def stop_when_done(done, total):
        # Once the lanes have finished: while the set is written (a tick),
        # or after the swap (the last report always comes then).
        if total and done == total:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt) as stopped:
        lyapsweep.run(SCENE, set=TINY, out=out, progress=stop_when_done)
    rows = len((out / "spectrum.csv").read_text().splitlines())
    if hasattr(stopped.value, "lyapsweep_written"):
        # After the swap: the new set (3 values) replaced the previous one
        # (4), as the exception says.
        written = stopped.value.lyapsweep_written
        assert sorted(Path(p).name for p in written) == [
            "bifurcation.csv", "figure.png", "figure.svg", "manifest.toml", "scene.toml", "spectrum.csv"
        ]
        assert rows == 1 + 3
        if sys.version_info >= (3, 11):
            assert any("the new set was written to" in n for n in stopped.value.__notes__)
    else:
        # While the set was written: a stop, the previous set whole.
        assert rows == 1 + 4
    assert not [p.name for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_an_exception_during_the_lanes_writes_nothing(tmp_path):
    out = tmp_path / "out"

    def stop_at_once(done, total):
        raise RuntimeError("stop")

    with pytest.raises(RuntimeError, match="stop") as stopped:
        lyapsweep.run(
            SCENE,
            set={**TINY, "integration.iterations": 200000, "sweep.count": 2},
            out=out,
            progress=stop_at_once,
        )
    assert not hasattr(stopped.value, "lyapsweep_written")
    assert not out.exists()


# ---- fork ---------------------------------------------------------------------


def _tiny_run(_):
    return len(lyapsweep.run(SCENE, set=TINY, progress=False).spectrum)


def test_workers_forked_after_a_run_run():
    lyapsweep.run(SCENE, set=TINY, progress=False)
    fork = multiprocessing.get_context("fork")
    with fork.Pool(2) as pool:
        result = pool.map_async(_tiny_run, range(2))
        assert result.get(timeout=60) == [3, 3]


# ---- the minor ones ---------------------------------------------------------


def test_progress_that_is_neither_bool_nor_callable_is_refused():
    with pytest.raises(TypeError, match="progress is True, False or a callable"):
        lyapsweep.run(SCENE, set=TINY, progress=42)


def test_set_as_a_list_of_pairs_applies_in_order():
    run = lyapsweep.run(SCENE, set=[*TINY.items(), ("sweep.count", 2)], progress=False)
    assert len(run.spectrum) == 2
    with pytest.raises(TypeError, match=r"set\[0\] is not a \(key, value\) pair"):
        lyapsweep.run(SCENE, set=[("sweep.count",)], progress=False)
    with pytest.raises(TypeError, match="set is a dict"):
        lyapsweep.run(SCENE, set="sweep.count=3", progress=False)


@pytest.mark.parametrize("dtype", ["float64", "float32", "int64", "int32", "uint16"])
def test_sweep_values_as_a_numpy_array(dtype):
    values = numpy.array([1, 2], dtype=dtype)
    sweep = {"parameter": "eta", "values": values}
    run = lyapsweep.run(SCENE, set={**TINY, "sweep": sweep}, progress=False)
    assert run.spectrum["eta"].tolist() == [1.0, 2.0]


def test_numpy_scalars_of_every_numeric_dtype():
    for dtype in ["int8", "int16", "int32", "int64", "uint8", "uint64"]:
        value = numpy.dtype(dtype).type(2)
        run = lyapsweep.run(SCENE, set={**TINY, "sweep.count": value}, progress=False)
        assert len(run.spectrum) == 2, dtype
    for dtype in ["float16", "float32", "float64", "longdouble"]:
        value = numpy.dtype(dtype).type(1.5)
        run = lyapsweep.run(SCENE, set={**TINY, "sweep.to": value}, progress=False)
        assert run.spectrum["eta"].iloc[-1] == 1.5, dtype


def test_numpy_values_with_no_toml_value_are_refused_by_key():
    with pytest.raises(TypeError, match=r"^sweep\.values: a numpy array of bool has no TOML value"):
        lyapsweep.run(SCENE, set={"sweep.values": numpy.array([True, False])}, progress=False)
    with pytest.raises(TypeError, match=r"^sweep\.from: a numpy complex128 has no TOML value"):
        lyapsweep.run(SCENE, set={"sweep.from": numpy.complex128(1j)}, progress=False)
    with pytest.raises(ValueError, match=r"^sweep\.count: an integer beyond 64 bits"):
        lyapsweep.run(SCENE, set={"sweep.count": numpy.uint64(2**64 - 1)}, progress=False)


def test_a_path_str_with_an_equals_sign_is_a_path(tmp_path, monkeypatch):
    folder = tmp_path / "a=b"
    folder.mkdir()
    scene = folder / "scene.toml"
    scene.write_text(SCENE.read_text().replace("../models/", str(ROOT / "models") + "/"))
    run = lyapsweep.run(str(scene), set=TINY, progress=False)
    assert len(run.spectrum) == 3
    # Named but missing: still a path, and the message says so.
    with pytest.raises(lyapsweep.SceneError, match="missing=1.toml"):
        lyapsweep.run(str(tmp_path / "missing=1.toml"), progress=False)
    # An existing file without the ending.
    plain = tmp_path / "k=v"
    plain.write_text(scene.read_text())
    assert len(lyapsweep.run(str(plain), set=TINY, progress=False).spectrum) == 3


def test_plot_draws_a_run_without_exponents():
    pytest.importorskip("matplotlib")
    import matplotlib

    matplotlib.use("Agg")
    run = lyapsweep.run(SCENE, set={**TINY, "output.lyapunov": "none"}, progress=False)
    assert run.spectrum is None
    fig = run.plot()
    (points,) = fig.axes
    assert len(points.get_lines()[0].get_xdata()) == len(run.bifurcation)
    assert points.get_xlabel() == "eta"


def test_messages_name_the_keyword_not_the_command_lines_option():
    with pytest.raises(lyapsweep.SceneError) as bad:
        lyapsweep.run(SCENE, set={"sweep.count": "many"}, progress=False)
    assert "--set" not in str(bad.value)
    assert bad.value.key == "sweep.count"
    with pytest.raises(lyapsweep.SceneError) as bad:
        lyapsweep.run(SCENE, set={"sweep.nope.deeper": 1}, progress=False)
    assert "--set" not in str(bad.value), str(bad.value)
    assert 'set["sweep.nope.deeper"] = 1' in str(bad.value) or "sweep.nope" in str(bad.value)
    with pytest.raises(lyapsweep.SceneError) as bad:
        lyapsweep.run(SCENE, backend="gpux", progress=False)
    assert "--set" not in str(bad.value), str(bad.value)
