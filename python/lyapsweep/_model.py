"""A model checked, and the adapters: ``lyapsweep model check`` and
``lyapsweep devices`` from Python."""

from __future__ import annotations

import os
from typing import Any, Mapping, Union

from . import _lyapsweep
from ._run import _source


def check_model(model: Union[str, "os.PathLike[str]", Mapping[str, Any]]) -> str:
    """Parses and compiles a model and returns its description, as
    ``lyapsweep model check`` prints it: its equations, the derivatives the
    sum rule uses, its events, what each backend runs and the generated
    WGSL.

    ``model`` is a path (a scene naming its model file has that file
    checked), TOML text or a dict: a ``[model]`` table, or the model's keys
    at the top. A problem raises ``ModelError`` with the command line's
    message, its ``key`` and, in an expression, its ``column``.
    """
    description, _named = _lyapsweep.check_model(_source(model))
    return description


def devices() -> list:
    """The GPU adapters wgpu finds, as ``lyapsweep devices`` lists them:
    one dict each (name, backend, device_type, f64, timestamps,
    exact_rounding, max_storage_binding and max_buffer in bytes,
    max_workgroups). ``WGPU_BACKEND`` restricts them."""
    return _lyapsweep.devices()
