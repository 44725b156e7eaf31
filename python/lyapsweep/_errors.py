"""The exceptions of the package: the command line's messages, with the key
they are about as an attribute for code that points at it."""

from __future__ import annotations

from typing import Optional


class SceneError(ValueError):
    """A scene lyapsweep cannot run, raised before anything is written.

    ``key`` is the scene key the message is about (``"sweep.count"``; for an
    override, the key ``set`` gave), or None when the message names none
    (TOML that does not parse, a file that cannot be read).
    """

    def __init__(self, message: str, *, key: Optional[str] = None, column: Optional[int] = None):
        super().__init__(message)
        self.key = key
        self.column = column


class ModelError(SceneError):
    """A model lyapsweep cannot compile: ``key`` names its key
    (``"model.equations.v"``) and ``column`` the column of the expression
    the message points at, when it points at one."""


class RunError(RuntimeError):
    """A run that failed on this machine rather than on its input: its files
    could not be written, or every lane failed (the set is written, with each
    lane's status in it, when ``out`` was given)."""

    def __init__(self, message: str, *, key: Optional[str] = None, column: Optional[int] = None):
        super().__init__(message)
        self.key = key
        self.column = column


class InterpreterWarning(RuntimeWarning):
    """A run whose model the host's C compiler did not build (none found,
    ``CC`` names none, it failed, or the host is not Unix): the CPU path ran
    it on the interpreter, to the same bits, 8 to 10 times slower. A wheel
    brings no C compiler; the command line warns on stderr likewise."""
