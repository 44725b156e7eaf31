"""The package as installed: its version is the library's, and without a
C compiler a run gives the same bits on the interpreter, with a warning
that says so."""

import json
import os
import re
import subprocess
import sys
import warnings
from importlib import metadata
from pathlib import Path

import lyapsweep

ROOT = Path(__file__).resolve().parents[2]
# A scene with a model file: its equations are what the C compiler builds.
SCENE = ROOT / "scenes" / "impact-pair.toml"
TINY = {
    "sweep.count": 5,
    "integration.transient": 20,
    "integration.iterations": 40,
    "run.backend": "cpu",
}


def crate_version(manifest: Path) -> str:
    """The `version` of a Cargo.toml's [package] table."""
    package = re.search(r"^\[package\]\n(.*?)(?=^\[)", manifest.read_text(), re.S | re.M)
    return re.search(r'^version\s*=\s*"([^"]+)"', package.group(1), re.M).group(1)


def test_the_version_is_the_library_s_and_the_installed_distribution_s():
    library = crate_version(ROOT / "Cargo.toml")
    assert lyapsweep.__version__ == library
    # The wheel's version is the Python crate's (maturin reads it).
    assert crate_version(ROOT / "python" / "Cargo.toml") == library
    assert metadata.version("lyapsweep") == library


def test_without_a_c_compiler_the_interpreter_gives_the_same_bits_and_a_warning(tmp_path):
    # A PATH with no `cc` on it, no CC, and a cache of built code of its
    # own (one built earlier with a compiler would be loaded from the cache).
    empty = tmp_path / "bin"
    empty.mkdir()
    env = {k: v for k, v in os.environ.items() if k != "CC"}
    env.update(PATH=str(empty), XDG_CACHE_HOME=str(tmp_path / "cache"))
    code = (
        "import json, sys, warnings, lyapsweep\n"
        "with warnings.catch_warnings(record=True) as caught:\n"
        "    warnings.simplefilter('always')\n"
        f"    run = lyapsweep.run({str(SCENE)!r}, set={TINY!r}, progress=False, out=sys.argv[1])\n"
        "print(json.dumps([[w.category.__name__, str(w.message), w.filename] for w in caught]))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code, str(tmp_path / "interpreted")],
        env=env, capture_output=True, text=True, timeout=120,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    caught = json.loads(done.stdout.splitlines()[-1])
    assert len(caught) == 1, caught
    category, message, filename = caught[0]
    assert category == "InterpreterWarning"
    assert "did not build the model's native code" in message and "interpreter" in message
    assert "cc: No such file or directory" in message
    assert "The results are the same to the bit" in message
    # Pointed at the caller's line, not the package's.
    assert filename == "<string>"

    with warnings.catch_warnings():
        warnings.simplefilter("error", lyapsweep.InterpreterWarning)
        compiled = lyapsweep.run(SCENE, set=TINY, progress=False, out=tmp_path / "compiled")
    assert compiled.summary["interpreter_fallback"] is None
    interpreted = (tmp_path / "interpreted" / "spectrum.csv").read_bytes()
    assert interpreted == (tmp_path / "compiled" / "spectrum.csv").read_bytes()
    assert (tmp_path / "interpreted" / "bifurcation.csv").read_bytes() == (
        tmp_path / "compiled" / "bifurcation.csv"
    ).read_bytes()
