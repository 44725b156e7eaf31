"""lyapsweep: Lyapunov spectra and bifurcation diagrams of non-smooth
oscillators, swept over thousands of parameter values.

``run(scene)`` runs a scene (a file, TOML text or a dict) as the command
line's ``lyapsweep run`` does and returns a ``Run`` whose ``spectrum``,
``bifurcation`` and ``attractors`` are pandas DataFrames of the CSV files'
numbers, to the bit. ``check_model`` and ``devices`` are ``lyapsweep model
check`` and ``lyapsweep devices``. Errors are the command line's messages,
raised as ``SceneError`` (a ValueError) or ``ModelError`` with the key.
``Run.to_xarray()`` labels the tables by the swept parameters (the extra
``lyapsweep[xarray]``). ``__version__`` is the library's.
"""

from ._errors import InterpreterWarning, ModelError, RunError, SceneError
from ._lyapsweep import __version__
from ._model import check_model, devices
from ._run import Run, run

__all__ = [
    "run",
    "Run",
    "check_model",
    "devices",
    "SceneError",
    "ModelError",
    "RunError",
    "InterpreterWarning",
    "__version__",
]
