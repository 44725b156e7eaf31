"""Lyapunov spectra of the Lorenz and Rössler flows and the Hénon map from
lyapsweep and from the Python tools people use for them, all in one run on
one machine: each estimate's error against the published exponents and the
time it took.

    pip install ./python -r python/benches/peers-requirements.txt
    python python/benches/peers.py [--quick] [--csv FILE]

The tools:

- lyapsweep: `lyapsweep.run` on the system's time-T map (Lorenz T = 0.2 as
  scenes/lorenz.toml, Rössler T = 1, both RK4 at dt = 0.01) or on the map
  itself (Hénon); central differences of perturbed copies, QR every period.
  Time: the whole call (the scene read, the run, its files written).
- jitcode's `jitcode_lyap`: the variational equations generated with
  SymEngine, compiled to C, integrated by `dopri5` (scipy, adaptive); the
  local exponents of each unit of time averaged, as jitcode's documentation
  does. Orthonormalising every 10 units (its example's interval) breaks the
  Lorenz spectrum (λ3 comes out near -2.9: e^(15.5 * 10) is beyond f64), so
  every 1. Time: the integration; compiling the C code (each run) is
  given apart.
- nolds' `lyap_e` (Eckmann et al.'s method) on a scalar time series: the
  Hénon map's x, the flows' x sampled every 0.05 (integrated here with
  scipy's DOP853 at rtol 1e-10, not counted in the time); embedding 2
  and matrix 2 for Hénon, 5 and 3 for the flows. Its cost grows as the
  square of the series' length.
- dysts: the estimates stored in its catalogue (`lyapunov_spectrum_estimated`
  and `maximum_lyapunov_estimated`); with --dysts-live also its
  `find_lyapunov_exponents` run here (a backward-Euler step on a sampled
  trajectory, a Python loop: minutes without numba). dysts' Lorenz has
  β = 2.667, not 8/3. It has no Hénon estimate.

The published exponents (J. C. Sprott, Chaos and Time-Series Analysis,
Oxford University Press 2003, Appendix A; with their rounding an error
below 5e-5 (Lorenz, Rössler) or 5e-6 (Hénon) is not resolved): Lorenz
(σ = 10, ρ = 28, β = 8/3) 0.9056, 0, -14.5723; Rössler (a = b = 0.2,
c = 5.7) 0.0714, 0, -5.3943; Hénon (a = 1.4, b = 0.3) 0.41922, -1.62319.

The seed's impact oscillator is not among them: jitcode integrates smooth
ODEs without events or state resets, dysts' catalogue has no impacting
system, and nolds would need a time series from another integrator that
handles the wall.
"""

import argparse
import csv
import importlib.metadata
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

PUBLISHED = {
    "lorenz": [0.9056, 0.0, -14.5723],
    "rossler": [0.0714, 0.0, -5.3943],
    "henon": [0.41922, -1.62319],
}
SIGMA, RHO, BETA = 10.0, 28.0, 8.0 / 3.0
A, B, C = 0.2, 0.2, 5.7


def lorenz(state):
    x, y, z = state
    return [SIGMA * (y - x), x * (RHO - z) - y, x * y - BETA * z]


def rossler(state):
    x, y, z = state
    return [-y - z, x + A * y, B + z * (x - C)]


FLOWS = {"lorenz": (lorenz, [1.0, 1.0, 1.0]), "rossler": (rossler, [1.0, 1.0, 1.0])}


def henon_series(n, transient=1000):
    x = y = 0.0
    out = np.empty(n)
    for i in range(transient + n):
        x, y = 1.0 - 1.4 * x * x + y, 0.3 * x
        if i >= transient:
            out[i - transient] = x
    return out


# --- lyapsweep ---------------------------------------------------------------

def lyapsweep_scene(system, length):
    """The scene of `system` over `length` units of time (iterations for
    Hénon), after a transient of 100 (1000 iterations)."""
    if system == "henon":
        return {"name": "henon", "system": {"kind": "henon", "a": 1.4, "b": 0.3},
                "integration": {"transient": 1000, "iterations": int(length),
                                "initial_state": [0.0, 0.0]}}
    if system == "lorenz":
        period = 0.2
        model = {"system": {"kind": "lorenz", "sigma": SIGMA, "rho": RHO, "beta": BETA,
                            "period": period}}
    else:
        period = 1.0
        model = {"model": {
            "name": "rossler", "states": ["x", "y", "z"],
            "parameters": {"a": A, "b": B, "c": C, "period": period},
            "equations": {"x": "-y - z", "y": "x + a*y", "z": "b + z*(x - c)"},
            "map": {"period": "period"}}}
    return {"name": system, **model,
            "integration": {"steps_per_period": round(period / 0.01),
                            "transient": round(100 / period),
                            "iterations": round(length / period),
                            "initial_state": [1.0, 1.0, 1.0]}}


def run_lyapsweep(system, length):
    import lyapsweep

    scene = lyapsweep_scene(system, length)
    start = time.perf_counter()
    run = lyapsweep.run(scene, backend="cpu", progress=False)
    elapsed = time.perf_counter() - start
    row = run.spectrum.iloc[0]
    n = len(PUBLISHED[system])
    return [float(row[f"lambda_{i + 1}"]) for i in range(n)], elapsed, None


# --- jitcode -----------------------------------------------------------------

def run_jitcode(system, length):
    # A new jitcode_lyap each run: one that has integrated refuses a second
    # set_initial_value (it then counts the tangent vectors as states).
    from jitcode import jitcode_lyap, y

    start = time.perf_counter()
    ode = jitcode_lyap(FLOWS[system][0]([y(0), y(1), y(2)]), n_lyap=3, verbose=False)
    ode.compile_C()
    compiled = time.perf_counter() - start
    ode.set_integrator("dopri5")
    ode.set_initial_value(np.array(FLOWS[system][1]), 0.0)
    start = time.perf_counter()
    ode.integrate(100.0)
    local = [ode.integrate(100.0 + t)[1] for t in np.arange(1.0, length + 1.0, 1.0)]
    elapsed = time.perf_counter() - start
    return list(np.mean(local, axis=0)), elapsed, f"+ {compiled:.1f} s compiling"


# --- nolds -------------------------------------------------------------------

def flow_series(system, n, dt=0.05):
    from scipy.integrate import solve_ivp

    f, start = FLOWS[system]
    settle = solve_ivp(lambda t, s: f(s), (0, 100), start, method="DOP853", rtol=1e-10, atol=1e-10)
    times = dt * np.arange(n)
    path = solve_ivp(lambda t, s: f(s), (0, times[-1]), settle.y[:, -1], method="DOP853",
                     t_eval=times, rtol=1e-10, atol=1e-10)
    return path.y[0], dt


def run_nolds(system, n):
    import nolds

    if system == "henon":
        series, dt, emb, dim = henon_series(n), 1.0, 2, 2
    else:
        (series, dt), emb, dim = flow_series(system, n), 5, 3
    start = time.perf_counter()
    exponents = nolds.lyap_e(series, emb_dim=emb, matrix_dim=dim, tau=dt)
    elapsed = time.perf_counter() - start
    return list(exponents), elapsed, None


# --- dysts -------------------------------------------------------------------

DYSTS_NAMES = {"lorenz": "Lorenz", "rossler": "Rossler"}


def dysts_stored(system):
    import dysts

    data = Path(dysts.__file__).parent / "data" / "chaotic_attractors.json"
    entry = json.loads(data.read_text())[DYSTS_NAMES[system]]
    return entry["lyapunov_spectrum_estimated"], entry["maximum_lyapunov_estimated"]


def run_dysts(system, length):
    import dysts.flows
    from dysts.analysis import find_lyapunov_exponents

    model = getattr(dysts.flows, DYSTS_NAMES[system])()
    start = time.perf_counter()
    exponents = find_lyapunov_exponents(model, int(length), pts_per_period=100)
    elapsed = time.perf_counter() - start
    return list(exponents), elapsed, None


# --- the table ---------------------------------------------------------------

def errors(system, exponents):
    published = PUBLISHED[system]
    first = abs(exponents[0] - published[0])
    if len(exponents) < len(published):
        return first, None
    return first, max(abs(e - p) for e, p in zip(exponents, published))


def versions():
    out = {"python": platform.python_version()}
    for name in ("lyapsweep", "jitcode", "symengine", "nolds", "dysts", "numpy", "scipy"):
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = "absent"
    try:
        out["cc"] = subprocess.run(["cc", "--version"], capture_output=True, text=True).stdout.splitlines()[0]
    except (OSError, IndexError):
        out["cc"] = "absent"
    return out


def cpu():
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def plan(quick, dysts_live):
    """(system, tool, setting, length, function) in the order they run."""
    flows = (1e3, 1e4) if quick else (1e3, 1e4, 1e5)
    rows = []
    for system in ("lorenz", "rossler"):
        rows += [(system, "lyapsweep", f"T = {t:g}", t, run_lyapsweep) for t in flows]
        rows += [(system, "jitcode_lyap", f"T = {t:g}", t, run_jitcode) for t in flows]
        rows += [(system, "nolds lyap_e", f"{n} samples", n, run_nolds) for n in (2000, 5000)]
        if dysts_live:
            rows.append((system, "dysts find_lyapunov_exponents", "1000 points", 1000, run_dysts))
    maps = (1e4, 1e5) if quick else (1e4, 1e5, 1e6)
    rows += [("henon", "lyapsweep", f"{n:g} iterations", n, run_lyapsweep) for n in maps]
    rows += [("henon", "nolds lyap_e", f"{n} samples", n, run_nolds) for n in (2000, 5000)]
    return rows


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--quick", action="store_true", help="leave out the longest runs")
    parser.add_argument("--dysts-live", action="store_true",
                        help="also run dysts' find_lyapunov_exponents (minutes without numba)")
    parser.add_argument("--csv", help="write the rows to this file too")
    options = parser.parse_args()
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"machine: {cpu()}, {os.cpu_count()} cores, load {load:.1f} at the start")
    print("versions: " + ", ".join(f"{k} {v}" for k, v in versions().items()))
    print()
    header = ["system", "tool", "setting", "exponents", "error λ1", "error, all", "time s", "note"]
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    table = []

    def emit(row):
        table.append(row)
        print("| " + " | ".join(str(c) for c in row) + " |", flush=True)

    for system, tool, setting, length, function in plan(options.quick, options.dysts_live):
        try:
            exponents, elapsed, note = function(system, length)
        except Exception as e:  # a peer that fails is a row, not the end of the table
            emit([system, tool, setting, "failed", "", "", "", f"{type(e).__name__}: {e}"])
            continue
        first, worst = errors(system, exponents)
        emit([system, tool, setting, ", ".join(f"{e:.5g}" for e in exponents), f"{first:.2g}",
              "" if worst is None else f"{worst:.2g}", f"{elapsed:.2f}", note or ""])
    for system in ("lorenz", "rossler"):
        spectrum, largest = dysts_stored(system)
        first, worst = errors(system, spectrum)
        emit([system, "dysts (stored)", "lyapunov_spectrum_estimated",
              ", ".join(f"{e:.5g}" for e in spectrum), f"{first:.2g}", f"{worst:.2g}", "", ""])
        emit([system, "dysts (stored)", "maximum_lyapunov_estimated", f"{largest:.5g}",
              f"{abs(largest - PUBLISHED[system][0]):.2g}", "", "", ""])
    if options.csv:
        with open(options.csv, "w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(header)
            writer.writerows(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
