"""Errors and warnings meant for users.

Every exception a user can cause by bad input (a missing or corrupt file, an invalid parameter, a degenerate
scene) derives from :class:`LightprobeError`; the command-line interface prints its message on one line and
exits with status 2 instead of showing a traceback.  Anything else is a bug in lightprobe.
"""

from __future__ import annotations

import numbers
import warnings

import numpy as np

__all__ = [
    "ImageError",
    "LightprobeError",
    "LightprobeWarning",
    "ParameterError",
    "SceneError",
    "numeric_array",
    "warn_once",
]


class LightprobeError(Exception):
    """Base class of user-facing errors; the message is one line and names the file or parameter at fault."""


class ImageError(LightprobeError):
    """An image (environment map, output) cannot be read, written or used."""


class SceneError(LightprobeError):
    """A scene description or mesh is invalid."""


class ParameterError(LightprobeError, ValueError):
    """An argument is out of range or of the wrong kind (also a ``ValueError``)."""


class LightprobeWarning(UserWarning):
    """Something was repaired on the way in (e.g. negative radiance clamped to zero)."""


_warned: set[str] = set()


def warn_once(message: str) -> None:
    """Warn ``message`` (a :class:`LightprobeWarning` that names its file) once per process.

    A file can be read along several paths in one run (a map resampled from angular, a scene loaded twice, a
    mesh shared by two objects); the user hears about each problem of each file once.  Python's own ``once``
    filters key on the caller's line, which differs between those paths, so they cannot do this.
    """
    if message in _warned:
        return
    _warned.add(message)
    warnings.warn(message, LightprobeWarning, stacklevel=3)


def numeric_array(value, what: str, error: type[LightprobeError] = ParameterError) -> np.ndarray:
    """``value`` (a number, or nested lists of numbers) as a float64 array; anything else (a string, a boolean, a
    table, a ragged list) raises ``error`` naming ``what``.  Shape and range are the caller's to check."""

    def is_numeric(v) -> bool:
        if isinstance(v, list | tuple):
            return all(is_numeric(x) for x in v)
        if isinstance(v, np.ndarray):
            return v.dtype.kind in "iuf"
        return isinstance(v, numbers.Real) and not isinstance(v, bool | np.bool_)

    if is_numeric(value):
        try:
            return np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            pass
    raise error(f"{what} must be a number or a list of numbers, got {value!r}")
