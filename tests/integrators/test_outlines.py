"""The outline control variate (integrators/outlines.py): each pixel's exact share of an emitter's projection, the
same set as a camera sample's membership test and as the light's own intersection, the shapes it leaves out, and
renders that keep their mean while the outlines' noise goes (also far from the origin and behind an occluder)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lightprobe.bsdfs import Lambert
from lightprobe.emitters.area import light_intersect
from lightprobe.geometry.camera import Camera
from lightprobe.geometry.mesh import TriangleMesh
from lightprobe.geometry.shapes import Rectangle, Sphere
from lightprobe.integrators import outlines
from lightprobe.integrators.outlines import (
    _ellipse_entries,
    _Film,
    _inside,
    _polygon_entries,
    _shapes,
    disk_polygon_area,
)
from lightprobe.integrators.wavefront import RenderSettings, render
from lightprobe.scene import Scene


def _disk_area(points) -> float:
    p = np.asarray(points, np.float64)
    return float(disk_polygon_area(np.ascontiguousarray(p[:, 0]), np.ascontiguousarray(p[:, 1]), len(p)))


def test_the_disk_and_a_polygon_meet_in_their_closed_form_areas():
    """The unit disk inside a large square (pi), a square inside the disk (its area), the half-plane x >= 0 (pi / 2),
    x >= 0.5 (the circular segment acos(0.5) - 0.5 sqrt(0.75)), a triangle with one vertex at the centre (a sector
    of 45 degrees, pi / 8), and a square far off the disk (0)."""
    assert _disk_area([(-5, -5), (5, -5), (5, 5), (-5, 5)]) == pytest.approx(math.pi, rel=1e-12)
    assert _disk_area([(-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)]) == pytest.approx(1.0, rel=1e-12)
    assert _disk_area([(0, -2), (2, -2), (2, 2), (0, 2)]) == pytest.approx(math.pi / 2, rel=1e-12)
    segment = math.acos(0.5) - 0.5 * math.sqrt(0.75)
    assert _disk_area([(0.5, -2), (2, -2), (2, 2), (0.5, 2)]) == pytest.approx(segment, rel=1e-12)
    assert _disk_area([(0, 0), (3, 0), (3, 3)]) == pytest.approx(math.pi / 8, rel=1e-12)
    assert _disk_area([(3, 3), (4, 3), (4, 4), (3, 4)]) == 0.0


def _scene(*emitters, camera=None, offset=(0.0, 0.0, 0.0)):
    """A camera and emitters (shape, emission, two_sided), all moved by ``offset``."""
    off = np.asarray(offset, np.float64)
    cam = camera or Camera(np.array([0.0, 0.0, 5.0]) + off, off, fov=40, resolution=(48, 36))
    scene = Scene(cam)
    for shape, emission, two_sided in emitters:
        if isinstance(shape, Sphere):
            shape = Sphere(shape.center + off, shape.radius)
        elif isinstance(shape, Rectangle):
            shape = Rectangle(shape.origin + off, shape.edge_u, shape.edge_v)
        else:
            shape = TriangleMesh.from_arrays(shape.vertices + off, shape.faces)
        scene.add(shape, Lambert(0.0), emission=emission, two_sided=two_sided)
    return scene


SPHERE = Sphere([0.3, -0.2, 0.0], 0.45)
SLANTED = Rectangle([-0.6, -0.3, 0.2], [1.0, 0.2, -0.5], [-0.1, 0.7, 0.3])  # normal (u x v) toward the camera
TRIANGLE = TriangleMesh.from_arrays(
    np.array([[-0.9, -0.6, 0.0], [0.7, -0.4, 0.4], [0.1, 0.8, -0.3]]), np.array([[0, 1, 2]])
)
WIDE = Camera([0.0, 0.0, 5.0], [0.0, 0.0, 0.0], fov=100, resolution=(48, 36))
CASES = {
    "sphere": ((SPHERE, 5.0, False),),
    "sphere-near-the-corner-of-a-wide-view": ((Sphere([-4.2, 2.9, 0.5], 0.6), 5.0, False),),
    "slanted-rectangle": ((SLANTED, 5.0, False),),
    "triangle": ((TRIANGLE, 5.0, False),),
}


def _grid_share(camera, pixel, test, n=64) -> float:
    """The share of an n x n grid of film points of ``pixel`` whose camera ray passes ``test`` (the camera's own
    rays, geometry/camera.py)."""
    a = (np.arange(n) + 0.5) / n
    offsets = np.stack(np.meshgrid(a, a, indexing="ij"), axis=-1).reshape(-1, 2)
    _, dirs = camera.rays(np.full(n * n, pixel), offsets)
    return float(np.mean([test(d) for d in dirs]))


@pytest.mark.parametrize("offset", [0.0, 1000.0], ids=["at-the-origin", "translated-by-1000"])
@pytest.mark.parametrize("case", list(CASES))
def test_a_pixels_cover_is_the_share_of_its_rays_that_meet_the_light(case, offset):
    """Every entry's coverage against the share of a 64 x 64 grid of the pixel's camera rays that the sample's
    membership test (``_inside``) passes, and that the light's own intersection (``light_intersect``, what a camera
    ray hits) meets.  The grid's own error was measured at most 0.001 a pixel and 0.0035 summed over an outline, so
    a pixel within 0.004 and the outline's sum within 0.012 (a sphere's radius 0.1 % off moves that sum by 0.03);
    the two tests agree but for a ray or two on the edge."""
    camera = WIDE if "wide" in case else None
    if camera is not None and offset:
        camera = Camera(camera.origin + offset, camera.target + offset, fov=100, resolution=(48, 36))
    scene = _scene(*CASES[case], camera=camera, offset=(offset, offset, offset))
    lights = scene.light_table()
    table = outlines.table(scene.camera, lights, None)
    assert table.cover.size >= 12, "the outline crosses a dozen pixels at least"
    o = scene.camera.origin
    errors = []
    for e in range(table.cover.size):
        pixel = int(np.searchsorted(table.start, e, side="right") - 1)
        row = table.geom[table.shape[e]]
        share = _grid_share(scene.camera, pixel, lambda d, row=row: _inside(row, d[0], d[1], d[2]))
        hit = _grid_share(scene.camera, pixel, lambda d: light_intersect(lights, 0, o[0], o[1], o[2], *d)[0] < math.inf)
        assert abs(share - hit) <= 2.0 / 64**2, (pixel, share, hit)
        errors.append(share - table.cover[e])
    assert np.max(np.abs(errors)) < 0.004
    assert abs(np.sum(errors)) < 0.012


@pytest.mark.parametrize("case", ["sphere", "slanted-rectangle", "triangle"])
def test_the_covers_of_every_pixel_add_up_to_the_projected_area(case):
    """Over every pixel the shape touches (covered whole or in part), the covers sum to the projection's area: the
    ellipse's pi / sqrt(det S), the polygon's shoelace area."""
    scene = _scene(*CASES[case])
    film = _Film(scene.camera)
    shapes = _shapes(film, scene.light_table())
    assert shapes.light.size == 1
    n = int(shapes.poly_n[0])
    if n:
        x, y = shapes.poly_x[0, :n].copy(), shapes.poly_y[0, :n].copy()
        _, covers = _polygon_entries(x, y, film.width, film.height)
        area = 0.5 * abs(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
    else:
        ellipse = shapes.ellipses[0]
        _, covers = _ellipse_entries(*ellipse, film.width, film.height)
        area = math.pi / (ellipse[2] * ellipse[4])
    assert covers.sum() == pytest.approx(area, rel=1e-9)
    assert covers.max() <= 1.0


def test_the_shapes_it_leaves_out():
    """A one-sided rectangle seen from its back (it sends nothing to the camera), a sphere across the camera's plane
    and a rectangle partly behind the camera get no entries; the same rectangle two-sided, seen from its back, does."""
    back = Rectangle([-0.5, -0.5, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0])  # u x v = -z: faces away from the camera
    one_sided = _scene((back, 5.0, False))
    assert outlines.table(one_sided.camera, one_sided.light_table(), None).cover.size == 0
    two_sided = _scene((back, 5.0, True))
    assert outlines.table(two_sided.camera, two_sided.light_table(), None).cover.size > 0
    across = _scene((Sphere([0.0, 0.0, 5.2], 0.5), 5.0, False))
    assert outlines.table(across.camera, across.light_table(), None).cover.size == 0
    behind = _scene((Rectangle([-0.5, -0.5, 3.0], [1.0, 0.0, 0.0], [0.0, 0.0, 4.0]), 5.0, True))
    assert outlines.table(behind.camera, behind.light_table(), None).cover.size == 0


def test_no_entry_where_two_emitters_overlap_and_a_neighbour_keeps_its_own():
    """Two panels overlapping on screen, one (long and slanted, its nearest corner closest to the camera) behind the
    other where they overlap: no pixel both touch keeps an entry of either (an order by distance kept the wrong one
    here); the long one keeps its outline elsewhere (the small one lies wholly over it).  Two triangles sharing an
    edge (one emissive mesh): the pixels along the edge keep both (they do not overlap)."""
    long = Rectangle([-0.4, -0.6, 3.0], [0.0, 0.5, -6.0], [0.8, 0.0, 0.0])  # from z = 3 to z = -3, tilted
    front = Rectangle([-0.15, -0.3, 0.5], [0.3, 0.0, 0.0], [0.0, 0.3, 0.0])  # at z = 0.5, over long's far part
    scene = _scene((long, 5.0, True), (front, 2.0, False))
    table = outlines.table(scene.camera, scene.light_table(), None)
    film = _Film(scene.camera)
    shapes = _shapes(film, scene.light_table())
    assert shapes.light.size == 2 and shapes.light[0] == 0, "the long panel's nearest corner is the nearer"
    touched = []
    for i in range(2):
        n = int(shapes.poly_n[i])
        pixels, _ = _polygon_entries(shapes.poly_x[i, :n].copy(), shapes.poly_y[i, :n].copy(), film.width, film.height)
        touched.append(set(pixels.tolist()))
    both = touched[0] & touched[1]
    assert len(both) > 10
    assert all(table.start[p] == table.start[p + 1] for p in both), "no entry where the two may overlap"
    assert table.cover.size > 0 and np.all(table.radiance == 5.0), "the long panel keeps its outline elsewhere"
    quad = TriangleMesh.from_arrays(
        np.array([[-0.6, -0.5, 0.0], [0.6, -0.5, 0.0], [0.6, 0.5, 0.0], [-0.6, 0.5, 0.0]]),
        np.array([[0, 1, 2], [0, 2, 3]]),
    )
    scene = _scene((quad, 5.0, False))
    table = outlines.table(scene.camera, scene.light_table(), None)
    both = [p for p in range(table.start.size - 1) if table.start[p + 1] - table.start[p] == 2]
    assert len(both) >= 10, "the pixels along the shared diagonal keep both triangles"


def _lit_wall(offset=0.0, occluder=False, wall=True):
    """A small bright sphere light (about 5 pixels across) seen directly before a Lambert wall it lights (or, without
    ``wall``, against nothing: camera rays that miss); ``occluder``: a grey ball in front hides part of its outline."""
    off = np.full(3, offset)
    scene = Scene(Camera(np.array([0.0, 0.0, 4.0]) + off, off, fov=30, resolution=(32, 24)))
    if wall:
        scene.add(Rectangle(np.array([-3.0, -3.0, -1.0]) + off, [6.0, 0.0, 0.0], [0.0, 6.0, 0.0]), Lambert(0.5))
    scene.add(Sphere(np.array([0.2, 0.1, 0.0]) + off, 0.15), Lambert(0.0), emission=[60.0, 45.0, 30.0])
    if occluder:
        scene.add(Sphere(np.array([0.26, 0.1, 1.5]) + off, 0.06), Lambert(0.5))
    return scene


def _outline_pixels(scene, seen: bool = False) -> np.ndarray:
    """(H, W) bool: the pixels an emitter's outline crosses (``seen``: where the camera sees the emitter there)."""
    geometry, visible = _tables(scene)
    table = visible if seen else geometry
    w, h = scene.camera.resolution
    return (np.diff(table.start) > 0).reshape(h, w)


@pytest.mark.parametrize(
    ("occluder", "wall"), [(False, True), (True, True), (False, False)], ids=["in-the-open", "partly-hidden", "missed"]
)
def test_the_outline_keeps_its_mean_and_loses_its_noise(occluder, wall):
    """64 spp with and without the control variate, against a 4096-spp render without it: over the outline's pixels
    the sum of the image is the reference's (pooled z within 4, red channel) and each pixel within 5 sigma; in the
    open the outline's variance (the renderer's own estimate, summed) falls at least 20-fold (measured: 8,900-fold
    before the wall, where only the wall's shading is left; none left where the rays that miss see nothing)."""
    scene = _lit_wall(occluder=occluder, wall=wall)
    mask = _outline_pixels(scene)
    assert mask.sum() >= 8
    ref = render(scene, RenderSettings(spp=4096, seed=7, outline_control_variate=False))
    with_cv = render(scene, RenderSettings(spp=64, seed=1))
    without = render(scene, RenderSettings(spp=64, seed=1, outline_control_variate=False))
    for result in (with_cv, without):
        diff = (result.image[..., 0] - ref.image[..., 0])[mask].astype(np.float64)
        var = (result.variance[..., 0] + ref.variance[..., 0])[mask].astype(np.float64)
        assert abs(diff.sum()) / math.sqrt(var.sum()) < 4.0
        assert np.all(np.abs(diff) / np.sqrt(var + 1e-12) < 5.0)
    served = _outline_pixels(scene, seen=True)
    assert with_cv.stats["outline_pixels"] == served.sum() and without.stats["outline_pixels"] == 0
    assert served.sum() < mask.sum() if occluder else np.array_equal(served, mask), "the ball hides part of it"
    noise_with, noise_without = with_cv.variance[..., 0][mask].sum(), without.variance[..., 0][mask].sum()
    if not occluder:
        assert noise_with * 20 < noise_without, (noise_with, noise_without)


def test_far_from_the_origin_the_outline_renders_the_same():
    """The lit wall moved by 1000 along each axis, against itself at the origin (both with the control variate, 256
    spp, other seeds): per pixel within 5 sigma, pooled over the image within 4."""
    here = render(_lit_wall(), RenderSettings(spp=256, seed=3))
    there = render(_lit_wall(offset=1000.0), RenderSettings(spp=256, seed=4))
    diff = (here.image[..., 0] - there.image[..., 0]).astype(np.float64)
    var = (here.variance[..., 0] + there.variance[..., 0]).astype(np.float64) + 1e-10
    assert np.all(np.abs(diff) / np.sqrt(var) < 5.0)
    assert abs(diff.sum()) / math.sqrt(var.sum()) < 4.0
    assert _outline_pixels(_lit_wall(offset=1000.0)).sum() == _outline_pixels(_lit_wall()).sum()


# --- visibility: entries only where the camera sees the emitter (issue 57) ----------------------------------------
def _occluded_scene(case: str) -> Scene:
    """A light and what hides it, at 48 x 36: ``behind-a-wall``, a ceiling panel of the next room whose outline
    projects onto the wall in front of it (the building of issue 57); ``behind-a-pillar``, a sphere light with a thin
    post in front of its middle; ``half-hidden``, a panel whose left half a wall's edge hides."""
    scene = Scene(Camera([0.0, 1.0, 5.0], [0.0, 1.0, 0.0], fov=40, resolution=(48, 36)))
    grey = Lambert(0.5)
    if case == "behind-a-wall":
        scene.add(Rectangle([-3.0, -1.0, 0.0], [6.0, 0.0, 0.0], [0.0, 4.0, 0.0]), grey)
        # faces down (u x v = -y), seen from below: its emitting side toward the camera
        scene.add(Rectangle([-0.4, 2.5, -1.4], [0.8, 0.0, 0.0], [0.0, 0.0, 0.8]), Lambert(0.0), emission=40.0)
        scene.add(Rectangle([-3.0, -0.2, -3.0], [0.0, 0.0, 6.0], [6.0, 0.0, 0.0]), grey)  # the floor, lit
    elif case == "behind-a-pillar":
        scene.add(Sphere([0.0, 1.0, 0.0], 0.5), Lambert(0.0), emission=30.0)
        scene.add(Rectangle([-0.04, -1.0, 2.0], [0.08, 0.0, 0.0], [0.0, 4.0, 0.0]), grey)
        scene.add(Rectangle([-3.0, -3.0, -1.0], [6.0, 0.0, 0.0], [0.0, 6.0, 0.0]), grey)
    else:
        scene.add(Rectangle([-0.5, 0.5, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]), Lambert(0.0), emission=20.0)
        scene.add(Rectangle([-3.0, -2.0, 2.0], [3.02, 0.0, 0.0], [0.0, 6.0, 0.0]), grey)
        scene.add(Rectangle([-3.0, -3.0, -1.0], [6.0, 0.0, 0.0], [0.0, 6.0, 0.0]), grey)
    return scene


def _tables(scene):
    """(the table of the geometry alone, the table of what the camera sees)."""
    from lightprobe.geometry.raytracer import RayTracer

    tracer = RayTracer(scene.compile())
    try:
        return outlines.table(scene.camera, scene.light_table(), None), outlines.table(
            scene.camera, scene.light_table(), tracer
        )
    finally:
        tracer.close()


def _hidden_share(scene, pixel, row, n=48) -> float:
    """The share of an n x n grid of the pixel's camera rays inside the shape of ``row`` whose nearest hit is not an
    emitter (the tests' scenes have one)."""
    from lightprobe.geometry.intersect import RECT, SPHERE
    from lightprobe.geometry.raytracer import RayTracer

    a = (np.arange(n) + 0.5) / n
    offsets = np.stack(np.meshgrid(a, a, indexing="ij"), axis=-1).reshape(-1, 2)
    origins, dirs = scene.camera.rays(np.full(n * n, pixel), offsets)
    inside = np.array([_inside(row, *d) for d in dirs])
    arrays = scene.compile()
    tracer = RayTracer(arrays)
    try:
        _, kind, index, *_ = tracer.intersect(origins[inside], dirs[inside])
    finally:
        tracer.close()
    light = np.full(kind.shape, -1)
    light[kind == SPHERE] = arrays.sphere_light[index[kind == SPHERE]]
    light[kind == RECT] = arrays.rect_light[index[kind == RECT]]
    return float(np.mean(light < 0))


def _pixels(table) -> set[int]:
    return set(np.flatnonzero(np.diff(table.start)).tolist()) if table.start.size else set()


OCCLUDED = ["behind-a-wall", "behind-a-pillar", "half-hidden"]


@pytest.mark.parametrize("case", OCCLUDED)
def test_no_entry_where_something_hides_the_emitter(case):
    """The geometry alone gives the emitter an outline (a dozen pixels at least); with the scene's rays, every entry
    kept is a pixel where a 48 x 48 grid of camera rays inside the shape all see the emitter, and every entry dropped
    one where some of them do not: behind the wall none is kept, behind the pillar and the wall's edge some are."""
    scene = _occluded_scene(case)
    geometry, seen = _tables(scene)
    everywhere, kept = _pixels(geometry), _pixels(seen)
    assert len(everywhere) >= 12
    assert kept <= everywhere
    if case == "behind-a-wall":
        assert not kept
    else:
        assert 6 <= len(kept) < len(everywhere)
    start = geometry.start
    for pixel in everywhere:
        row = geometry.geom[geometry.shape[start[pixel]]]
        hidden = _hidden_share(scene, pixel, row)
        if pixel in kept:
            assert hidden == 0.0, (pixel, hidden)
        else:
            assert hidden > 0.0, (pixel, hidden)


@pytest.mark.parametrize("case", OCCLUDED)
def test_a_hidden_emitter_adds_no_noise(case):
    """64 spp with and without the control variate, uniform counts, the same seed: a pixel without an entry renders
    the same bits either way (behind the wall: the whole image; with every entry kept, the wall's pixels took -40 on
    the hidden panel's rays and +40 a, new noise), and where entries are kept the outline's variance falls at least
    ten-fold with the same mean (pooled z within 4)."""
    scene = _occluded_scene(case)
    _, seen = _tables(scene)
    w, h = scene.camera.resolution
    served = np.zeros(w * h, bool)
    served[list(_pixels(seen))] = True
    served = served.reshape(h, w)
    on = render(scene, RenderSettings(spp=64, seed=1, adaptive=False))
    off = render(scene, RenderSettings(spp=64, seed=1, adaptive=False, outline_control_variate=False))
    assert on.stats["outline_pixels"] == served.sum()
    assert np.array_equal(on.image[~served], off.image[~served])
    if served.any():
        diff = (on.image[..., 0] - off.image[..., 0])[served].astype(np.float64)
        var = (on.variance[..., 0] + off.variance[..., 0])[served].astype(np.float64)
        assert abs(diff.sum()) / math.sqrt(var.sum()) < 4.0
        assert on.variance[..., 0][served].sum() * 10 < off.variance[..., 0][served].sum()
