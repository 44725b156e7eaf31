"""The minimal critical shock of the seed's two orbits at eta = 0.6, checked
by brute force on a finer grid.

The tool's `critical_shock` is the nearest start of another basin on the
basin image's grid, in the box's scaled max norm. Here each orbit's square
of that radius (plus two coarse cells) is covered again by a grid FINER
times finer, clipped to the box, and the nearest start of another basin is
taken from that grid's labels. Usage:

    python3 docs/bench-shock/check.py LYAPSWEEP [COARSE] [FINER]
"""

import csv
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

BOX = {"x": (-3.0, 1.9), "v": (-3.0, 3.0)}
WIDTH = {k: hi - lo for k, (lo, hi) in BOX.items()}
SCENE = """name = "seed-shock"
[system]
kind = "impact-oscillator"
zeta = 0.05
f = 1.0
wall = 2.0
restitution = 1.0
[sweep]
parameter = "eta"
from = 0.6
to = 0.6
count = 1
[integration]
steps_per_period = 1800
transient = 200
iterations = 8
initial_state = [0.0, 0.0]
[run]
backend = "cpu"
[output]
lyapunov = "none"
bifurcation_points = 8
[attractors]
grid = [{nx}, {nv}]
box = {{ x = [{x0!r}, {x1!r}], v = [{v0!r}, {v1!r}] }}
basins = 1
max_period = 4
"""


def run(binary, nx, nv, box, out):
    out.mkdir(parents=True)
    scene = out / "scene.toml"
    scene.write_text(
        SCENE.format(nx=nx, nv=nv, x0=box["x"][0], x1=box["x"][1], v0=box["v"][0], v1=box["v"][1])
    )
    subprocess.run([binary, "run", "-q", str(scene), "--out", str(out / "run")], check=True, stdout=subprocess.DEVNULL)
    with open(out / "run" / "attractors.csv") as f:
        rows = [r for r in csv.DictReader(f) if r["branch"]]
    labels = np.load(out / "run" / "basins-0.npy")
    return rows, labels


def axis(lo, hi, n):
    # As the tool places a grid's starts: corners included, the last exact.
    a = lo + np.arange(n) * (hi - lo) / (n - 1)
    a[-1] = hi
    return a


def nearest_other(labels, box, label, point):
    ny, nx = labels.shape
    x, v = np.meshgrid(axis(*box["x"], nx), axis(*box["v"], ny))
    d = np.maximum(abs(x - point[0]) / WIDTH["x"], abs(v - point[1]) / WIDTH["v"])
    other = (labels != label) & (labels >= 0)
    return d[other].min() if other.any() else None


def main():
    binary = sys.argv[1]
    coarse = int(sys.argv[2]) if len(sys.argv) > 2 else 128
    finer = int(sys.argv[3]) if len(sys.argv) > 3 else 4
    cell = 1.0 / (coarse - 1)
    with tempfile.TemporaryDirectory() as tmp:
        rows, labels = run(binary, coarse, coarse, BOX, Path(tmp) / "coarse")
        print(f"coarse grid {coarse} x {coarse}, a cell {cell:.5f} of the box")
        print("| orbit (impacts) | point (x, v) | critical_shock | recomputed | finer grid | fine starts | fine shock | difference |")
        print("|---|---|---|---|---|---|---|---|")
        for row in rows:
            label, point = int(row["branch"]), (float(row["x"]), float(row["v"]))
            shock = float(row["critical_shock"])
            again = nearest_other(labels, BOX, label, point)
            reach = shock + 2 * cell
            box = {
                k: (max(lo, p - reach * WIDTH[k]), min(hi, p + reach * WIDTH[k]))
                for (k, (lo, hi)), p in zip(BOX.items(), point)
            }
            n = {k: int(round((hi - lo) / WIDTH[k] / cell * finer)) + 1 for k, (lo, hi) in box.items()}
            fine_rows, fine = run(binary, n["x"], n["v"], box, Path(tmp) / f"fine-{label}")
            # The same orbit in the fine run: the attractor nearest the point.
            match = min(
                fine_rows,
                key=lambda r: abs(float(r["x"]) - point[0]) + abs(float(r["v"]) - point[1]),
            )
            fine_shock = nearest_other(fine, box, int(match["branch"]), point)
            print(
                f"| {label} ({row['impacts_per_period']}) | ({point[0]:.6f}, {point[1]:.6f}) | {shock:.5f} | {again:.5f} "
                f"| {n['x']} x {n['v']} | {n['x'] * n['v']} | {fine_shock:.5f} | {shock - fine_shock:.5f} |"
            )


if __name__ == "__main__":
    main()
