"""What a long run does for its caller: it releases the GIL, shows its
progress, and stops within a second on Ctrl-C, writing nothing."""

import os
import signal
import threading
import time
from pathlib import Path

import pytest

import lyapsweep
from lyapsweep import _run

ROOT = Path(__file__).resolve().parents[2]
SEED = ROOT / "scenes" / "seed-fig3.toml"
# The seed's impact oscillator on the CPU path: about 0.14 s of one core a
# lane per 1000 iterations of 1800 steps.
QUICK = {"sweep.count": 8, "integration.transient": 100, "integration.iterations": 200, "run.backend": "cpu"}


def long_run(backend):
    """Overrides that make the seed's sweep last far longer than a test
    waits (half a minute on 2 cores, longer on lavapipe)."""
    return {"sweep.count": 64, "integration.iterations": 20000, "run.backend": backend}


def require_gpu():
    """Skips a GPU test where there is no adapter with f64, except where
    CI asks for one (LYAPSWEEP_REQUIRE_GPU=1): there it fails."""
    if any(a["f64"] for a in lyapsweep.devices()):
        return
    if os.environ.get("LYAPSWEEP_REQUIRE_GPU") == "1":
        pytest.fail("LYAPSWEEP_REQUIRE_GPU=1 but no adapter with f64 was found")
    pytest.skip("no GPU adapter with f64")


def files(folder):
    return {p.name: p.read_bytes() for p in folder.iterdir()}


@pytest.mark.parametrize("backend", ["cpu", "gpu"])
def test_ctrl_c_stops_a_long_run_within_a_second_and_writes_nothing(tmp_path, backend):
    if backend == "gpu":
        require_gpu()
    out = tmp_path / "out"
    # A set already in the folder must come through whole.
    lyapsweep.run(SEED, set=QUICK, out=out, progress=False)
    before = files(out)
    sent = []

    def ctrl_c():
        sent.append(time.perf_counter())
        os.kill(os.getpid(), signal.SIGINT)

    timer = threading.Timer(1.0, ctrl_c)
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            lyapsweep.run(SEED, set=long_run(backend), out=out, progress=False)
        stopped = time.perf_counter()
    finally:
        timer.cancel()
    assert sent, "the run ended before Ctrl-C was sent"
    assert stopped - sent[0] < 1.0
    # The old set, byte for byte, and nothing staged beside it.
    assert files(out) == before
    assert [p.name for p in tmp_path.iterdir()] == ["out"]


def test_an_exception_from_the_progress_callable_stops_the_run(tmp_path):
    def fails(done, total):
        raise ValueError("the notebook's widget broke")

    out = tmp_path / "out"
    with pytest.raises(ValueError, match="widget broke"):
        lyapsweep.run(SEED, set=long_run("cpu"), out=out, progress=fails)
    assert list(tmp_path.iterdir()) == []


def test_the_gil_is_released_while_the_lanes_run():
    # About a second of lanes; the GIL held throughout would leave this
    # thread waiting that long between two of its 10 ms sleeps.
    sets = {"sweep.count": 16, "integration.iterations": 2500, "run.backend": "cpu"}
    worker = threading.Thread(target=lyapsweep.run, args=(SEED,), kwargs={"set": sets, "progress": False})
    start = time.perf_counter()
    worker.start()
    ticks = [start]
    while worker.is_alive():
        time.sleep(0.01)
        ticks.append(time.perf_counter())
    worker.join()
    assert ticks[-1] - start > 0.5, "the run was too short to tell"
    longest = max(b - a for a, b in zip(ticks, ticks[1:]))
    assert longest < 0.25


def test_a_progress_callable_follows_every_lane_iteration():
    seen = []
    sets = {**QUICK, "integration.iterations": 1000}
    lyapsweep.run(SEED, set=sets, progress=lambda done, total: seen.append((done, total)))
    # Lanes × (transient + iterations), the last call once the run is over.
    work = 8 * (100 + 1000)
    assert seen[-1] == (work, work)
    assert all(total == work for _, total in seen)
    assert all(a <= b for (a, _), (b, _) in zip(seen, seen[1:]))


class FakeTqdm:
    """Records what a tqdm bar is told."""

    made = []

    def __init__(self, total, **options):
        self.total, self.n, self.closed = total, 0, False
        FakeTqdm.made.append(self)

    def update(self, n):
        self.n += n

    def refresh(self):
        pass

    def close(self):
        self.closed = True


def test_progress_shows_a_tqdm_bar_when_tqdm_is_installed(monkeypatch):
    FakeTqdm.made.clear()
    monkeypatch.setattr(_run, "_tqdm", lambda: FakeTqdm)
    lyapsweep.run(SEED, set={**QUICK, "integration.iterations": 1000}, progress=True)
    [bar] = FakeTqdm.made
    assert (bar.n, bar.total, bar.closed) == (8 * 1100, 8 * 1100, True)


def test_progress_falls_back_to_the_command_lines_display(monkeypatch, capfd):
    monkeypatch.setattr(_run, "_tqdm", lambda: None)
    # A line at every look (stderr is not a terminal here), and a last one.
    monkeypatch.setenv("LYAPSWEEP_PROGRESS_SECONDS", "0")
    lyapsweep.run(SEED, set=QUICK, progress=True)
    assert "progress: 100% (2400 of 2400 lane-iterations)" in capfd.readouterr().err
