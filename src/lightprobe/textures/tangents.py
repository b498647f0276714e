"""Per-vertex tangents for normal mapping, when a mesh does not store them.

glTF asks for MikkTSpace tangents when a file has none.  These are Lengyel's (2001): each triangle's dP/du and
dP/d(-v) from its texture coordinates, summed at its vertices, the sum made orthogonal to the vertex normal
(Gram-Schmidt) and normalised; ``w`` = +1 or -1 says whether the bitangent cross(n, t) w runs toward decreasing v
(up the image: glTF's v points down the rows, and its normal maps are "+Y up").  MikkTSpace computes the same frame
on a smooth mesh with a continuous, unmirrored UV layout; it differs where it splits vertices (UV seams, mirrored
charts, hard edges) and in its angle weighting, so a normal map baked against MikkTSpace can show faint seams there.
"""

from __future__ import annotations

import numpy as np

__all__ = ["generate_tangents"]


def generate_tangents(vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray, uvs: np.ndarray) -> np.ndarray:
    """(V, 4) unit tangents and handedness for a mesh with vertex ``normals`` (V, 3) and ``uvs`` (V, 2)."""
    p = vertices[faces]  # (F, 3, 3)
    t = uvs[faces]  # (F, 3, 2)
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    du1, dv1 = t[:, 1, 0] - t[:, 0, 0], -(t[:, 1, 1] - t[:, 0, 1])  # -v: toward the top of the image
    du2, dv2 = t[:, 2, 0] - t[:, 0, 0], -(t[:, 2, 1] - t[:, 0, 1])
    det = du1 * dv2 - du2 * dv1
    ok = np.abs(det) > 1e-300
    inv = np.divide(1.0, det, out=np.zeros_like(det), where=ok)[:, None]
    sdir = (e1 * dv2[:, None] - e2 * dv1[:, None]) * inv  # dP/du
    tdir = (e2 * du1[:, None] - e1 * du2[:, None]) * inv  # dP/d(-v)
    tangent_sum = np.zeros_like(vertices)
    bitangent_sum = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(tangent_sum, faces[:, k], sdir)
        np.add.at(bitangent_sum, faces[:, k], tdir)
    n = normals
    tangent = tangent_sum - n * np.einsum("ij,ij->i", n, tangent_sum)[:, None]
    length = np.linalg.norm(tangent, axis=1)
    bad = ~(length > 1e-12 * np.maximum(np.linalg.norm(tangent_sum, axis=1), 1e-300))
    tangent = np.divide(tangent, length[:, None], out=np.zeros_like(tangent), where=~bad[:, None])
    if bad.any():  # no usable UV gradient: any direction in the tangent plane
        helper = np.where(np.abs(n[bad, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        fallback = np.cross(n[bad], helper)
        tangent[bad] = fallback / np.maximum(np.linalg.norm(fallback, axis=1, keepdims=True), 1e-300)
    w = np.where(np.einsum("ij,ij->i", np.cross(n, tangent), bitangent_sum) < 0.0, -1.0, 1.0)
    return np.ascontiguousarray(np.column_stack([tangent, w]))
