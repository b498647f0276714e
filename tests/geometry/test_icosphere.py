"""The icosphere the demo's blob is made of: trimesh's, bit for bit (the demo's images must not change), closed and
outward-facing, on the sphere."""

import numpy as np
import pytest
import trimesh

from lightprobe.geometry.icosphere import icosphere


@pytest.mark.parametrize("radius", [1.0, 0.7])
@pytest.mark.parametrize("subdivisions", [0, 1, 2, 5])
def test_the_same_vertices_and_faces_as_trimesh(subdivisions, radius):
    vertices, faces = icosphere(subdivisions, radius)
    theirs = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    assert vertices.dtype == np.float64 and faces.dtype == np.int64
    assert np.array_equal(vertices, theirs.vertices)  # every bit, in the same order
    assert np.array_equal(faces, theirs.faces)


@pytest.mark.parametrize("subdivisions", [0, 3])
def test_a_closed_sphere_facing_out(subdivisions):
    vertices, faces = icosphere(subdivisions, 2.0)
    assert faces.shape == (20 * 4**subdivisions, 3)
    assert np.allclose(np.linalg.norm(vertices, axis=1), 2.0, rtol=1e-14)
    # every edge shared by exactly two faces, once in each direction: closed and consistently wound
    edges = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    assert len({tuple(e) for e in edges}) == len(edges)
    assert {tuple(e) for e in edges} == {(b, a) for a, b in edges}
    a, b, c = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    outward = np.einsum("ij,ij->i", np.cross(b - a, c - a), a + b + c)
    assert np.all(outward > 0)
    # volume of the inscribed polyhedron: below the sphere's, closer with each subdivision
    volume = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0
    assert 0.6 * (4 / 3 * np.pi * 8) < volume < 4 / 3 * np.pi * 8


def test_negative_subdivisions_are_refused():
    with pytest.raises(ValueError, match="subdivisions must be >= 0"):
        icosphere(-1)
