"""Techniques written as ``numba.njit`` functions: the context they see, and the compiled loops that call them.

A technique whose ``sample`` and ``pdf`` are ``numba.njit`` functions is called one sample at a time, inside
compiled loops, instead of once per batch::

    class CosineJit:
        kind = "bsdf"
        dimensions = 2
        support = "hemisphere"

        @staticmethod
        @numba.njit
        def sample(u, ctx):          # u: (dimensions,) float64, one sample's numbers
            r, phi = np.sqrt(u[0]), 2.0 * np.pi * u[1]
            z = np.sqrt(max(0.0, 1.0 - u[0]))
            return (r * np.cos(phi), r * np.sin(phi), z), z / np.pi   # wi: a 3-tuple or a (3,) array; pdf

        @staticmethod
        @numba.njit
        def pdf(wi, ctx):            # wi: (3,) float64
            return max(wi[2], 0.0) / np.pi

``ctx`` is a :class:`JitContext`, one shading point: ``wo``, ``normal``, ``position`` ((3,) arrays), ``frame``
((3, 3), rows s, t, n in world space), ``material`` (a named tuple of the material's parameters, e.g. a Phong's
``rho_d``, ``rho_s`` ((3,) arrays), ``exponent``, ``diffuse_probability``, and for every material ``kind`` and
``params``, the block lightprobe's kernels read: :func:`material_record`), ``environment``
(:class:`EnvironmentRecord`: ``luminance`` (H, W), ``radiance`` (H, W, 3), ``to_world`` (3, 3) and ``kernel``,
lightprobe's own arrays for its map sampling: an empty tuple in the context of a user's technique) and ``data``:
the technique's ``data`` attribute, a tuple of arrays and numbers (empty when it has none), read after
``prepare(environment)`` has run, which is where a light technique builds its distributions (in NumPy, once per
map).

:class:`JitTechnique` gives such a technique the NumPy contract (arrays in, arrays out; what ``check`` and the
laboratory's NumPy estimator call) through one compiled loop per method. An exception raised inside the user's
function is found again sample by sample and re-raised by running that sample's call in Python
(``py_func``), so the error names the user's line and the sample, as for a NumPy technique. Numba compiles the loop
for each function it is given (and for each material type): a few seconds on the first call of a process, not
cached on disk (a function passed as an argument cannot be).
"""

from __future__ import annotations

import inspect
import itertools
import queue
import re
import threading
import time
import weakref
from collections import namedtuple
from concurrent.futures import Future
from typing import NamedTuple

import numba
import numpy as np
from numba import njit, types
from numba.core import cgutils
from numba.core.dispatcher import Dispatcher
from numba.extending import intrinsic

from .._numba import FASTMATH, jit
from ..bsdfs.base import PARAM_SIZE
from ..bsdfs.dispatch import bsdf_pdf, bsdf_sample
from ..emitters.envmap import env_pdf, env_sample, placeholder_environment
from ..sampling.mis import mis_weight
from .technique_errors import TechniqueError, _row, _TooLong, _user_line

__all__ = [
    "EnvironmentRecord",
    "JitContext",
    "JitTechnique",
    "environment_record",
    "jit_functions",
    "material_record",
]

#: the compiled loops that call user functions: not cached (a function argument cannot be), otherwise the render
#: core's flags, so that lightprobe's own techniques called through them give the core's numbers
user_serial = njit(nogil=True, error_model="numpy", fastmath=FASTMATH)
user_inline = njit(nogil=True, error_model="numpy", fastmath=FASTMATH, inline="always")


class JitContext(NamedTuple):
    """One shading point as an njit technique sees it (see the module docstring)."""

    wo: np.ndarray
    normal: np.ndarray
    frame: np.ndarray
    position: np.ndarray
    material: tuple
    environment: tuple
    data: tuple


class KernelMaterial(NamedTuple):
    """A material as lightprobe's own techniques see it: its kind and kernel block (``bsdfs.dispatch``)."""

    kind: int
    params: np.ndarray


class EnvironmentRecord(NamedTuple):
    """The environment map for njit code: texel luminance (H, W) and radiance (H, W, 3), lat-long with row 0 the
    zenith; ``to_world`` the map's rotation (3, 3); ``kernel`` lightprobe's arrays (``emitters.envmap``) where its
    map sampling reads them, else an empty tuple (:func:`environment_record`)."""

    luminance: np.ndarray
    radiance: np.ndarray
    to_world: np.ndarray
    kernel: tuple


_RECORD_TYPES: dict[tuple, type] = {}
#: each map's record, kept while the map lives (not beyond: a record holds the map's arrays)
_ENVIRONMENT_RECORDS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def material_record(material) -> tuple:
    """A named tuple of a material's parameters for njit code: ``kind`` and ``params`` (its kernel block), then
    each public attribute that is a number (as float) or a 1-D float array, in the order the material sets them.
    One named-tuple type per material class, so that Numba compiles a loop once per class, not per material."""
    if material is None:
        fields, values = ["kind", "params"], [-1, np.zeros(PARAM_SIZE)]
    else:
        fields, values = ["kind", "params"], [int(material.kind), np.ascontiguousarray(material.params)]
        for name, value in vars(material).items():
            if name.startswith("_") or name in ("kind", "params", "textures"):
                continue
            if isinstance(value, bool) or value is None:
                continue
            if isinstance(value, int | float | np.floating | np.integer):
                fields.append(name)
                values.append(float(value))
            elif isinstance(value, np.ndarray) and value.ndim == 1 and np.issubdtype(value.dtype, np.floating):
                fields.append(name)
                values.append(np.ascontiguousarray(value, dtype=np.float64))
    key = (type(material).__name__, tuple(fields))
    record_type = _RECORD_TYPES.get(key)
    if record_type is None:
        record_type = namedtuple(f"{key[0] if material is not None else 'No'}Material", fields)
        _RECORD_TYPES[key] = record_type
    return record_type(*values)


def environment_record(environment, *, kernel: bool = True) -> EnvironmentRecord:
    """The map's :class:`EnvironmentRecord` (lightprobe's placeholder map when there is none); with ``kernel``
    False, its ``kernel`` an empty tuple.

    Only lightprobe's own map sampling reads the kernel record (about 25 arrays), and Numba compiles each function
    that takes a context for every field of its type, read or not: a three-line technique compiled in 0.22-0.31 s
    with the kernel in its context and 0.11 s without (decisions.md 136). A user's technique is therefore given the
    record without it; lightprobe's techniques get the whole record (``lab.render._Shader._records``)."""
    env = environment if environment is not None else placeholder_environment()
    records = _ENVIRONMENT_RECORDS.get(env)
    if records is None:
        full = EnvironmentRecord(
            np.ascontiguousarray(env.luminance, dtype=np.float64),
            np.ascontiguousarray(env.radiance, dtype=np.float64),
            np.ascontiguousarray(env.to_world, dtype=np.float64),
            env.kernel,
        )
        records = _ENVIRONMENT_RECORDS[env] = (full, full._replace(kernel=()))
    return records[0] if kernel else records[1]


def _njit_function(technique, method: str, label: str):
    """The njit function behind ``technique.method``, None when it is plain Python; an error for njit functions
    that take ``self``."""
    value = getattr(technique, method, None)
    if isinstance(value, Dispatcher):
        return value
    func = getattr(value, "__func__", None)
    if isinstance(func, Dispatcher):
        if len(inspect.signature(func.py_func).parameters) == 2:  # an njit function stored as a class attribute
            return func
        raise TechniqueError(f"{label}.{method}: an njit function cannot take self: make it a @staticmethod "
                             f"{method}({'u' if method == 'sample' else 'wi'}, ctx)")  # fmt: skip
    return None


def jit_functions(technique, label: str):
    """(sample, pdf) njit functions of a technique, or None when neither is njit; an error when only one is."""
    sample = _njit_function(technique, "sample", label)
    pdf = _njit_function(technique, "pdf", label)
    if (sample is None) != (pdf is None):
        njit_one, plain = ("sample", "pdf") if sample is not None else ("pdf", "sample")
        raise TechniqueError(f"{label}: {njit_one} is a numba.njit function but {plain} is not: make both njit "
                             "functions (one sample per call) or both NumPy methods (a batch per call)")  # fmt: skip
    return None if sample is None else (sample, pdf)


def technique_data(technique, label: str) -> tuple:
    """The technique's ``data`` attribute as a tuple (empty when it has none)."""
    data = getattr(technique, "data", ())
    if isinstance(data, list):
        data = tuple(data)
    if not isinstance(data, tuple):
        raise TechniqueError(f"{label}: data must be a tuple of arrays and numbers (ctx.data in njit code), got "
                             f"{type(data).__name__}")  # fmt: skip
    return data


# --- borrowed references -----------------------------------------------------------------------------------------
def _strip(context, builder, typ, value):
    if isinstance(typ, types.Array):
        ary = context.make_array(typ)(context, builder, value=value)
        ary.meminfo = cgutils.get_null_value(ary.meminfo.type)
        ary.parent = cgutils.get_null_value(ary.parent.type)
        return ary._getvalue()
    if isinstance(typ, types.BaseTuple):
        members = typ.types if hasattr(typ, "types") else [typ.dtype] * typ.count
        for i, member in enumerate(members):
            value = builder.insert_value(value, _strip(context, builder, member, builder.extract_value(value, i)), i)
    return value


@intrinsic
def borrowed(typingctx, value):
    """``value`` (an array, or a tuple of arrays, numbers and tuples, to any depth) with every array's reference
    count dropped: the same data, valid while the original lives. A context built from borrowed arrays costs no
    atomic reference counting per sample: building one per sample from the records themselves (about 25 arrays
    with lightprobe's map) took 230-730 ns a sample against 100-130 ns for the call itself (decisions.md 87)."""

    def codegen(context, builder, sig, args):
        return _strip(context, builder, sig.args[0], args[0])

    return value(value), codegen


# --- the compiled loops --------------------------------------------------------------------------------------------
# Serial loops over a range of rows, run on every core by threads (the loops release the GIL): Numba's parallel
# loops cannot take the nested named tuples a context holds, and report a raise inside them without its message.
@user_serial
def _sample_rows(lo, hi, sample, u, wo, normal, frame, position, material, environment, data, wi, pdf):
    wo, normal, frame, position = borrowed(wo), borrowed(normal), borrowed(frame), borrowed(position)
    material, environment, data = borrowed(material), borrowed(environment), borrowed(data)
    for i in range(lo, hi):
        ctx = JitContext(wo[i], normal[i], frame[i], position[i], material, environment, data)
        w, p = sample(u[i], ctx)
        wi[i, 0] = w[0]
        wi[i, 1] = w[1]
        wi[i, 2] = w[2]
        pdf[i] = p


@user_serial
def _pdf_rows(lo, hi, pdf, wi, wo, normal, frame, position, material, environment, data, out):
    wo, normal, frame, position = borrowed(wo), borrowed(normal), borrowed(frame), borrowed(position)
    material, environment, data = borrowed(material), borrowed(environment), borrowed(data)
    for i in range(lo, hi):
        ctx = JitContext(wo[i], normal[i], frame[i], position[i], material, environment, data)
        out[i] = pdf(wi[i], ctx)


@user_serial
def _first_raising(func, inputs, wo, normal, frame, position, material, environment, data):
    """The first row whose call raises, -1 when none does."""
    for i in range(inputs.shape[0]):
        ctx = JitContext(wo[i], normal[i], frame[i], position[i], material, environment, data)
        try:
            func(inputs[i], ctx)
        except Exception:  # the user's code; the row is what is wanted here
            return i
    return -1


class _Workers:
    """Daemon threads that run compiled loops: compiled code cannot be stopped, so a call that overruns its time
    limit (or loops forever) is abandoned by the caller and must not hold the process open at exit, as a
    ThreadPoolExecutor's threads would."""

    def __init__(self, count: int):
        self.count = count
        self.tasks: queue.SimpleQueue = queue.SimpleQueue()
        for i in range(count):
            threading.Thread(target=self._work, name=f"lightprobe-lab-{i}", daemon=True).start()

    def _work(self) -> None:
        while True:
            future, fn, args = self.tasks.get()
            if future.set_running_or_notify_cancel():
                try:
                    future.set_result(fn(*args))
                except BaseException as exc:  # handed to the caller
                    future.set_exception(exc)

    def submit(self, fn, *args) -> Future:
        future: Future = Future()
        self.tasks.put((future, fn, args))
        return future


_WORKERS: _Workers | None = None


def run_rows(loop, n: int, *args) -> None:
    """``loop(lo, hi, *args)`` over [0, n) in chunks, on every core (Numba's thread count); the first exception
    raised is raised here."""
    global _WORKERS
    workers = max(1, numba.get_num_threads())
    if workers == 1 or n < 2:
        loop(0, n, *args)
        return
    if _WORKERS is None or _WORKERS.count < workers:
        _WORKERS = _Workers(workers)
    chunks = min(n, 4 * workers)
    bounds = [n * c // chunks for c in range(chunks + 1)]
    futures = [_WORKERS.submit(loop, lo, hi, *args) for lo, hi in itertools.pairwise(bounds)]
    try:
        for future in futures:
            future.result()
    except BaseException:  # a time limit, Ctrl-C or a raise: the chunks not started are dropped
        for future in futures:
            future.cancel()
        raise


_ANSI = re.compile(r"\x1b\[[0-9;]*m")


def compile_error(label: str, method: str, exc: Exception) -> TechniqueError:
    """One line for a Numba typing or lowering error in the user's function."""
    lines = [line.strip() for line in _ANSI.sub("", str(exc)).splitlines() if line.strip()]
    where = next((m.group(0) for line in lines if (m := re.search(r'File "[^"]+", line \d+', line))), "")
    first = lines[0] if lines else type(exc).__name__
    where = f"; {where}" if where else ""
    return TechniqueError(f"{label}.{method}: numba could not compile it with lightprobe's arguments: {first[:200]}"
                          f"{where} (check: compiles)")  # fmt: skip


class JitTechnique:
    """The NumPy contract (arrays in, arrays out) around a technique written as njit functions."""

    def __init__(self, technique, label: str, functions):
        self.technique = technique
        self.label = label
        self.sample_fn, self.pdf_fn = functions
        if hasattr(technique, "prepare"):
            self.prepare = technique.prepare

    def data(self) -> tuple:
        return technique_data(self.technique, self.label)

    def arguments(self, ctx, rows: int | None = None) -> tuple:
        """The per-row arrays (the first ``rows`` rows, all when None) and the shared records of a
        :class:`~lightprobe.lab.techniques.Context`."""
        n = len(ctx)
        return (
            np.ascontiguousarray(ctx.wo[:rows], dtype=np.float64),
            np.ascontiguousarray(np.broadcast_to(ctx.normal, (n, 3))[:rows], dtype=np.float64),
            np.ascontiguousarray(np.broadcast_to(ctx.frame, (n, 3, 3))[:rows], dtype=np.float64),
            np.ascontiguousarray(np.broadcast_to(ctx.position, (n, 3))[:rows], dtype=np.float64),
            material_record(ctx.material),
            environment_record(ctx.environment, kernel=False),  # a user's functions alone run in these loops
            self.data(),
        )

    def sample(self, u, ctx, *, rows: int | None = None):
        u = np.ascontiguousarray(u, dtype=np.float64)[:rows]
        wi, pdf = np.empty((u.shape[0], 3)), np.empty(u.shape[0])
        self.call(_sample_rows, self.sample_fn, "sample", u, self.arguments(ctx, rows), (wi, pdf))
        return wi, pdf

    def pdf(self, wi, ctx, *, rows: int | None = None):
        wi = np.ascontiguousarray(wi, dtype=np.float64)[:rows]
        out = np.empty(wi.shape[0])
        self.call(_pdf_rows, self.pdf_fn, "pdf", wi, self.arguments(ctx, rows), (out,))
        return out

    def compile(self, method: str, inputs, ctx) -> None:
        """Compile ``method``'s loop for these arguments' types (a call on no rows, its arrays empty: once compiled,
        this costs nothing): the caller does this before it starts a call's time limit, so that Numba's compile
        (seconds) is not counted as the technique's time, and a limit's signal never lands inside the compiler."""
        getattr(self, method)(inputs, ctx, rows=0)

    def call(self, loop, func, method: str, inputs: np.ndarray, arguments: tuple, outputs: tuple) -> None:
        """``loop`` over the rows of ``inputs``, its failures as one-line errors naming the sample."""
        from numba.core.errors import NumbaError

        try:
            run_rows(loop, inputs.shape[0], func, inputs, *arguments, *outputs)
        except NumbaError as exc:
            raise compile_error(self.label, method, exc) from None
        except (_TooLong, TechniqueError):
            raise
        except Exception:  # a raise inside the user's function, reported with its row below
            raise self.raised(func, method, inputs, arguments) from None

    def raised(self, func, method: str, inputs: np.ndarray, arguments: tuple) -> TechniqueError:
        """The error of the first sample whose call raises: found in compiled code, then re-run in Python for the
        exception's message and the user's line."""
        row = _first_raising(func, inputs, *arguments)
        name = "u" if method == "sample" else "wi"
        if row < 0:
            return TechniqueError(f"{self.label}.{method} failed in compiled code and not when run again "
                                  f"(check: {method} runs; batch of {len(inputs)})")  # fmt: skip
        wo, normal, frame, position, material, environment, data = arguments
        ctx = JitContext(wo[row], normal[row], frame[row], position[row], material, environment, data)
        try:
            func.py_func(inputs[row], ctx)
        except Exception as exc:  # the user's code
            line = _user_line(exc).lstrip(": ") or "no line"
            return TechniqueError(
                f"{self.label}.{method} raised {type(exc).__name__}: {exc} ({line}; check: {method} runs; sample "
                f"{row} of a batch of {len(inputs)}, {name} = {_row(inputs, row)})"
            )
        return TechniqueError(f"{self.label}.{method} raised in compiled code at sample {row} but not in Python "
                              f"(check: {method} runs; {name} = {_row(inputs, row)})")  # fmt: skip


# --- lightprobe's own techniques as njit functions (the laboratory's compiled estimator calls them) ---------------
@jit
def builtin_bsdf_sample(u, ctx):
    # the materials take their 2D pair from columns 1 and 2 of their u (bsdfs/base.py); a technique's is in 0 and 1
    m = ctx.material
    wi, pdf, _ = bsdf_sample(m.kind, m.params, (ctx.wo[0], ctx.wo[1], ctx.wo[2]), u[2], u[0], u[1])
    return wi, pdf


@jit
def builtin_bsdf_pdf(wi, ctx):
    m = ctx.material
    return bsdf_pdf(m.kind, m.params, (ctx.wo[0], ctx.wo[1], ctx.wo[2]), (wi[0], wi[1], wi[2]))


@jit
def builtin_env_sample(u, ctx):
    x, y, z, pdf = env_sample(ctx.environment.kernel, False, u[0], u[1])
    return (x, y, z), pdf


@jit
def builtin_env_pdf(wi, ctx):
    return env_pdf(ctx.environment.kernel, False, wi[0], wi[1], wi[2])


@jit
def balance_weight(n_f, p_f, n_g, p_g):
    return mis_weight(n_f, p_f, n_g, p_g, 1.0)


@jit
def power_weight(n_f, p_f, n_g, p_g):
    return mis_weight(n_f, p_f, n_g, p_g, 2.0)


HEURISTICS = {"balance": balance_weight, "power": power_weight}


def elapsed_check(label: str, method: str, start: float, limit: float, n: int) -> None:
    """Compiled code cannot be stopped from outside: a call that took longer than the limit fails afterwards."""
    spent = time.perf_counter() - start
    if limit and limit > 0 and spent > limit:
        raise TechniqueError(f"{label}.{method}: took {spent:.1f} s on a batch of {n}, longer than {limit:g} s "
                             "(check: time limit; compiled code is stopped only after the batch)")  # fmt: skip
