"""Meshes: every file format, normals, validation of degenerate input, transforms."""

from __future__ import annotations

import gzip
import shutil

import numpy as np
import pytest
import trimesh

from lightprobe.errors import LightprobeWarning, SceneError
from lightprobe.geometry.mesh import TriangleMesh, angle_weighted_normals

from ..conftest import DATA, requires_data


@pytest.fixture(scope="module")
def box():
    return trimesh.creation.box(extents=(1, 2, 3))


@pytest.mark.parametrize("ext", ["obj", "ply", "glb", "stl", "ply.gz"])
def test_formats(tmp_path, box, ext):
    path = tmp_path / f"box.{ext}"
    if ext == "ply.gz":
        box.export(tmp_path / "box.ply")
        with open(tmp_path / "box.ply", "rb") as src, gzip.open(path, "wb") as dst:
            shutil.copyfileobj(src, dst)
    else:
        box.export(path)
    mesh = TriangleMesh.load(path)
    assert mesh.triangle_count == 12
    np.testing.assert_allclose(mesh.bounds, [[-0.5, -1, -1.5], [0.5, 1, 1.5]], atol=1e-6)
    assert mesh.normals is not None and np.allclose(np.linalg.norm(mesh.normals, axis=1), 1)


def test_file_normals_are_kept_and_flat_option(tmp_path):
    """A PLY whose stored normals all point +X (not the geometric +Z): they must survive loading."""
    path = tmp_path / "n.ply"
    header = (
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
        "property float nx\nproperty float ny\nproperty float nz\nelement face 1\n"
        "property list uchar int vertex_indices\nend_header\n"
    )
    path.write_text(header + "0 0 0 1 0 0\n1 0 0 1 0 0\n0 1 0 1 0 0\n3 0 1 2\n")
    np.testing.assert_allclose(TriangleMesh.load(path).normals, [[1, 0, 0]] * 3)
    assert TriangleMesh.load(path, smooth=False).normals is None


def test_angle_weighted_normals_of_a_cube_corner():
    box = trimesh.creation.box()
    n = angle_weighted_normals(np.asarray(box.vertices), np.asarray(box.faces))
    # at a cube corner the three faces meet at equal angles: the normal is the diagonal
    np.testing.assert_allclose(np.abs(n), 1 / np.sqrt(3), atol=1e-12)


def test_validation():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)
    with pytest.warns(LightprobeWarning, match="dropped 2 degenerate"):
        mesh = TriangleMesh.from_arrays(v, [[0, 1, 2], [0, 0, 1], [0, 1, 1]], name="m")
    assert mesh.triangle_count == 1
    with pytest.raises(SceneError, match="all 1 triangles are degenerate"):
        TriangleMesh.from_arrays(v, [[0, 0, 0]], name="m")
    with pytest.raises(SceneError, match="out of range"):
        TriangleMesh.from_arrays(v, [[0, 1, 7]], name="m")
    bad = v.copy()
    bad[1, 0] = np.nan
    with pytest.raises(SceneError, match="m: 1 vertices are NaN"):
        TriangleMesh.from_arrays(bad, [[0, 1, 2]], name="m")
    with pytest.raises(SceneError, match="non-empty"):
        TriangleMesh.from_arrays(np.zeros((0, 3)), [[0, 1, 2]], name="m")
    with pytest.raises(SceneError, match="integers"):
        TriangleMesh.from_arrays(v, [[0.0, 1.0, 2.0]], name="m")
    collinear = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], float)
    with pytest.raises(SceneError, match="degenerate"):
        TriangleMesh.from_arrays(collinear, [[0, 1, 2]], name="m")


def test_invalid_stored_normals_are_replaced():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    with pytest.warns(LightprobeWarning, match="replaced 1"):
        mesh = TriangleMesh.from_arrays(v, [[0, 1, 2]], normals=[[0, 0, 1], [0, 0, 0], [0, 0, 2]], name="m")
    np.testing.assert_allclose(mesh.normals, [[0, 0, 1]] * 3)


def test_bad_files(tmp_path):
    with pytest.raises(SceneError, match="no such file"):
        TriangleMesh.load(tmp_path / "none.obj")
    (tmp_path / "junk.ply").write_bytes(b"ply\nformat nonsense\n")
    with pytest.raises(SceneError, match=r"junk\.ply"):
        TriangleMesh.load(tmp_path / "junk.ply")
    (tmp_path / "empty.obj").write_text("# nothing\n")
    with pytest.raises(SceneError, match=r"empty\.obj"):
        TriangleMesh.load(tmp_path / "empty.obj")


def test_transform_moves_points_and_normals():
    mesh = TriangleMesh.from_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], name="t")
    m = np.diag([2.0, 1.0, 1.0, 1.0])
    m[:3, 3] = [0, 0, 5]
    out = mesh.transformed(m)
    np.testing.assert_allclose(out.vertices[1], [2, 0, 5])
    np.testing.assert_allclose(out.normals, [[0, 0, 1]] * 3)
    mirrored = mesh.transformed(np.diag([-1.0, 1, 1, 1]))
    v = mirrored.vertices[mirrored.faces[0]]
    assert np.cross(v[1] - v[0], v[2] - v[0])[2] > 0  # winding flipped so the face still points +z


@requires_data
@pytest.mark.data
@pytest.mark.parametrize(
    "name",
    [
        "stanford_dragon_vrip_res4.ply.gz",
        "suzanne_blender_subd3.obj",
        "utah_teapot_three_seg8.ply",
        "stanford_bunny_npm_3674.obj",
    ],
)
def test_real_meshes(name):
    mesh = TriangleMesh.load(DATA / "meshes" / name)
    assert mesh.triangle_count > 900 and mesh.normals is not None
