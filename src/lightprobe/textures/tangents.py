"""Per-vertex tangents for normal mapping, when a mesh does not store them: MikkTSpace's weighting.

glTF asks for MikkTSpace (Mikkelsen 2008) when a file has no tangents, because normal maps are baked against it.
This follows its evaluation: each triangle's unit dP/du (from its texture coordinates; its orientation, the sign of
its UV area, gives the bitangent's side), projected at each corner onto that vertex's normal and normalised, summed
over the vertex's corners weighted by the corner's angle (measured in the vertex's tangent plane), normalised.
``w`` = +1 or -1 says on which side of cross(n, t) the bitangent lies: toward decreasing v, up the image (glTF's v
points down the rows and its normal maps are "+Y up"; the reference implementation's sign negated, as for glTF).

What is not MikkTSpace's: it splits a vertex whose corners disagree (faces of both orientations meeting there, at a
mirrored chart's edge) into one tangent per group; a mesh vertex here has one, that of the orientation with the
larger weight.  Measured against the reference C code (npm ``mikktspace``, its WebAssembly build; the fixture
``tests/data/mikktspace_reference.json``): equal to float32 rounding on smooth, unmirrored layouts, mirrored ones
included; different only at such vertices and at poles where UVs degenerate.
"""

from __future__ import annotations

import numpy as np

__all__ = ["generate_tangents"]


def _unit(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    length = np.linalg.norm(v, axis=-1, keepdims=True)
    ok = length > 1e-20
    return np.divide(v, length, out=np.zeros_like(v), where=ok), ok[..., 0]


def generate_tangents(vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray, uvs: np.ndarray) -> np.ndarray:
    """(V, 4) unit tangents and handedness for a mesh with unit vertex ``normals`` (V, 3) and ``uvs`` (V, 2)."""
    p = vertices[faces]  # (F, 3, 3)
    t = uvs[faces]  # (F, 3, 2)
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    du1, dv1 = t[:, 1, 0] - t[:, 0, 0], -(t[:, 1, 1] - t[:, 0, 1])  # -v: toward the top of the image
    du2, dv2 = t[:, 2, 0] - t[:, 0, 0], -(t[:, 2, 1] - t[:, 0, 1])
    area = du1 * dv2 - du2 * dv1  # twice the signed UV area: its sign is the face's orientation
    orientation = np.where(area > 0.0, 1.0, -1.0)
    # dP/du scaled by the signed area, made a unit vector pointing along +u (MikkTSpace's vOs)
    face_tangent, _ = _unit((e1 * dv2[:, None] - e2 * dv1[:, None]) * orientation[:, None])
    n_vertices = vertices.shape[0]
    sums = np.zeros((2, n_vertices, 3))  # per orientation (index 0: -1, 1: +1)
    weights = np.zeros((2, n_vertices))
    side = (orientation > 0.0).astype(np.int64)
    for k in range(3):
        vertex = faces[:, k]
        n = normals[vertex]
        tangent = face_tangent - n * np.einsum("ij,ij->i", n, face_tangent)[:, None]
        tangent, ok = _unit(tangent)
        # the corner's angle, between its two edges projected into the vertex's tangent plane
        a = p[:, (k + 1) % 3] - p[:, k]
        b = p[:, (k + 2) % 3] - p[:, k]
        a, _ = _unit(a - n * np.einsum("ij,ij->i", n, a)[:, None])
        b, _ = _unit(b - n * np.einsum("ij,ij->i", n, b)[:, None])
        angle = np.arccos(np.clip(np.einsum("ij,ij->i", a, b), -1.0, 1.0)) * ok
        np.add.at(sums, (side, vertex), tangent * angle[:, None])
        np.add.at(weights, (side, vertex), angle)
    chosen = np.where(weights[1] >= weights[0], 1, 0)
    tangent = sums[chosen, np.arange(n_vertices)]
    tangent, ok = _unit(tangent - normals * np.einsum("ij,ij->i", normals, tangent)[:, None])
    if not ok.all():  # no usable UV gradient: any direction in the tangent plane
        bad = ~ok
        helper = np.where(np.abs(normals[bad, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        tangent[bad], _ = _unit(np.cross(normals[bad], helper))
    w = np.where(chosen == 1, 1.0, -1.0)
    return np.ascontiguousarray(np.column_stack([tangent, w]))
