"""The unit icosphere: an icosahedron whose faces are split in four, ``subdivisions`` times, each time with the
vertices pushed out to the sphere.

The demo's blob is built on it (``demo.blob_mesh``). It is written here, not taken from ``trimesh.creation``, because
importing trimesh costs the demo's process about 0.45 s (trimesh imports SciPy's optimisers and parses their
docstrings), for a mesh that takes 3 ms to make (decisions.md 140). It makes trimesh's icosphere bit for bit, the
same vertices in the same order and the same faces (``tests/geometry/test_icosphere.py`` holds the two together), so
that the demo's images did not change: the same NumPy operations in the same order as trimesh's (5.2)
``creation.icosphere`` and ``remesh.subdivide``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["icosphere"]

# trimesh's icosahedron (its resources' "icosahedron"): the 12 vertices (+-a, +-b, 0) and their cyclic permutations,
# a = 0.5257311121191336, b = 0.85065080835204 (a^2 + b^2 = 1), and 20 counter-clockwise faces
_A, _B = 0.5257311121191336, 0.85065080835204
_VERTICES = (
    (-_A, _B, 0.0), (_A, _B, 0.0), (-_A, -_B, 0.0), (_A, -_B, 0.0),
    (0.0, -_A, _B), (0.0, _A, _B), (0.0, -_A, -_B), (0.0, _A, -_B),
    (_B, 0.0, -_A), (_B, 0.0, _A), (-_B, 0.0, -_A), (-_B, 0.0, _A),
)  # fmt: skip
_FACES = (
    (0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2), (10, 7, 6),
    (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7),
    (9, 8, 1),
)  # fmt: skip


def _to_radius(vertices: np.ndarray, radius: float) -> None:
    """Move each vertex along its direction from the origin to distance ``radius`` (in place)."""
    scalar = np.sqrt(np.dot(vertices**2, [1, 1, 1]))
    unit = vertices / scalar.reshape((-1, 1))
    vertices += unit * (radius - scalar).reshape((-1, 1))


def _subdivide(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each face split in four at its edges' midpoints, one midpoint per edge: the midpoints follow the vertices,
    ordered by their edge's (larger, smaller) vertex numbers, and face i becomes faces 4 i .. 4 i + 3 (its corners'
    three, then the middle one)."""
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape((-1, 2)), axis=1)
    # one key per edge, the larger vertex number in the high half: trimesh's order of unique edges
    keys = (edges[:, 1].astype(np.uint64) << np.uint64(32)) | edges[:, 0].astype(np.uint64)
    _, unique, inverse = np.unique(keys, return_index=True, return_inverse=True)
    mid = vertices[edges[unique]].mean(axis=1)
    mid_idx = inverse.reshape((-1, 3)) + len(vertices)
    new_faces = np.column_stack(
        [
            faces[:, 0], mid_idx[:, 0], mid_idx[:, 2],
            mid_idx[:, 0], faces[:, 1], mid_idx[:, 1],
            mid_idx[:, 2], mid_idx[:, 1], faces[:, 2],
            mid_idx[:, 0], mid_idx[:, 1], mid_idx[:, 2],
        ]
    ).reshape((-1, 3))  # fmt: skip
    return np.vstack((vertices, mid)), new_faces


def icosphere(subdivisions: int = 3, radius: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (V, 3) float64, faces (20 4^subdivisions, 3) int64) of the icosphere of ``radius`` about the
    origin, counter-clockwise seen from outside."""
    subdivisions = int(subdivisions)
    if subdivisions < 0:
        raise ValueError(f"subdivisions must be >= 0, got {subdivisions}")
    radius = float(radius)
    vertices = np.array(_VERTICES, dtype=np.float64)
    faces = np.array(_FACES, dtype=np.int64)
    for _ in range(subdivisions):
        vertices, faces = _subdivide(vertices, faces)
        _to_radius(vertices, radius)
    if subdivisions == 0:
        _to_radius(vertices, radius)
    return vertices, faces
