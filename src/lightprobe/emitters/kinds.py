"""The light table and the one list of light kinds.

Every light of a scene is a row of one table (:class:`LightArrays`), as pbrt-v4 keeps every ``Light`` in one array
(its ``ImageInfiniteLight`` among them): bounded lights first (area lights, then point and spot lights), then the
infinite ones (directional lights and suns, then the environment map, whose data the kernels read from its own
:class:`~lightprobe.emitters.envmap.EnvKernel`).  :data:`KINDS` is the only place a kind's number is written; the
contract that dispatches on it is :mod:`lightprobe.emitters.lights`, and a test runs every kind through it.

A light sample is a :class:`LightSample` record (pbrt-v4's ``LightLiSample``, Mitsuba 3's ``DirectionSample3f``):
direction toward the light, distance to the sampled point (inf for infinite lights), radiance arriving, density
per steradian (1 for a delta light) and whether the light is a delta light (no other technique can produce its
direction, so it takes MIS weight 1).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .._numba import jit_inline
from ..geometry.intersect import RECT_WIDTH

__all__ = [
    "KINDS",
    "LIGHT_DIRECTIONAL",
    "LIGHT_ENVIRONMENT",
    "LIGHT_POINT",
    "LIGHT_RECT",
    "LIGHT_SPHERE",
    "LIGHT_SPOT",
    "LIGHT_SUN",
    "LIGHT_TRIANGLE",
    "ROW_WIDTH",
    "Kind",
    "LightArrays",
    "LightSample",
    "area_rows",
    "concatenate",
    "flag_rows",
    "is_area_kind",
    "is_infinite_kind",
    "is_positional_kind",
    "light_counts",
    "rows_of",
]

# columns of a geometry row: the widest kind's, a parallelogram's (geometry.intersect.rectangle_rows)
ROW_WIDTH = RECT_WIDTH

(LIGHT_RECT, LIGHT_SPHERE, LIGHT_TRIANGLE, LIGHT_POINT, LIGHT_SPOT, LIGHT_DIRECTIONAL, LIGHT_ENVIRONMENT,
 LIGHT_SUN) = range(8)  # fmt: skip


@dataclass(frozen=True)
class Kind:
    """A light kind: its number in the table, its name in scene files, where its sampling lives, and its flags."""

    code: int
    name: str
    module: str  # the module of lightprobe.emitters that samples it
    area: bool  # a surface that rays can hit (its rows come from emissive objects)
    delta: bool  # a delta position: one direction from each point (a directional light of angle 0 is one too)
    infinite: bool  # infinitely far: no distance, lights every point from the same directions


KINDS = {
    k.name: k
    for k in (
        Kind(LIGHT_RECT, "rectangle", "area", area=True, delta=False, infinite=False),
        Kind(LIGHT_SPHERE, "sphere", "area", area=True, delta=False, infinite=False),
        Kind(LIGHT_TRIANGLE, "triangle", "area", area=True, delta=False, infinite=False),
        Kind(LIGHT_POINT, "point", "punctual", area=False, delta=True, infinite=False),
        Kind(LIGHT_SPOT, "spot", "punctual", area=False, delta=True, infinite=False),
        Kind(LIGHT_DIRECTIONAL, "directional", "directional", area=False, delta=False, infinite=True),
        Kind(LIGHT_ENVIRONMENT, "environment", "envmap", area=False, delta=False, infinite=True),
        Kind(LIGHT_SUN, "sun", "sun", area=False, delta=False, infinite=True),
    )
}


# the flags a row's kind is tested for: what the code asks, never a kind's number or order
_FLAGS = {
    "area": lambda k: k.area,  # a surface rays can hit
    "infinite": lambda k: k.infinite,  # infinitely far: rows after every bounded light's
    "positional": lambda k: k.delta and not k.infinite,  # a position with no surface: a shadow ray ends at it
}


def _flag_table(name: str) -> np.ndarray:
    """Entry ``code`` is whether the kind of that code has the flag ``name``: built from :data:`KINDS`, so that a
    new kind with the flag set is counted with no other line changed (compiled code reads the table as a constant)."""
    table = np.zeros(max(kind.code for kind in KINDS.values()) + 1, np.bool_)
    for kind in KINDS.values():
        table[kind.code] = _FLAGS[name](kind)
    return table


_FLAG_TABLES = {name: _flag_table(name) for name in _FLAGS}
_AREA, _INFINITE, _POSITIONAL = _FLAG_TABLES["area"], _FLAG_TABLES["infinite"], _FLAG_TABLES["positional"]


@jit_inline
def is_area_kind(kind):
    """Whether a light table's kind code is an area light's (a surface rays can hit)."""
    return _AREA[kind]


@jit_inline
def is_infinite_kind(kind):
    """Whether a light table's kind code is an infinite light's (no distance, no surface)."""
    return _INFINITE[kind]


@jit_inline
def is_positional_kind(kind):
    """Whether a light table's kind code is a position with no surface around it (a point or spot light)."""
    return _POSITIONAL[kind]


def flag_rows(kinds: np.ndarray, name: str) -> np.ndarray:
    """Which rows of a light table's ``kind`` column have the flag ``name`` (``area``, ``infinite``,
    ``positional``): a boolean mask, for NumPy code."""
    return _FLAG_TABLES[name][kinds]


class LightArrays(NamedTuple):
    """The light table the kernels read: row l is one light."""

    kind: np.ndarray  # (L,) int64: a Kind's code
    geom: np.ndarray  # (L, ROW_WIDTH) float64: a rectangle's row of geometry/intersect.rectangle_rows (origin,
    #                   edge_u, edge_v, unit normal, dual vectors) | sphere centre, radius | triangle v0, v1, v2,
    #                   unit normal | point position | spot position, axis, cos total, cos start | directional
    #                   direction toward the light, cos of its half-angle, its solid angle | environment: unused |
    #                   sun: a directional row's six, then its table's turbidity index, 1 / sin^2 alpha, its
    #                   scale and 1 for a limb-darkened disc (emitters/sun.py)
    radiance: np.ndarray  # (L, 3) float64: radiance; a point or spot light's intensity; a delta directional
    #                       light's irradiance; the environment's: unused (its map); the sun's disc's mean
    two_sided: np.ndarray  # (L,) int64
    area: np.ndarray  # (L,) float64 (0 for lights without a surface)


class LightSample(NamedTuple):
    """A sampled direction toward a light from a shading point (what ``lights.light_sample`` returns)."""

    wx: float  # unit direction toward the light
    wy: float
    wz: float
    distance: float  # to the sampled point; inf for infinite lights (a shadow ray tests the segment)
    r: float  # radiance arriving along the direction (zero from the back of a one-sided light)
    g: float
    b: float
    pdf: float  # per steradian; 1 for a delta light; 0: no sample
    delta: bool  # no other technique produces this direction: MIS weight 1


def rows_of(kinds: np.ndarray, name: str) -> np.ndarray:
    """Which rows of a light table's ``kind`` column are of the kind ``name`` (a :data:`KINDS` key): a boolean mask.
    Code outside this package asks by name or by flag (:func:`area_rows`), never by a kind's number."""
    return kinds == KINDS[name].code


def area_rows(kinds: np.ndarray) -> np.ndarray:
    """Which rows of a light table's ``kind`` column are area lights (surfaces rays can hit): a boolean mask."""
    return flag_rows(kinds, "area")


def light_counts(kinds: np.ndarray) -> dict:
    """How many rows of a light table's ``kind`` column are of each kind, by the kinds' flags and names: ``lights``
    (every row, the environment's included), ``area_lights`` (surfaces rays can hit), ``point_lights``,
    ``spot_lights``, ``directional_lights``, and whether there is an ``environment``."""
    by_code = {kind.code: kind for kind in KINDS.values()}
    counts = {"lights": int(kinds.shape[0]), "area_lights": 0}
    counts.update({f"{kind.name}_lights": 0 for kind in KINDS.values() if not kind.area and kind.name != "environment"})
    for code, n in zip(*np.unique(kinds, return_counts=True), strict=True):
        kind = by_code[int(code)]
        key = "area_lights" if kind.area else f"{kind.name}_lights"
        counts[key] = counts.get(key, 0) + int(n)
    counts["environment"] = bool(counts.pop("environment_lights", 0))
    return counts


def concatenate(parts) -> LightArrays:
    """One table of the rows of several."""
    parts = list(parts)
    if not parts:
        return LightArrays(
            np.zeros(0, np.int64), np.zeros((0, ROW_WIDTH)), np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(0)
        )
    return LightArrays(
        *(np.ascontiguousarray(np.concatenate([getattr(t, f) for t in parts])) for f in LightArrays._fields)
    )
