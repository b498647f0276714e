"""The light table of a scene: one row per emitter (:class:`~.kinds.LightArrays`), built from its shapes and lights.

Rows in the order the renderer numbers them: the emissive spheres, then rectangles, then each face of each emissive
mesh (the order ``Scene.compile`` gives the surfaces, so a hit's surface finds its row), then the point and spot
lights, then the infinite ones (directional lights and suns), and the environment last (``selection.py`` checks it).
"""

from __future__ import annotations

import numpy as np

from ..geometry.intersect import RECT_WIDTH, rectangle_rows_of
from ..geometry.mesh import TriangleMesh
from ..geometry.shapes import Rectangle, Sphere
from .kinds import KINDS, LightArrays, concatenate
from .lights import light_arrays

__all__ = ["light_table"]


def light_table(emitters, lights, *, environment: bool) -> LightArrays:
    """The table (world space) of ``emitters`` (objects with ``shape``, ``emission`` and ``two_sided``: a scene's
    emissive objects, in its order) and ``lights`` (point, spot, directional lights, suns), with a last row for the
    environment map when ``environment``."""
    spheres = [o for o in emitters if isinstance(o.shape, Sphere)]
    rects = [o for o in emitters if isinstance(o.shape, Rectangle)]
    sphere_geom = np.zeros((len(spheres), RECT_WIDTH))
    sphere_geom[:, :4] = np.array([[*o.shape.center, o.shape.radius] for o in spheres]).reshape(-1, 4)
    rect_geom = rectangle_rows_of([o.shape for o in rects])
    # built as arrays, not one AreaLight each: a scene file with 100,000 rectangle lights (issue 32)
    analytic = LightArrays(
        np.array([KINDS["sphere"].code] * len(spheres) + [KINDS["rectangle"].code] * len(rects), np.int64),
        np.ascontiguousarray(np.concatenate([sphere_geom, rect_geom])),
        np.array([o.emission for o in spheres + rects], np.float64).reshape(-1, 3),
        np.array([o.two_sided for o in spheres + rects], np.int64),
        np.concatenate(
            [
                4.0 * np.pi * sphere_geom[:, 3] ** 2,
                np.linalg.norm(np.cross(rect_geom[:, 3:6], rect_geom[:, 6:9]), axis=1),
            ]
        ),
    )
    meshes = [_triangle_lights(o.shape, o.emission, o.two_sided) for o in emitters if isinstance(o.shape, TriangleMesh)]
    # after every surface's rows, so compile()'s numbering of those holds; bounded lights before infinite ones
    bounded = [x for x in lights if not KINDS[x.kind].infinite]
    infinite = [x for x in lights if KINDS[x.kind].infinite]
    lamps = light_arrays(bounded + infinite, environment=environment)
    return concatenate([analytic, *meshes, lamps])


def _triangle_lights(mesh: TriangleMesh, emission, two_sided: bool):
    """The light table rows of an emissive mesh, one per face."""
    v = mesh.vertices[mesh.faces]  # (F, 3, 3)
    cross = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    length = np.linalg.norm(cross, axis=1)
    f = v.shape[0]
    return LightArrays(
        np.full(f, KINDS["triangle"].code, np.int64),
        np.ascontiguousarray(
            np.concatenate([v.reshape(-1, 9), cross / length[:, None], np.zeros((f, RECT_WIDTH - 12))], axis=1)
        ),
        np.ascontiguousarray(np.broadcast_to(np.asarray(emission, dtype=np.float64), (f, 3))),
        np.full(f, int(two_sided), np.int64),
        0.5 * length,
    )
