"""Errors and warnings meant for users.

Every exception a user can cause by bad input (a missing or corrupt file, an invalid parameter, a degenerate
scene) derives from :class:`LightprobeError`; the command-line interface prints its message on one line and
exits with status 2 instead of showing a traceback.  Anything else is a bug in lightprobe.  A C library's error
text (OpenImageIO's, libpng's) becomes one line with :func:`library_message`, and :func:`library_output_held` keeps
the library from printing its own error line beside lightprobe's.
"""

from __future__ import annotations

import contextlib
import numbers
import os
import sys
import tempfile
import warnings

import numpy as np

__all__ = [
    "ImageError",
    "LightprobeError",
    "LightprobeWarning",
    "ParameterError",
    "SceneError",
    "library_message",
    "library_output_held",
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


def _is_numeric(v) -> bool:
    if isinstance(v, list | tuple):
        return all(_is_numeric(x) for x in v)
    if isinstance(v, np.ndarray):
        return v.dtype.kind in "iuf"
    return isinstance(v, numbers.Real) and not isinstance(v, bool | np.bool_)


def numeric_array(value, what: str, error: type[LightprobeError] = ParameterError) -> np.ndarray:
    """``value`` (a number, or nested lists of numbers) as a float64 array; anything else (a string, a boolean, a
    table, a ragged list) raises ``error`` naming ``what``.  Shape and range are the caller's to check."""
    if _is_numeric(value):
        try:
            return np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            pass
    raise error(f"{what} must be a number or a list of numbers, got {value!r}")


@contextlib.contextmanager
def library_output_held():
    """Hold what C libraries write to the process's stderr (file descriptor 2) inside the block: libpng prints
    ``libpng error: ...`` there before OpenImageIO returns the same words as an error, so a corrupt file gave a
    stray line before lightprobe's one-line error.  Yields a list; the caller appends True if the read succeeded,
    and only then is the held output (a library's warnings) written out, after the block.  Python's own
    ``sys.stderr`` is flushed first, so nothing of it is held."""
    outcome: list[bool] = []
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError, AttributeError):  # no stderr to hold (closed, or None): read as it is
        yield outcome
        return
    with tempfile.TemporaryFile() as held:
        os.dup2(held.fileno(), 2)
        try:
            yield outcome
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        if outcome and outcome[0]:
            held.seek(0)
            if text := held.read():
                os.write(2, text)


def library_message(text: str, default: str) -> str:
    """An image library's error text on one line: OpenImageIO returns libpng's messages one a line, a message often
    repeated inside the next one; the distinct ones joined with '; '."""
    lines = [line.strip() for line in (text or "").splitlines() if line.strip()]
    kept = [line for line in dict.fromkeys(lines) if not any(line != other and line in other for other in lines)]
    return "; ".join(kept) or default
