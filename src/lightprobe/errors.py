"""Errors and warnings meant for users.

Every exception a user can cause by bad input (a missing or corrupt file, an invalid parameter, a degenerate
scene) derives from :class:`LightprobeError`; the command-line interface prints its message on one line and
exits with status 2 instead of showing a traceback.  Anything else is a bug in lightprobe.
"""

from __future__ import annotations

__all__ = ["ImageError", "LightprobeError", "LightprobeWarning", "ParameterError", "SceneError"]


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
