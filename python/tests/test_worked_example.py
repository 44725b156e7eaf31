"""docs/python.md's worked example, run as written on fewer values: its
code works, and its numbers are the ones the page describes."""

import math
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "python.md"


def test_the_worked_example_runs_and_finds_what_the_page_says(tmp_path, monkeypatch):
    blocks = re.findall(r"```python\n(.*?)```", PAGE.read_text(), re.S)
    code = "\n".join(blocks)
    # 31 values of η (0.05 apart) instead of 301, without a progress bar.
    assert '"count": 301' in code and 'lyapsweep.run(scene, backend="cpu")' in code
    code = code.replace('"count": 301', '"count": 31')
    code = code.replace('backend="cpu")', 'backend="cpu", progress=False)')
    monkeypatch.chdir(tmp_path)
    scope = {}
    exec(compile(code, str(PAGE), "exec"), scope)
    assert (tmp_path / "wall-oscillator.png").stat().st_size > 0

    run, attractors = scope["run"], scope["attractors"]
    assert run.summary["flagged"] == 0
    assert run.summary["max_sum_error"] < 1e-6
    # The orbit that misses the wall: the linear oscillator's exponents,
    # only where its amplitude is below the wall (η > √2), and beside the
    # impacting orbit at η = 1.6.
    free = attractors[attractors["impacts_per_period"] == 0]
    assert len(free) > 0
    assert (free["eta"] > math.sqrt(2)).all()
    assert ((free["lambda_1"] + 0.05).abs() < 1e-4).all()
    assert ((free["lambda_2"] + 0.05).abs() < 1e-4).all()
    at = attractors[(attractors["eta"] - 1.6).abs() < 1e-9]
    assert sorted(at["impacts_per_period"]) == [0.0, 1.0]
