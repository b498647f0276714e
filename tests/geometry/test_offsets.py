"""Rays that leave a surface from the origin intersect.ray_offset gives them (the function the BSDF-ray and shadow
stages call, with the point's error bound) never hit that surface again: on slanted triangles (Embree, float32) and
on slanted parallelograms and spheres (float64), at the origin, 1000 units from it and 100,000 units from it, small
and large, rays grazing the surface included, leaving to either side of it.  A sixty-fourth of a mesh point's bound,
or no offset from an analytic shape, lets rays hit their own surface: the check can fail (and fails when ray_offset
moves the origin a thousandth of the bound).  Measured for meshes: self-hits start between a quarter and a sixteenth
of the bound (decisions.md 68)."""

from __future__ import annotations

import numpy as np
import pytest

from lightprobe._numba import jit_alloc
from lightprobe.bsdfs import Lambert
from lightprobe.emitters.envmap import EnvironmentMap
from lightprobe.geometry.camera import Camera
from lightprobe.geometry.intersect import (
    ANALYTIC_ERROR,
    MESH,
    RECT,
    SPHERE,
    point_error,
    ray_offset,
    triangle_error,
)
from lightprobe.geometry.mesh import TriangleMesh
from lightprobe.geometry.raytracer import RayTracer
from lightprobe.geometry.shapes import Rectangle, Sphere
from lightprobe.scene import Scene

PLACES = [
    ((0.0, 0.0, 0.0), 1.0),
    ((1000.0, 0.0, -1000.0), 1.0),
    ((1000.0, 0.0, -1000.0), 0.01),
    ((1e5, 0.0, 0.0), 10.0),
]


@jit_alloc
def _triangle_errors(a, b, c, n):
    out = np.empty(a.shape[0])
    for i in range(a.shape[0]):
        out[i] = triangle_error(a[i, 0], a[i, 1], a[i, 2], b[i, 0], b[i, 1], b[i, 2], c[i, 0], c[i, 1], c[i, 2], n[i])
    return out


@jit_alloc
def _point_errors(p, n, extent):
    out = np.empty(p.shape[0])
    for i in range(p.shape[0]):
        out[i] = point_error(ANALYTIC_ERROR, p[i, 0], p[i, 1], p[i, 2], n[i, 0], n[i, 1], n[i, 2], extent[i])
    return out


@jit_alloc
def _origins(p, n, error, d):
    """The origins :func:`ray_offset` gives rays leaving points p (normals n, error bounds ``error``) along d."""
    out = np.empty(p.shape)
    for i in range(p.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = ray_offset(
            p[i, 0], p[i, 1], p[i, 2], n[i, 0], n[i, 1], n[i, 2], error[i], d[i, 0], d[i, 1], d[i, 2]
        )
    return out


def _leaving(rng, n):
    """Unit directions, half of them on the side of normals n and half on the other (two-sided surfaces: ray_offset
    must move the origin to the side the ray goes to), a third of them within about half a degree of the surface."""
    d = rng.normal(size=n.shape)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    grazing = rng.random(n.shape[0]) < 1 / 3
    d[grazing] -= 0.99 * (d[grazing] * n[grazing]).sum(axis=1, keepdims=True) * n[grazing]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    side = np.where(rng.random((n.shape[0], 1)) < 0.5, -1.0, 1.0)
    return d * np.sign((d * n).sum(axis=1, keepdims=True)) * side


def _own_hits(tracer, p, n, error, d, kind, own, near=None):
    """Rays from the origins ray_offset gives (p, its normal n and error bound, direction d) that hit their own shape
    first (closer than ``near``, when the shape has a far side a ray may rightly reach)."""
    t, hit_kind, index, prim, _, _ = tracer.intersect(_origins(p, n, error, d), d)
    which = prim if kind == MESH else index
    close = np.isfinite(t) if near is None else t < near
    return int(np.count_nonzero((hit_kind == kind) & (which == own) & close))


def _tracer(scene_objects):
    scene = Scene(Camera([0, 0, 5], [0, 0, 0]), EnvironmentMap.from_array(np.ones((2, 4, 3), np.float32)))
    for shape in scene_objects:
        scene.add(shape, Lambert(0.5), two_sided=True)
    return RayTracer(scene.compile())


@pytest.mark.parametrize(("centre", "size"), PLACES)
def test_rays_leaving_a_triangle_never_hit_it(centre, size):
    rng = np.random.default_rng(1)
    count, rays = 64, 20_000
    corners = (
        np.asarray(centre)
        + np.arange(count)[:, None, None] * [10.0 * size, 0, 0]
        + rng.normal(size=(count, 3, 3)) * size
    )
    vertices = corners.reshape(-1, 3)
    tracer = _tracer([TriangleMesh.from_arrays(vertices, np.arange(3 * count).reshape(-1, 3), smooth=False)])
    face = rng.integers(0, count, rays)
    a, b, c = corners[face, 0], corners[face, 1], corners[face, 2]
    w = rng.random((rays, 2))
    w[w.sum(axis=1) > 1] = 1 - w[w.sum(axis=1) > 1]
    p = a + w[:, :1] * (b - a) + w[:, 1:] * (c - a)
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    d = _leaving(rng, n)
    error = _triangle_errors(a, b, c, n)
    try:
        assert _own_hits(tracer, p, n, error, d, MESH, face) == 0
        assert _own_hits(tracer, p, n, error / 64, d, MESH, face) > rays // 100
    finally:
        tracer.close()


@pytest.mark.parametrize(("centre", "size"), PLACES)
def test_rays_leaving_a_parallelogram_or_a_sphere_never_hit_it(centre, size):
    rng = np.random.default_rng(2)
    count, rays = 20, 20_000
    o = np.asarray(centre, dtype=np.float64)
    corner = o + np.arange(count)[:, None] * [10.0 * size, 0, 0] + rng.normal(size=(count, 3)) * size
    u, v = rng.normal(size=(count, 3)) * size, rng.normal(size=(count, 3)) * size
    centres = o + np.arange(count)[:, None] * [10.0 * size, 0, 0] + [0, 5.0 * size, 0]
    radius = rng.uniform(0.2, 1.0, count) * size
    shapes = [Rectangle(corner[i], u[i], v[i]) for i in range(count)]
    shapes += [Sphere(centres[i], radius[i]) for i in range(count)]
    tracer = _tracer(shapes)
    try:
        which = rng.integers(0, count, rays)
        # parallelograms: points projected onto the plane as intersect.surface does, error from their extent
        ab = rng.random((rays, 2))
        p = corner[which] + ab[:, :1] * u[which] + ab[:, 1:] * v[which]
        n = np.cross(u[which], v[which])
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        extent = np.maximum(np.abs(u[which]).max(axis=1), np.abs(v[which]).max(axis=1))
        error = _point_errors(p, n, extent)
        d = _leaving(rng, n)
        assert _own_hits(tracer, p, n, error, d, RECT, which) == 0
        assert _own_hits(tracer, p, n, np.zeros(rays), d, RECT, which) > rays // 100
        # spheres: points c + r n, error from the radius
        n = rng.normal(size=(rays, 3))
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        p = centres[which] + radius[which, None] * n
        error = _point_errors(p, n, radius[which])
        d = _leaving(rng, n)
        # a ray into the sphere rightly meets its far side, 2 r |cos| away: a hit at less than half that is its own
        half_chord = radius[which] * np.abs((d * n).sum(axis=1))
        assert _own_hits(tracer, p, n, error, d, SPHERE, which, near=half_chord) == 0
        assert _own_hits(tracer, p, n, np.zeros(rays), d, SPHERE, which, near=half_chord) > rays // 100
    finally:
        tracer.close()
