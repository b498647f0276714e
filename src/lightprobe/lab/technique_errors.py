"""The lab's errors for user techniques and what they name, shared by ``techniques.py`` (the NumPy path) and
``jit_techniques.py`` (the compiled loops): a module of its own, so that neither imports the other for them."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import LightprobeError

__all__ = ["TechniqueError"]


class TechniqueError(LightprobeError):
    """A user technique failed a check or could not be loaded; the message names the function and the sample."""


class _TooLong(Exception):
    """A technique's call ran past its time limit (raised by ``techniques._time_limit``'s signal handler)."""


class _RenderTimeUp(Exception):
    """The render's time limit ran out during (or before) a technique's call: the render stops and keeps the passes
    it finished, as the render core stops at its time limit."""


def _row(a: np.ndarray, i: int) -> str:
    return np.array2string(np.asarray(a[i]), precision=6, separator=", ", suppress_small=False)


_PACKAGE = Path(__file__).resolve().parents[1]


def _user_line(exc: BaseException, file: Path | None = None) -> str:
    """': line N of NAME' for the deepest frame of the traceback in ``file`` (default: any file outside
    lightprobe), or ''."""
    tb = exc.__traceback__
    found = ""
    while tb is not None:
        name = Path(tb.tb_frame.f_code.co_filename)
        mine = name.resolve() == file.resolve() if file is not None else _PACKAGE not in name.resolve().parents
        if mine and name.suffix == ".py":
            found = f": line {tb.tb_lineno}" + ("" if file is not None else f" of {name.name}")
        tb = tb.tb_next
    return found
