"""Sampling techniques written by users, in plain Python: the contract, loading them from a file, and calling them
safely.

A *technique* draws directions at a batch of shading points and says how dense they are::

    class CosineHemisphere:
        kind = "bsdf"            # "bsdf": directions in the local shading frame (normal +z, wo toward the viewer)
                                 # "light": directions toward the environment map, in world space
        dimensions = 2           # random numbers per sample: 1, 2 or 3 (under sobol the first two are one pair)
        support = "hemisphere"   # bsdf only: "hemisphere" (never below the surface) or "sphere" (a lobe may dip
                                 # below it, like a Phong lobe about the mirror direction)

        def sample(self, u, ctx):      # u: (N, dimensions) in [0, 1)
            ...
            return wi, pdf             # (N, 3) unit directions, (N,) density per steradian (0: no sample)

        def pdf(self, wi, ctx):        # the density with which sample() produces wi, (N,)
            ...

Arrays in, arrays out: one call serves a whole batch (NumPy; the methods may call ``numba.njit`` functions for
speed). ``ctx`` (:class:`Context`) describes the batch's shading points; a batch shares one material. An optional
``prepare(self, environment)`` is called once per environment map before a light technique is used (build the
map's distributions there, not in every call).

:func:`load_technique` reads ``FILE.py[:NAME]``; :class:`GuardedTechnique` calls a technique and turns every way it
can go wrong (an exception, NaN or Inf, a negative pdf, the wrong shape or dtype, non-unit directions, a call that
takes too long) into one :class:`TechniqueError` naming the function, the check and the first offending sample.
lightprobe's own techniques behind the same contract, and the :class:`Context` a technique sees, are
:mod:`lightprobe.integrators.batch_estimator`'s (:func:`builtin` guards them like a user's).
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.util
import inspect
import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from ..integrators.batch_estimator import Context, EnvironmentSampling, MaterialSampling
from . import jit_techniques as jt
from .jit_techniques import JitTechnique, jit_functions, technique_data
from .technique_errors import TechniqueError, _RenderTimeUp, _row, _TooLong, _user_line

__all__ = [
    "KINDS",
    "Context",
    "GuardedTechnique",
    "TechniqueError",
    "direction_to_uv",
    "load_technique",
    "uv_to_direction",
]

KINDS = ("bsdf", "light")
SUPPORTS = ("hemisphere", "sphere")
#: |wi| may differ from 1 by this much
UNIT_TOLERANCE = 1e-4
#: seconds one call may take before it is stopped (per batch; batches hold at most a few hundred thousand samples)
DEFAULT_TIME_LIMIT = 60.0


# --- lat-long coordinates (the README's convention, Mitsuba 3's) ----------------------------------------------------
def uv_to_direction(environment, u, v) -> np.ndarray:
    """World directions (N, 3) of lat-long coordinates (u, v) in [0, 1]^2 of ``environment`` (its rotation applied):
    theta = pi v from +Y, phi = 2 pi u, local (sin phi sin theta, cos theta, -cos phi sin theta)."""
    theta = np.pi * np.asarray(v, dtype=np.float64)
    phi = 2.0 * np.pi * np.asarray(u, dtype=np.float64)
    st = np.sin(theta)
    local = np.stack([np.sin(phi) * st, np.cos(theta), -np.cos(phi) * st], axis=-1)
    rotation = np.eye(3) if environment is None else environment.to_world
    return local @ rotation.T


def direction_to_uv(environment, dirs) -> tuple[np.ndarray, np.ndarray]:
    """Lat-long (u, v) of world directions (N, 3): the inverse of :func:`uv_to_direction`."""
    rotation = np.eye(3) if environment is None else environment.to_world
    local = np.asarray(dirs, dtype=np.float64) @ rotation
    u = np.mod(np.arctan2(local[:, 0], -local[:, 2]) / (2.0 * np.pi), 1.0)
    v = np.arccos(np.clip(local[:, 1], -1.0, 1.0)) / np.pi
    return u, v


# --- loading ----------------------------------------------------------------------------------------------------
def _is_technique(obj) -> bool:
    return callable(getattr(obj, "sample", None)) and callable(getattr(obj, "pdf", None)) and not inspect.ismodule(obj)


def _module_techniques(module) -> dict[str, object]:
    return {
        name: obj
        for name, obj in vars(module).items()
        if not name.startswith("_")
        and _is_technique(obj)
        and getattr(obj, "__module__", module.__name__) == module.__name__
    }


#: the modules imported by :func:`load_module` in this process, by (resolved path, SHA-256 of the file's bytes)
_IMPORTED: dict[tuple[str, str], object] = {}


def load_module(path: str | Path, *, what: str = "technique file"):
    """Import a user's Python file; a missing file, an error while importing it or an import that would end the
    program (``sys.exit``, ``os._exit``, a crash) is one line naming the file.

    A file imported before in this process with the same bytes is not imported again: the module of that import is
    returned, with its njit functions and what Numba compiled for them (a notebook that checks or compares the same
    file again, or the laboratory's commands in one process, compile nothing twice; decisions.md 139). A file whose
    bytes changed is imported anew. Like Python's own ``import``, the files it imports are not reloaded."""
    file = Path(path)
    if not file.is_file():
        raise TechniqueError(f"{file}: no such {what}")
    try:
        key = (str(file.resolve()), hashlib.sha256(file.read_bytes()).hexdigest())
    except OSError as exc:
        raise TechniqueError(f"{file}: cannot read the {what}: {exc.strerror or exc}") from None
    if key in _IMPORTED:
        return _IMPORTED[key]
    module = _import_file(file, what)
    _IMPORTED[key] = module
    return module


def _import_file(file: Path, what: str):
    """:func:`load_module`'s import of ``file``, every time it is called."""
    name = f"lightprobe_user_{abs(hash(str(file.resolve())))}"
    spec = importlib.util.spec_from_file_location(name, file)
    if spec is None or spec.loader is None:
        raise TechniqueError(f"{file}: not a Python file")
    ended = _ends_the_process(spec)
    if ended is not None:
        raise TechniqueError(f"{file}: importing it {ended}; a {what} must not end the program")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except SyntaxError as exc:
        raise TechniqueError(f"{file}: line {exc.lineno}: syntax error: {exc.msg}") from None
    except SystemExit as exc:  # sys.exit(), exit(): it would end lightprobe with the file's status, silently
        raise TechniqueError(
            f"{file}{_user_line(exc, file)}: importing it ended the program (sys.exit({exc.code!r})); a {what} "
            "must not end the program"
        ) from None
    except Exception as exc:  # the user's code: any error it raises on import is reported, not a traceback
        raise TechniqueError(
            f"{file}{_user_line(exc, file)}: importing it raised {type(exc).__name__}: {exc}"
        ) from None
    return module


def _ends_the_process(spec) -> str | None:
    """Import the file of ``spec`` in a forked child first: how the import ended the child's whole process, which
    no ``except`` can catch (``os._exit``, a fatal signal, a crash in a C extension), or None when it returned or
    raised (the caller's own import then reports the raise). The child's output goes nowhere: the caller's import
    prints what the file prints, once. A fork of this process costs 10-20 ms (decisions.md 102); where there is no
    fork, the caller's import is the only one."""
    if not hasattr(os, "fork"):
        return None
    read, write = os.pipe()
    try:
        pid = os.fork()
    except OSError:  # no room for another process: import in this one only
        os.close(read)
        os.close(write)
        return None
    if pid == 0:  # the child: never return into the caller's code, never run its exit handlers
        try:
            os.close(read)
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, 1)
            os.dup2(devnull, 2)
            try:
                spec.loader.exec_module(importlib.util.module_from_spec(spec))
            except BaseException:  # a raise or sys.exit: the caller's own import reports it
                pass
            os.write(write, b"returned")
        finally:
            os._exit(0)
    os.close(write)
    try:
        with os.fdopen(read, "rb") as said:
            returned = said.read() == b"returned"
        _, status = os.waitpid(pid, 0)
    except BaseException:  # Ctrl-C while the child imports: end it too
        with contextlib.suppress(OSError):
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
        raise
    if returned:
        return None
    if os.WIFSIGNALED(status):
        return f"killed the process ({signal.Signals(os.WTERMSIG(status)).name})"
    return f"ended the whole process (exit status {os.waitstatus_to_exitcode(status)}, as os._exit does)"


def load_technique(spec: str, *, time_limit: float = DEFAULT_TIME_LIMIT) -> GuardedTechnique:
    """The technique ``FILE.py:NAME`` (``FILE.py`` alone when the file defines exactly one): a class is
    instantiated without arguments, an instance (or any object with ``sample`` and ``pdf``) used as it is."""
    file, name = (spec, "") if spec.endswith(".py") or ":" not in spec else spec.rsplit(":", 1)
    module = load_module(file)
    found = _module_techniques(module)
    if name:
        if not hasattr(module, name):
            listed = ", ".join(found) or "none"
            raise TechniqueError(f"{file}: no technique named {name!r} (techniques found: {listed})")
        obj = getattr(module, name)
        if not _is_technique(obj):
            raise TechniqueError(f"{file}: {name} is not a technique: it needs sample(u, ctx) and pdf(wi, ctx) methods")
    else:
        if len(found) != 1:
            listed = ", ".join(found) or "none"
            raise TechniqueError(f"{file}: name one technique as {file}:NAME (techniques found: {listed})")
        name, obj = next(iter(found.items()))
    if inspect.isclass(obj):
        try:
            obj = obj()
        except (Exception, SystemExit) as exc:  # a sys.exit() in the user's code must not end lightprobe
            raise TechniqueError(f"{file}:{name}: creating it raised {type(exc).__name__}: {exc}") from None
    return GuardedTechnique(obj, f"{Path(file).name}:{name}", time_limit=time_limit)


# --- calling a technique safely -----------------------------------------------------------------------------------
@contextmanager
def _time_limit(seconds: float):
    """Raise _TooLong in the main thread after ``seconds`` (SIGALRM); elsewhere, no limit."""
    if not (seconds and seconds > 0) or threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        raise _TooLong

    previous = signal.signal(signal.SIGALRM, handler)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, previous)


class RenderClock:
    """A render's time limit as the user techniques it calls see it: the seconds left, not counting what Numba
    spends compiling or loading machine code meanwhile (lightprobe's kernels on their first use, the loops around
    njit techniques), as the render core starts its clock only after warming up its stages. Use it as a context
    manager: the compile timer listens while it is open."""

    def __init__(self, time_limit: float | None):
        from numba.core import event

        self.time_limit = time_limit
        self.start = time.perf_counter()
        # Numba takes its global compiler lock around every compile and every load from its cache
        self._compiling = event.TimingListener()
        self._listening = event.install_listener("numba:compiler_lock", self._compiling)

    def __enter__(self) -> RenderClock:
        self._listening.__enter__()
        self.start = time.perf_counter()
        return self

    def __exit__(self, *exc) -> None:
        self._listening.__exit__(*exc)

    def seconds_spent(self) -> float:
        """Seconds since the render started, Numba's compiling and loading not counted."""
        compiling = self._compiling.duration if self._compiling.done else 0.0
        return time.perf_counter() - self.start - compiling

    def seconds_left(self) -> float | None:
        """Seconds before the limit (None without one); a :class:`_RenderTimeUp` once it has passed."""
        if self.time_limit is None:
            return None
        left = self.time_limit - self.seconds_spent()
        if left <= 0.0:
            raise _RenderTimeUp
        return left


class GuardedTechnique:
    """A technique whose every call is checked: see the module docstring."""

    #: the clock of the render that calls the technique (set by ``render_lab`` for a render), or None: a call is
    #: stopped at the earlier of the render's time limit and the technique's own ``time_limit``
    clock: RenderClock | None = None

    def __init__(self, technique, label: str, *, time_limit: float = DEFAULT_TIME_LIMIT):
        self.user = technique
        self.label = label
        self.time_limit = time_limit
        #: (sample, pdf) as numba.njit functions of one sample (the laboratory's compiled estimator calls them), or
        #: None: a NumPy technique, called a batch at a time
        self.jit = jit_functions(technique, label)
        # what every call goes through: the technique itself, or the NumPy contract around its njit functions
        self.technique = technique if self.jit is None else JitTechnique(technique, label, self.jit)
        #: the user's njit functions, whose loops compile before a call's time limit starts
        self._compiled_loops = isinstance(self.technique, JitTechnique)
        #: lightprobe's own technique (``builtin``), whose njit twins have cached loops
        self.builtin = False
        self.kind = getattr(technique, "kind", "bsdf")
        if self.kind not in KINDS:
            raise TechniqueError(f"{label}: kind must be one of {KINDS}, got {self.kind!r}")
        self.dimensions = getattr(technique, "dimensions", 2)
        if not isinstance(self.dimensions, int) or not 1 <= self.dimensions <= 3:
            raise TechniqueError(f"{label}: dimensions must be 1, 2 or 3, got {self.dimensions!r}")
        self.support = getattr(technique, "support", "hemisphere" if self.kind == "bsdf" else "sphere")
        if self.support not in SUPPORTS:
            raise TechniqueError(f"{label}: support must be one of {SUPPORTS}, got {self.support!r}")
        self._prepared: set[int] = set()

    def __repr__(self) -> str:
        return f"GuardedTechnique({self.label}, kind={self.kind})"

    def data(self) -> tuple:
        """What njit code sees as ``ctx.data``: the technique's ``data`` attribute, a tuple (after ``prepare``)."""
        return technique_data(self.user, self.label)

    def _call(self, method: str, check: str, args, first_input: np.ndarray, input_name: str):
        fn = getattr(self.technique, method)
        render_ends_first = False
        try:
            if self._compiled_loops and method in ("sample", "pdf"):
                self.technique.compile(method, *args)  # before the time limit: compiling is not the technique's time
            limit, left = self.time_limit, None if self.clock is None else self.clock.seconds_left()
            if left is not None and not (limit and 0 < limit <= left):
                limit, render_ends_first = left, True
            with _time_limit(limit):
                return fn(*args)
        except _TooLong:
            if render_ends_first:  # the render's time is up, not the technique's: the render stops, no error
                raise _RenderTimeUp from None
            raise TechniqueError(
                f"{self.label}.{method}: took longer than {self.time_limit:g} s on a batch of {len(first_input)} "
                f"(check: time limit; first sample {input_name} = {_row(first_input, 0)})"
            ) from None
        except (TechniqueError, _RenderTimeUp):
            raise
        except (Exception, SystemExit) as exc:  # a sys.exit() in the user's code must not end lightprobe
            line = _user_line(exc).lstrip(": ") or "no line"
            raise TechniqueError(
                f"{self.label}.{method} raised {type(exc).__name__}: {exc} ({line}; "
                f"check: {check}; batch of {len(first_input)}, first sample {input_name} = {_row(first_input, 0)})"
            ) from None

    def prepare(self, environment) -> None:
        hook = getattr(self.technique, "prepare", None)
        if hook is None or environment is None or id(environment) in self._prepared:
            return
        self._call("prepare", "prepare", (environment,), np.zeros((1, 1)), "environment")
        self._prepared.add(id(environment))

    def _array(self, value, shape: tuple, method: str, what: str, inputs, input_name: str) -> np.ndarray:
        """``value`` as float64 of ``shape``, or an error naming the problem and the first offending sample."""
        where = f"{self.label}.{method}"
        try:
            a = np.asarray(value)
        except Exception as exc:
            raise TechniqueError(f"{where}: {what} is not an array ({exc})") from None
        if a.dtype == object or not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)):
            raise TechniqueError(f"{where}: {what} has dtype {a.dtype}, expected float (check: shape and dtype)")
        if len(shape) == 1 and a.shape == (shape[0], 1):
            a = a[:, 0]
        if a.shape != shape:
            raise TechniqueError(
                f"{where}: {what} has shape {a.shape}, expected {shape} (check: shape and dtype; a batch of "
                f"{shape[0]} went in)"
            )
        a = a.astype(np.float64)
        bad = ~np.isfinite(a) if a.ndim == 1 else ~np.all(np.isfinite(a), axis=1)
        if bad.any():
            i = int(np.argmax(bad))
            raise TechniqueError(
                f"{where}: {what} is not finite at sample {i} ({_row(a, i)}) (check: finite values; "
                f"{input_name} = {_row(inputs, i)}; {int(bad.sum())} of {shape[0]} samples)"
            )
        return a

    def sample(self, u: np.ndarray, ctx: Context) -> tuple[np.ndarray, np.ndarray]:
        """Checked ``sample``: (wi (N, 3), pdf (N,)), finite, unit where pdf > 0, pdf >= 0."""
        n = u.shape[0]
        if self.kind == "light":
            self.prepare(ctx.environment)
        out = self._call("sample", "sample runs", (u, ctx), u, "u")
        if not isinstance(out, tuple | list) or len(out) != 2:
            raise TechniqueError(f"{self.label}.sample must return (wi, pdf), got {type(out).__name__}")
        wi = self._array(out[0], (n, 3), "sample", "wi", u, "u")
        pdf = self._array(out[1], (n,), "sample", "pdf", u, "u")
        self._nonnegative(pdf, "sample", u, "u")
        norm = np.linalg.norm(wi, axis=1)
        bad = (np.abs(norm - 1.0) > UNIT_TOLERANCE) & (pdf > 0)
        if bad.any():
            i = int(np.argmax(bad))
            raise TechniqueError(
                f"{self.label}.sample: wi is not a unit vector at sample {i}: |wi| = {norm[i]:.6g} "
                f"(check: unit directions; u = {_row(u, i)}, wi = {_row(wi, i)}; {int(bad.sum())} of {n} samples)"
            )
        return wi, pdf

    def pdf(self, wi: np.ndarray, ctx: Context) -> np.ndarray:
        """Checked ``pdf``: (N,), finite, >= 0."""
        if self.kind == "light":
            self.prepare(ctx.environment)
        out = self._call("pdf", "pdf runs", (wi, ctx), wi, "wi")
        pdf = self._array(out, (wi.shape[0],), "pdf", "the result", wi, "wi")
        self._nonnegative(pdf, "pdf", wi, "wi")
        return pdf

    def _nonnegative(self, pdf, method, inputs, input_name) -> None:
        bad = pdf < 0.0
        if bad.any():
            i = int(np.argmax(bad))
            raise TechniqueError(
                f"{self.label}.{method}: negative pdf {pdf[i]:.6g} at sample {i} (check: pdf >= 0; "
                f"{input_name} = {_row(inputs, i)}; {int(bad.sum())} of {len(pdf)} samples)"
            )


def builtin(kind: str) -> GuardedTechnique:
    """lightprobe's technique of ``kind`` ("bsdf" or "light"), guarded like a user's: its NumPy methods for batch
    calls, its njit twins (the same kernels) for the laboratory's compiled estimator."""
    obj = MaterialSampling() if kind == "bsdf" else EnvironmentSampling()
    guarded = GuardedTechnique(obj, "lightprobe:" + ("brdf" if kind == "bsdf" else "env"), time_limit=0.0)
    guarded.builtin = True
    guarded.jit = (
        (jt.builtin_bsdf_sample, jt.builtin_bsdf_pdf) if kind == "bsdf" else (jt.builtin_env_sample, jt.builtin_env_pdf)
    )
    return guarded


#: a MIS heuristic: weight(n_f, p_f, n_g, p_g) of a sample of technique f (n_f samples) against technique g
Heuristic = Callable[[float, np.ndarray, float, np.ndarray], np.ndarray]
