"""The arrays a scene compiles to (:meth:`lightprobe.scene.Scene.compile`): its meshes, shapes, materials and
shape hierarchy in world space, as the Numba kernels read them."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["SceneArrays"]


class SceneArrays(NamedTuple):
    """Everything the kernels need, as arrays (world space)."""

    mesh_vertices: np.ndarray  # (V, 3) float64
    mesh_normals: np.ndarray  # (V, 3) float64, zeros for flat meshes
    mesh_faces: np.ndarray  # (F, 3) int64, indices into mesh_vertices
    mesh_face_start: np.ndarray  # (M + 1,) int64: mesh g owns faces [start[g], start[g+1])
    mesh_smooth: np.ndarray  # (M,) int64, 1 = interpolate vertex normals
    mesh_material: np.ndarray  # (M,) int64
    mesh_two_sided: np.ndarray  # (M,) int64
    mesh_bounds: np.ndarray  # (M, 2, 3) float64
    mesh_spheres: np.ndarray  # (M, 5) float64: centre, outer radius^2, inner radius^2 (geometry/proxies.py)
    spheres: np.ndarray  # (S, 4) float64: centre, radius
    sphere_material: np.ndarray
    sphere_two_sided: np.ndarray
    rects: np.ndarray  # (R, RECT_WIDTH) float64: origin, edge_u, edge_v, unit normal, dual u, dual v
    rect_material: np.ndarray
    rect_two_sided: np.ndarray
    sphere_light: np.ndarray  # (S,) int64: the sphere's row in the light table, -1 if it does not emit
    rect_light: np.ndarray  # (R,) int64
    mesh_light_start: np.ndarray  # (M,) int64: the light of face f of mesh g is start[g] + f; -1: no emission
    material_kind: np.ndarray  # (K,) int64
    material_params: np.ndarray  # (K, PARAM_SIZE) float64
    # textures (textures/): per material, 1 if textured, its texture rows by use (-1: none) and normal-map scale;
    # per mesh vertex, texture coordinates and tangents (zeros where unused); the packed texture table
    material_textured: np.ndarray  # (K,) int64
    material_textures: np.ndarray  # (K, 3) int64: base colour, metallic-roughness, normal
    material_normal_scale: np.ndarray  # (K,) float64
    material_alpha: np.ndarray  # (K, 2) float64: alpha cutoff (-1: opaque) and alpha factor (geometry/alpha_mask.py)
    mesh_uvs: np.ndarray  # (V, 2) float64
    mesh_tangents: np.ndarray  # (V, 4) float64
    texture_table: np.ndarray  # (T, 7) int64 (textures/image_texture.py)
    texture_bytes: np.ndarray  # (N, 4) uint8
    texture_floats: np.ndarray  # (N', 4) float32
    # a hierarchy over spheres and rectangles when there are many (geometry/shape_bvh.ShapeTree's arrays; a nested
    # tuple is refused by Numba's parallel kernels, so its fields are flat here): empty arrays otherwise
    tree_lo: np.ndarray
    tree_hi: np.ndarray
    tree_skip: np.ndarray
    tree_first: np.ndarray
    tree_count: np.ndarray
    tree_prims: np.ndarray
    tree_loose: np.ndarray
    tree_boxes: np.ndarray
    tree_child: np.ndarray
    tree_parent: np.ndarray
