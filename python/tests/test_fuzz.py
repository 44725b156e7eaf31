"""Property tests of the Python entry: whatever a caller passes (dicts of any
shape and depth, numpy's scalars and arrays, nan and inf, str, bytes,
None, nested lists), ``lyapsweep.run`` returns a Run or raises one of the
package's exceptions, a TypeError or a ValueError: it never crashes and
never hangs. The scenes are tiny, or fail validation before any work."""

from datetime import timedelta
from pathlib import Path

import numpy
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, example, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from hypothesis.extra import numpy as hnp  # noqa: E402

import lyapsweep  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "scenes" / "impact-pair.toml"
TINY = {
    "sweep.count": 2,
    "integration.transient": 5,
    "integration.iterations": 5,
    "output.bifurcation_points": 2,
    "run.backend": "cpu",
}
# What the package documents it raises (SceneError and ModelError are
# ValueErrors, RunError a RuntimeError).
DOCUMENTED = (lyapsweep.SceneError, lyapsweep.RunError, TypeError, ValueError)
# Each example is a tiny run at most: a hang is a failure, not a slow test.
SETTINGS = settings(
    max_examples=60,
    deadline=timedelta(seconds=20),
    suppress_health_check=[HealthCheck.too_slow],
    database=None,
)

NUMERIC_DTYPES = ["int8", "int16", "int32", "int64", "uint8", "uint16", "uint32", "uint64",
                  "float16", "float32", "float64"]
OTHER_DTYPES = ["bool", "complex64", "complex128", "datetime64[s]", "timedelta64[s]", "U3", "S3"]

# A numpy scalar of each dtype (`array[()]` is the scalar, not a 0-d array).
numpy_scalars = st.sampled_from(NUMERIC_DTYPES + OTHER_DTYPES).flatmap(
    lambda d: hnp.from_dtype(numpy.dtype(d)).map(lambda x: numpy.array(x, dtype=d)[()])
)
numpy_arrays = hnp.arrays(
    dtype=st.sampled_from(NUMERIC_DTYPES + ["bool", "complex128", "U2"]).map(numpy.dtype),
    shape=hnp.array_shapes(min_dims=0, max_dims=3, max_side=4),
)
scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=20),
    st.binary(max_size=10),
    numpy_scalars,
    numpy_arrays,
)
# Keys a scene has, and any others.
KEYS = ["name", "model", "system", "sweep", "integration", "output", "run", "parameter", "from",
        "to", "count", "values", "transient", "iterations", "lyapunov", "backend", "precision"]
keys = st.one_of(st.sampled_from(KEYS), st.text(max_size=8))
values = st.recursive(
    scalars,
    lambda inner: st.one_of(
        st.lists(inner, max_size=4),
        st.tuples(inner, inner),
        st.dictionaries(keys, inner, max_size=4),
    ),
    max_leaves=20,
)


def outcome(call):
    """A Run, or the documented exception the call raised."""
    try:
        result = call()
    except DOCUMENTED as e:
        return e
    assert isinstance(result, lyapsweep.Run)
    return result


@SETTINGS
@given(scene=st.one_of(st.dictionaries(keys, values, max_size=6), values))
def test_any_scene_returns_or_raises_what_is_documented(scene):
    outcome(lambda: lyapsweep.run(scene, set={"run.backend": "cpu"}, progress=False))


def nested(depth, leaf, kind):
    """`leaf` inside `depth` dicts (or lists)."""
    for _ in range(depth):
        leaf = {"a": leaf} if kind == "dict" else [leaf]
    return leaf


@SETTINGS
@given(
    key=st.sampled_from(["sweep.count", "sweep.from", "sweep.to", "integration.transient",
                         "integration.iterations", "output.lyapunov", "output.bifurcation_points",
                         "model.parameters.zeta", "name", "sweep", "run.precision"]),
    value=st.one_of(values, numpy_scalars, st.integers(-3, 5), st.floats(-1, 3)),
)
# Negative damping that pumps energy in between impacts faster than they take
# it out: the flights shrink until a period holds hundreds of thousands of
# impacts, and the lane stops at the bound on events (it once ran for hours).
@example(key="model.parameters.zeta", value=-300460)
def test_any_override_of_a_tiny_scene_returns_or_raises_what_is_documented(key, value):
    outcome(lambda: lyapsweep.run(SCENE, set={**TINY, key: value}, progress=False))


@SETTINGS
@given(depth=st.integers(0, 3000), kind=st.sampled_from(["dict", "list"]), leaf=scalars)
def test_values_nested_at_any_depth_are_refused_or_run(depth, kind, leaf):
    got = outcome(lambda: lyapsweep.run({"sweep": nested(depth, leaf, kind)}, progress=False))
    assert not isinstance(got, lyapsweep.Run)
    if depth > 40:
        assert "nested deeper than" in str(got)


@SETTINGS
@given(values=st.one_of(
    hnp.arrays(dtype=st.sampled_from(NUMERIC_DTYPES).map(numpy.dtype), shape=st.integers(1, 3)),
    st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=1, max_size=3),
))
def test_numeric_sweep_values_run_or_name_the_key(values):
    # nan and inf among the values: refused by key, never run.
    sweep = {"parameter": "eta", "values": values}
    got = outcome(lambda: lyapsweep.run(SCENE, set={**TINY, "sweep": sweep}, progress=False))
    if isinstance(got, lyapsweep.Run):
        assert len(got.spectrum) == len(values)
    elif isinstance(got, lyapsweep.SceneError):
        # A key: the value itself, or what it makes of the model (eta = 0).
        assert got.key is not None, got


@SETTINGS
@given(text=st.one_of(st.text(max_size=60), st.just("a=" * 40), st.just("[" * 5000)))
def test_any_text_returns_or_raises_what_is_documented(text):
    outcome(lambda: lyapsweep.run(text, progress=False))
