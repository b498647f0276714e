"""The one light contract: every kind of the light table behind the same sample / pdf / radiance functions.

After pbrt-v4's ``Light::SampleLi / PDF_Li / L / Le`` and Mitsuba 3's ``sample_direction / pdf_direction / eval``.
For a shading point p with normal n:

* ``light_sample(lights, env, l, strategy, compensated, p, n, u0, u1)`` -> :class:`~.kinds.LightSample`: a direction
  toward light l, the distance to the sampled point (inf for infinite lights), the radiance arriving, the density
  per steradian (1 for a delta light), and whether it is a delta light;
* ``light_pdf(lights, env, l, strategy, compensated, p, n, w)``: the density with which ``light_sample`` produces
  direction w (0 for a delta light: no given direction is ever its);
* ``escaped_radiance(lights, env, w)``: what a ray that leaves the scene along w sees: the environment's, every
  directional light's and sun's radiance (the table's last rows, :func:`first_infinite` on), each
  ``infinite_radiance``;
* for area lights a BSDF ray has hit at a known point, ``emitted`` and ``area_pdf_at`` (module ``area``).

``strategy`` is how area lights are sampled (:data:`~.area.STRATEGIES`); ``compensated`` whether the environment is
sampled from its MIS-compensated density.  The environment's own data is its kernel ``env``
(:class:`~.envmap.EnvKernel`); a scene without one passes a placeholder that no row refers to.  Which kind is
which: :data:`~.kinds.KINDS`, the one table; ``tests/emitters/test_lights.py`` runs every kind through the contract
(chi-square where it has a density, closed forms where it is a delta).
"""

from __future__ import annotations

import importlib

import numpy as np

from .._numba import jit, jit_inline
from .._worksharing import in_threads, read_only, read_only_rows
from .area import light_normal, light_radiance
from .area import light_pdf_at as area_pdf_at
from .kinds import (
    KINDS,
    LIGHT_DIRECTIONAL,
    LIGHT_ENVIRONMENT,
    ROW_WIDTH,
    LightArrays,
    concatenate,
    is_infinite_kind,
    is_positional_kind,
)

__all__ = [
    "area_pdf_at",
    "emitted",
    "escaped_batch",
    "escaped_radiance",
    "first_infinite",
    "infinite_radiance",
    "is_delta",
    "is_infinite",
    "is_positional",
    "light_arrays",
    "light_pdf_of",
    "light_sample_of",
    "pdf_batch",
    "sample_batch",
]


@jit_inline
def is_delta(lights, l):
    """Whether row l is a delta light: a point or spot light, or a directional light of angle 0."""
    kind = lights.kind[l]
    return is_positional_kind(kind) or (kind == LIGHT_DIRECTIONAL and lights.geom[l, 4] <= 0.0)


@jit_inline
def is_infinite(lights, l):
    """Whether row l is infinitely far (a directional light or the environment): no distance, no surface."""
    return is_infinite_kind(lights.kind[l])


@jit_inline
def first_infinite(lights):
    """The first row of the infinite lights, which close the table (kinds.py): found from its end, a step per
    infinite light (a few), so that code that reads the table needs no count kept beside it."""
    first = lights.kind.shape[0]
    while first > 0 and is_infinite(lights, first - 1):
        first -= 1
    return first


@jit_inline
def is_positional(lights, l):
    """Whether row l is a point or spot light: a position with no surface around it (a shadow ray ends at it)."""
    return is_positional_kind(lights.kind[l])


# The contract's three dispatchers are written out from KINDS (:func:`dispatch_source`): for each module that samples
# some kinds, a test of the row's kind code and a call of that module's row_sample / row_pdf / row_radiance, which
# are inlined and call the kind's own sampler with only its own data.  A new kind is a module with those functions
# and a line of KINDS; no dispatcher is edited.  Compiled code only, inlined into its callers.
_CONTRACT = {
    "row_sample": "lights, env, l, strategy, compensated, px, py, pz, nx, ny, nz, u0, u1",
    "row_pdf": "lights, env, l, strategy, compensated, px, py, pz, nx, ny, nz, wx, wy, wz",
    "row_radiance": "lights, env, l, wx, wy, wz",  # the infinite kinds': what an escaping ray sees
}


def dispatch_source(function: str, name: str) -> str:
    """The Python source of the dispatcher ``name`` for the contract function ``function`` of :data:`_CONTRACT`:
    the kinds' modules in the order of :data:`~.kinds.KINDS` (``row_radiance``: the infinite kinds' only), each
    behind a test of its kinds' codes, the last one unconditional."""
    groups: dict[str, list[int]] = {}
    for kind in KINDS.values():
        if function != "row_radiance" or kind.infinite:
            groups.setdefault(kind.module, []).append(kind.code)
    parameters = _CONTRACT[function]
    lines = [f"def {name}({parameters}):", "    kind = lights.kind[l]"]
    for i, (module, codes) in enumerate(groups.items()):
        call = f"return {module}.{function}({parameters})"
        if i == len(groups) - 1:
            lines.append(f"    {call}")
        else:
            lines += [f"    if {' or '.join(f'kind == {code}' for code in codes)}:", f"        {call}"]
    return "\n".join(lines) + "\n"


def _compiled_dispatcher(function: str, name: str, doc: str):
    """The dispatcher written by :func:`dispatch_source`, a function that Numba inlines into its callers at the IR
    level.  As an ``overload(inline="always")``, as they were, each was also compiled on its own and typed again at
    every call site: the light-sample, BSDF-ray and escaping-ray stages compiled in 26.4 s, now 21.9.  As called
    kernels the area scene rendered 10-21 % slower (the light table and the environment passed by value;
    decisions.md 23, 130)."""
    modules = {kind.module for kind in KINDS.values()}
    namespace = {"__name__": __name__}
    namespace.update({module: importlib.import_module(f"{__package__}.{module}") for module in modules})
    exec(compile(dispatch_source(function, name), __file__, "exec"), namespace)
    dispatcher = namespace[name]
    dispatcher.__doc__ = doc
    return jit_inline(dispatcher)


light_sample_of = _compiled_dispatcher(
    "row_sample",
    "light_sample_of",
    """A :class:`LightSample` of light l from point p (normal n) with the pair (u0, u1).""",
)
light_pdf_of = _compiled_dispatcher(
    "row_pdf",
    "light_pdf_of",
    """Density per steradian with which :func:`light_sample_of` produces unit direction w (0 for a delta light).""",
)
infinite_radiance = _compiled_dispatcher(
    "row_radiance",
    "infinite_radiance",
    """Radiance that infinite light l (the environment, a directional light or the sun) sends along -w, toward a ray
    leaving the scene along unit direction w.""",
)


@jit_inline
def escaped_radiance(lights, env, wx, wy, wz):
    """Radiance a ray leaving the scene along unit direction w sees: every infinite light's, the environment's from
    its map."""
    r = g = b = 0.0
    for l in range(first_infinite(lights), lights.kind.shape[0]):
        lr, lg, lb = infinite_radiance(lights, env, l, wx, wy, wz)
        r += lr
        g += lg
        b += lb
    return r, g, b


@jit_inline
def emitted(lights, l, x, y, z, wx, wy, wz):
    """Radiance leaving area light l at its point (x, y, z) toward a ray travelling along w (0 from its back)."""
    n = light_normal(lights, l, x, y, z)
    return light_radiance(lights, l, -(n[0] * wx + n[1] * wy + n[2] * wz))


# --- batches for Python and the tests -------------------------------------------------------------------------------
# The batches for Python and the tests: serial range kernels that ``_worksharing.in_threads`` runs in threads, not
# ``prange`` loops, whose parallel passes compiled for longer (decisions.md 129, 130); any split of the rows gives
# the same values.
@jit
def _sample_range(lights, env, l, strategy, compensated, points, normals, u, out, lo, hi):
    for i in range(lo, hi):
        s = light_sample_of(
            lights, env, l, strategy, compensated, points[i, 0], points[i, 1], points[i, 2], normals[i, 0],
            normals[i, 1], normals[i, 2], u[i, 0], u[i, 1],
        )  # fmt: skip
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = s.wx, s.wy, s.wz, s.distance
        out[i, 4], out[i, 5], out[i, 6], out[i, 7] = s.r, s.g, s.b, s.pdf
        out[i, 8] = 1.0 if s.delta else 0.0


def _sample_batch(lights, env, l, strategy, compensated, points, normals, u):
    out = np.empty((u.shape[0], 9))
    in_threads(_sample_range, u.shape[0], lights, env, l, strategy, compensated, points, normals, u, out)
    return out


@jit
def _pdf_range(lights, env, l, strategy, compensated, points, normals, dirs, out, lo, hi):
    for i in range(lo, hi):
        out[i] = light_pdf_of(
            lights, env, l, strategy, compensated, points[i, 0], points[i, 1], points[i, 2], normals[i, 0],
            normals[i, 1], normals[i, 2], dirs[i, 0], dirs[i, 1], dirs[i, 2],
        )  # fmt: skip


def _pdf_batch(lights, env, l, strategy, compensated, points, normals, dirs):
    out = np.empty(dirs.shape[0])
    in_threads(_pdf_range, dirs.shape[0], lights, env, l, strategy, compensated, points, normals, dirs, out)
    return out


@jit
def _escaped_range(lights, env, dirs, out, lo, hi):
    for i in range(lo, hi):
        out[i, 0], out[i, 1], out[i, 2] = escaped_radiance(lights, env, dirs[i, 0], dirs[i, 1], dirs[i, 2])


def _escaped_batch(lights, env, dirs):
    out = np.empty((dirs.shape[0], 3))
    in_threads(_escaped_range, dirs.shape[0], lights, env, dirs, out)
    return out


def _env_kernel(env):
    if env is not None:
        return env.kernel
    from .envmap import placeholder_environment

    return placeholder_environment().kernel


def sample_batch(lights: LightArrays, l: int, points, normals, u, *, env=None, strategy="solid-angle",
                 compensated=False) -> np.ndarray:  # fmt: skip
    """Samples of row l for ``points``, ``normals`` (N, 3) and ``u`` (N, 2): an (N, 9) array of direction,
    distance, radiance, pdf and delta (1.0 or 0.0); ``env`` the scene's EnvironmentMap when row l is its."""
    from .area import STRATEGIES

    u = read_only(np.ascontiguousarray(np.asarray(u, dtype=np.float64).reshape(-1, 2)))
    points, normals = read_only_rows(points, u.shape[0]), read_only_rows(normals, u.shape[0])
    return _sample_batch(lights, _env_kernel(env), l, STRATEGIES[strategy], bool(compensated), points, normals, u)


def pdf_batch(lights: LightArrays, l: int, points, normals, dirs, *, env=None, strategy="solid-angle",
              compensated=False) -> np.ndarray:  # fmt: skip
    """The density of row l's samples at ``dirs`` (N, 3) from ``points`` with ``normals``."""
    from .area import STRATEGIES

    d = read_only(np.ascontiguousarray(np.asarray(dirs, dtype=np.float64).reshape(-1, 3)))
    points, normals = read_only_rows(points, d.shape[0]), read_only_rows(normals, d.shape[0])
    return _pdf_batch(lights, _env_kernel(env), l, STRATEGIES[strategy], bool(compensated), points, normals, d)


def escaped_batch(lights: LightArrays, dirs, *, env=None) -> np.ndarray:
    """What rays leaving the scene along ``dirs`` see from the infinite lights (the table's last rows)."""
    d = read_only(np.ascontiguousarray(np.asarray(dirs, dtype=np.float64).reshape(-1, 3)))
    return _escaped_batch(lights, _env_kernel(env), d)


def light_arrays(lights, *, environment: bool = False) -> LightArrays:
    """The table of Python light objects (:class:`~.area.AreaLight`, :class:`~.punctual.PointLight`,
    :class:`~.punctual.SpotLight`, :class:`~.directional.DirectionalLight`, :class:`~.sun.SunLight`), in order,
    with a last row for the
    scene's environment map when ``environment``."""
    rows = [
        LightArrays(
            np.array([KINDS[x.kind].code], np.int64),
            np.asarray(x.geom, dtype=np.float64).reshape(1, ROW_WIDTH),
            np.asarray(x.radiance, dtype=np.float64).reshape(1, 3),
            np.array([int(x.two_sided)], np.int64),
            np.array([float(x.area)]),
        )
        for x in lights
    ]
    if environment:
        rows.append(
            LightArrays(
                np.array([LIGHT_ENVIRONMENT], np.int64),
                np.zeros((1, ROW_WIDTH)),
                np.zeros((1, 3)),
                np.zeros(1, np.int64),
                np.zeros(1),
            )
        )
    return concatenate(rows)
