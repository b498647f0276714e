"""Light selectors written by users, in plain Python: the contract, loading one from a file, and calling it safely.

A *selector* chooses which light a light sample goes to, at a batch of shading points::

    class NearestFirst:
        def select(self, ctx, u):      # u: (N,) in [0, 1)
            ...
            return light, pmf          # (N,) light indices (0 .. ctx.lights.count - 1), (N,) their probabilities

        def pmf(self, ctx, light):     # (N,) light indices -> (N,) the probability select() picks each one
            ...

``ctx`` (:class:`SelectorContext`) holds the points (``ctx.point``, ``ctx.normal``: the geometric normal, both (N, 3),
world space) and ``ctx.lights`` (:class:`LightSet`): the scene's lights as the renderer numbers them (bounded lights
first, then the infinite ones: a directional light, the sun, the environment map), with each one's kind, centre,
normal (area lights), power and whether it is infinitely far.  An optional ``prepare(self, lights)`` is called once
with the :class:`LightSet` before the selector is used (build distributions there).

:func:`load_selector` reads ``FILE.py[:NAME]``; :class:`GuardedSelector` calls a selector and turns every way it can
go wrong (an exception, the wrong shape, a light index out of range, a pmf of 0 for a light it picked, pmfs that do
not sum to 1 over the lights, ``select``'s pmf not equal to ``pmf()``, picks that do not follow ``pmf()`` (a chi-square
test at a few points), a call that takes too long) into one
:class:`~lightprobe.lab.techniques.TechniqueError` naming the function, the check and the first offending sample.
``lightprobe compare --selector FILE.py[:NAME]`` measures a selector against the renderer's and the oracle
(:mod:`lightprobe.experiments.light_choice`).
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..emitters.kinds import KINDS, LightArrays, flag_rows
from ..emitters.selection import _light_bounds, power_of_lights
from .technique_errors import TechniqueError, _row, _TooLong, _user_line
from .techniques import DEFAULT_TIME_LIMIT, _time_limit, load_module

__all__ = ["GuardedSelector", "LightSet", "SelectorContext", "load_selector"]

#: |sum of the pmfs over the lights - 1| allowed at a point, and |select's pmf - pmf()| relative
PMF_TOLERANCE = 1e-6
#: points where the picks are tested against pmf(), picks at each, and the test's significance (Sidak over the
#: points; the numbers are seeded, so a verdict never changes from one run to the next)
PICK_POINTS = 4
PICKS = 20_000
PICK_SIGNIFICANCE = 1e-3
_NAMES = {kind.code: kind.name for kind in KINDS.values()}


@dataclass(frozen=True)
class LightSet:
    """The scene's lights, row l = light index l (what ``select`` returns)."""

    count: int
    #: (L,) each light's kind: rectangle, sphere, triangle, point, spot, directional, environment, sun
    kind: tuple[str, ...]
    #: (L,) bool: infinitely far (directional, sun, environment): no position
    infinite: np.ndarray
    #: (L, 3) the centre of each bounded light's bounding box (NaN for the infinite ones)
    center: np.ndarray
    #: (L, 3) an area light's unit normal (rectangles and triangles; zeros for the others)
    normal: np.ndarray
    #: (L,) emitted power of the luminance (W-like units; 0 for the infinite lights, chosen by their irradiance)
    power: np.ndarray

    @classmethod
    def of(cls, lights: LightArrays) -> LightSet:
        lo, hi, _, w, _, _, _ = _light_bounds(lights)
        infinite = flag_rows(lights.kind, "infinite")
        center = np.where(infinite[:, None], np.nan, 0.5 * (lo + hi))
        normal = np.where(np.isin(lights.kind, [KINDS["rectangle"].code, KINDS["triangle"].code])[:, None], w, 0.0)
        for a in (center, normal):
            a.setflags(write=False)
        power = power_of_lights(lights)
        power.setflags(write=False)
        infinite.setflags(write=False)
        kinds = tuple(_NAMES[int(k)] for k in lights.kind)
        return cls(len(kinds), kinds, infinite, center, normal, power)


@dataclass(frozen=True)
class SelectorContext:
    """A batch of shading points, as a selector sees them."""

    point: np.ndarray  # (N, 3) world
    normal: np.ndarray  # (N, 3) geometric normal, unit, on the side the viewer sees
    lights: LightSet

    def __len__(self) -> int:
        return self.point.shape[0]

    def subset(self, rows) -> SelectorContext:
        return SelectorContext(self.point[rows], self.normal[rows], self.lights)


def _is_selector(obj) -> bool:
    return callable(getattr(obj, "select", None)) and callable(getattr(obj, "pmf", None)) and not inspect.ismodule(obj)


def load_selector(spec: str, *, time_limit: float = DEFAULT_TIME_LIMIT) -> GuardedSelector:
    """The selector ``FILE.py:NAME`` (``FILE.py`` alone when the file defines exactly one): a class is instantiated
    without arguments, an instance (any object with ``select`` and ``pmf``) used as it is."""
    file, name = (spec, "") if spec.endswith(".py") or ":" not in spec else spec.rsplit(":", 1)
    module = load_module(file, what="selector file")
    found = {
        n: obj
        for n, obj in vars(module).items()
        if not n.startswith("_")
        and _is_selector(obj)
        and getattr(obj, "__module__", module.__name__) == module.__name__
    }
    if name:
        if not hasattr(module, name):
            raise TechniqueError(f"{file}: no selector named {name!r} (selectors found: {', '.join(found) or 'none'})")
        obj = getattr(module, name)
        if not _is_selector(obj):
            raise TechniqueError(
                f"{file}: {name} is not a selector: it needs select(ctx, u) and pmf(ctx, light) methods"
            )
    else:
        if len(found) != 1:
            raise TechniqueError(
                f"{file}: name one selector as {file}:NAME (selectors found: {', '.join(found) or 'none'})"
            )
        name, obj = next(iter(found.items()))
    if inspect.isclass(obj):
        try:
            obj = obj()
        except (Exception, SystemExit) as exc:  # the user's code: a sys.exit() must not end lightprobe
            raise TechniqueError(f"{file}:{name}: creating it raised {type(exc).__name__}: {exc}") from None
    return GuardedSelector(obj, f"{Path(file).name}:{name}", time_limit=time_limit)


class GuardedSelector:
    """A selector whose every call is checked: see the module docstring."""

    def __init__(self, selector, label: str, *, time_limit: float = DEFAULT_TIME_LIMIT):
        self.user = selector
        self.label = label
        self.time_limit = time_limit
        self._prepared: int | None = None

    def __repr__(self) -> str:
        return f"GuardedSelector({self.label})"

    def _call(self, method: str, args, first_input: np.ndarray, input_name: str):
        try:
            with _time_limit(self.time_limit):
                return getattr(self.user, method)(*args)
        except _TooLong:
            raise TechniqueError(
                f"{self.label}.{method}: took longer than {self.time_limit:g} s on a batch of {len(first_input)} "
                f"(check: time limit; first sample {input_name} = {_row(first_input, 0)})"
            ) from None
        except TechniqueError:
            raise
        except (Exception, SystemExit) as exc:  # the user's code: any error is reported, not a traceback
            line = _user_line(exc).lstrip(": ") or "no line"
            raise TechniqueError(
                f"{self.label}.{method} raised {type(exc).__name__}: {exc} ({line}; check: {method} runs; batch of "
                f"{len(first_input)}, first sample {input_name} = {_row(first_input, 0)})"
            ) from None

    def prepare(self, lights: LightSet) -> None:
        hook = getattr(self.user, "prepare", None)
        if hook is None or self._prepared == id(lights):
            return
        self._call("prepare", (lights,), np.zeros((1, 1)), "lights")
        self._prepared = id(lights)

    def _vector(self, value, n: int, method: str, what: str, inputs, input_name: str, integer: bool = False):
        where = f"{self.label}.{method}"
        try:
            a = np.asarray(value)
        except Exception as exc:
            raise TechniqueError(f"{where}: {what} is not an array ({exc})") from None
        if a.shape == (n, 1):
            a = a[:, 0]
        if a.shape != (n,):
            raise TechniqueError(
                f"{where}: {what} has shape {a.shape}, expected ({n},) (check: shape and dtype; a batch of {n} went in)"
            )
        if integer:
            if not np.issubdtype(a.dtype, np.integer):
                raise TechniqueError(f"{where}: {what} has dtype {a.dtype}, expected integers (check: shape and dtype)")
            return a.astype(np.int64)
        if not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)):
            raise TechniqueError(f"{where}: {what} has dtype {a.dtype}, expected float (check: shape and dtype)")
        a = a.astype(np.float64)
        bad = ~np.isfinite(a) | (a < 0.0)
        if bad.any():
            i = int(np.argmax(bad))
            raise TechniqueError(
                f"{where}: {what} is {a[i]:.6g} at sample {i} (check: finite pmf >= 0; {input_name} = "
                f"{_row(inputs, i)}; {int(bad.sum())} of {n} samples)"
            )
        return a

    def select(self, ctx: SelectorContext, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Checked ``select``: light indices in range, each with a pmf > 0."""
        self.prepare(ctx.lights)
        n = u.shape[0]
        out = self._call("select", (ctx, u), u, "u")
        if not isinstance(out, tuple | list) or len(out) != 2:
            raise TechniqueError(f"{self.label}.select must return (light, pmf), got {type(out).__name__}")
        light = self._vector(out[0], n, "select", "light", u, "u", integer=True)
        pmf = self._vector(out[1], n, "select", "pmf", u, "u")
        bad = (light < 0) | (light >= ctx.lights.count)
        if bad.any():
            i = int(np.argmax(bad))
            raise TechniqueError(
                f"{self.label}.select: light index {light[i]} out of range at sample {i} (check: 0 <= light < "
                f"{ctx.lights.count}; u = {u[i]:.6g}, point = {_row(ctx.point, i)}; {int(bad.sum())} of {n} samples)"
            )
        zero = pmf <= 0.0
        if zero.any():
            i = int(np.argmax(zero))
            raise TechniqueError(
                f"{self.label}.select: pmf 0 for the light it picked ({light[i]}) at sample {i} (check: pmf > 0 "
                f"where picked; u = {u[i]:.6g}, point = {_row(ctx.point, i)}; {int(zero.sum())} of {n} samples)"
            )
        return light, pmf

    def pmf(self, ctx: SelectorContext, light: np.ndarray) -> np.ndarray:
        """Checked ``pmf``: (N,), finite, >= 0."""
        self.prepare(ctx.lights)
        out = self._call("pmf", (ctx, light), light, "light")
        return self._vector(out, light.shape[0], "pmf", "the result", light, "light")

    def pmf_matrix(self, points, normals, lights: LightArrays, *, seed: int = 0) -> np.ndarray:
        """Every light's probability at every point, (N, L), after checking that the pmfs sum to 1 at each point
        and that ``select``'s picks (one per point) come with ``pmf()``'s probability."""
        light_set = LightSet.of(lights)
        ctx = SelectorContext(np.asarray(points, np.float64), np.asarray(normals, np.float64), light_set)
        n, count = len(ctx), light_set.count
        table = np.empty((n, count))
        for light in range(count):  # a light at a time: a batch the size of the points, whatever the light count
            table[:, light] = self.pmf(ctx, np.full(n, light, np.int64))
        total = table.sum(axis=1)
        bad = np.abs(total - 1.0) > PMF_TOLERANCE
        if bad.any():
            i = int(np.argmax(bad))
            raise TechniqueError(
                f"{self.label}.pmf: the pmfs of the {count} lights sum to {total[i]:.9g}, not 1, at sample {i} "
                f"(check: pmfs sum to 1; point = {_row(ctx.point, i)}; {int(bad.sum())} of {n} points)"
            )
        u = np.random.default_rng(seed).random(n)
        light, pmf = self.select(ctx, u)
        expected = table[np.arange(n), light]
        bad = np.abs(pmf - expected) > PMF_TOLERANCE * np.maximum(expected, 1e-300)
        if bad.any():
            i = int(np.argmax(bad))
            raise TechniqueError(
                f"{self.label}.select: pmf {pmf[i]:.9g} for light {light[i]} at sample {i}, but pmf() says "
                f"{expected[i]:.9g} (check: select's pmf = pmf(); u = {u[i]:.6g}, point = {_row(ctx.point, i)}; "
                f"{int(bad.sum())} of {n} samples)"
            )
        self._check_picks(ctx, table, seed)
        return table

    def _check_picks(self, ctx: SelectorContext, table: np.ndarray, seed: int) -> None:
        """At up to ``PICK_POINTS`` points, ``PICKS`` picks each: none where pmf() is 0, and their counts pass a
        chi-square test against pmf() (lights expected fewer than 20 times pooled into one cell)."""
        from scipy import stats

        rng = np.random.default_rng(seed + 1)
        points = np.unique(np.linspace(0, len(ctx) - 1, PICK_POINTS).astype(np.int64))
        for i in points:
            u = rng.random(PICKS)
            light, _ = self.select(ctx.subset(np.full(PICKS, i)), u)
            pmf = table[i]
            counts = np.bincount(light, minlength=pmf.size)
            never = (counts > 0) & (pmf == 0.0)
            if never.any():
                j = int(np.argmax(never))
                raise TechniqueError(
                    f"{self.label}.select: picked light {j} {counts[j]} times at sample {i}, where pmf() says 0 "
                    f"(check: picks follow pmf(); point = {_row(ctx.point, i)})"
                )
            expected = PICKS * pmf
            big = expected >= 20
            observed = np.append(counts[big], counts[~big].sum())
            wanted = np.append(expected[big], expected[~big].sum())
            keep = wanted > 0
            if keep.sum() < 2:
                continue
            _, p_value = stats.chisquare(observed[keep], wanted[keep] * observed[keep].sum() / wanted[keep].sum())
            if p_value < PICK_SIGNIFICANCE / points.size:
                worst = int(np.argmax(np.abs(counts - expected) / np.sqrt(np.maximum(expected, 1.0))))
                raise TechniqueError(
                    f"{self.label}.select: its picks do not follow pmf() at sample {i}: chi-square p = {p_value:.3g} "
                    f"over {PICKS} picks; light {worst} picked {counts[worst]} times, pmf() expects "
                    f"{expected[worst]:.1f} (check: picks follow pmf(); point = {_row(ctx.point, i)})"
                )
