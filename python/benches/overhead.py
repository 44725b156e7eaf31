"""The Python package's overhead against the command line on the seed's
sweep: each round runs `lyapsweep run` and a Python process calling
`lyapsweep.run` (the interpreter, imports, the DataFrames read back, all
counted) on the same scene, alternating, and prints each round's wall times
and the median ratio.

    python python/benches/overhead.py [--rounds 3] [--set KEY=VALUE ...]

Run from the checkout's root after `cargo build --release` and
`pip install ./python`, on an otherwise idle machine."""

import argparse
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "scenes" / "seed-fig3.toml"
BINARY = Path(os.environ.get("LYAPSWEEP_BIN", ROOT / "target" / "release" / "lyapsweep"))

PYTHON_RUN = """
import sys, lyapsweep
sets = dict(kv.split("=", 1) for kv in sys.argv[3:])
sets = {k: float(v) if "." in v else int(v) for k, v in sets.items()}
run = lyapsweep.run(sys.argv[1], out=sys.argv[2], set=sets, progress=False)
assert len(run.spectrum) == run.summary["lanes"]
print(run.summary["time"])
"""


def timed(args):
    start = time.perf_counter()
    done = subprocess.run(args, check=True, capture_output=True, text=True)
    return time.perf_counter() - start, done.stdout


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--set", action="append", default=[], help="KEY=VALUE (numbers only)")
    options = parser.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
          f"Python {platform.python_version()}; scene {SCENE.name} {' '.join(options.set)}")
    cli_sets = [a for kv in options.set for a in ("--set", kv)]
    ratios = []
    with tempfile.TemporaryDirectory() as scratch:
        for r in range(options.rounds):
            cli, _ = timed([str(BINARY), "run", str(SCENE), "-q", "--out", f"{scratch}/cli"] + cli_sets)
            py, lanes_time = timed([sys.executable, "-c", PYTHON_RUN, str(SCENE), f"{scratch}/py"] + options.set)
            ratios.append(py / cli)
            print(f"round {r + 1}: command line {cli:.2f} s, Python {py:.2f} s "
                  f"(its lanes {float(lanes_time):.2f} s), ratio {py / cli:.3f}")
    print(f"median ratio Python / command line: {statistics.median(ratios):.3f}")


if __name__ == "__main__":
    main()
