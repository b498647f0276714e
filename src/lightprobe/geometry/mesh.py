"""Triangle meshes: loading (OBJ, PLY, PLY.GZ, glTF/GLB, anything trimesh reads), validation, normals.

Shading normals: a mesh keeps the vertex normals stored in its file; without them, ``smooth=True`` (the default)
computes angle-weighted vertex normals (Thuermer & Wuethrich 1998, what Mitsuba 3 does for a PLY without
normals) and ``smooth=False`` shades flat with the geometric normal.

Validation is strict about what cannot be rendered and lenient about what can be repaired: no triangles, NaN or
infinite vertices, or out-of-range indices raise :class:`~lightprobe.errors.SceneError` naming the mesh;
degenerate triangles (repeated vertices or zero area) are dropped with a warning; invalid stored normals are
replaced by computed ones with a warning.
"""

from __future__ import annotations

import gzip
import os
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from ..errors import SceneError, warn_once

__all__ = ["TriangleMesh", "angle_weighted_normals"]


def angle_weighted_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit vertex normals: the face normals around each vertex weighted by the triangle's angle there."""
    v = vertices[faces]  # (F, 3, 3)
    face_n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    length = np.linalg.norm(face_n, axis=1, keepdims=True)
    face_n = np.divide(face_n, length, out=np.zeros_like(face_n), where=length > 0)
    normals = np.zeros_like(vertices)
    for k in range(3):
        a = v[:, (k + 1) % 3] - v[:, k]
        b = v[:, (k + 2) % 3] - v[:, k]
        cos = np.einsum("ij,ij->i", a, b) / np.maximum(np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1), 1e-300)
        angle = np.arccos(np.clip(cos, -1.0, 1.0))
        np.add.at(normals, faces[:, k], face_n * angle[:, None])
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return np.divide(normals, length, out=np.zeros_like(normals), where=length > 0)


@dataclass(frozen=True)
class TriangleMesh:
    """Vertices (V, 3) float64, faces (F, 3) int64, optional unit vertex normals (V, 3), and optional per-face values
    (F, k) float64 that stay with their faces (a degenerate face dropped takes its row along): the file's face
    colours, or a scene file's per-face emission.  Optional texture coordinates ``uvs`` (V, 2) (glTF's: v down the
    image) and ``tangents`` (V, 4) (unit xyz and the bitangent's sign w) serve textured materials."""

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray | None = None
    name: str = "<mesh>"
    face_values: np.ndarray | None = None
    uvs: np.ndarray | None = None
    tangents: np.ndarray | None = None

    @classmethod
    def from_arrays(
        cls,
        vertices,
        faces,
        normals=None,
        *,
        smooth: bool = True,
        name: str = "<mesh>",
        face_values=None,
        uvs=None,
        tangents=None,
    ) -> TriangleMesh:
        """Validate and build; see the module docstring for what is rejected and what is repaired.  ``face_values``
        (F,) or (F, k) numbers, one row per face given, are kept for the faces that remain.  ``uvs`` (V, 2) must be
        finite; ``tangents`` (V, 4) with a zero or non-finite direction are dropped with a warning (generated
        instead where a normal map needs them)."""
        try:
            v = np.asarray(vertices, dtype=np.float64)
            f = np.asarray(faces)
        except (TypeError, ValueError) as exc:
            raise SceneError(f"{name}: vertices and faces must be numeric arrays ({exc})") from None
        if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] == 0:
            raise SceneError(f"{name}: vertices must be a non-empty (V, 3) array, got shape {v.shape}")
        if f.ndim != 2 or f.shape[1] != 3 or f.shape[0] == 0:
            raise SceneError(f"{name}: faces must be a non-empty (F, 3) array of triangles, got shape {f.shape}")
        if not np.issubdtype(f.dtype, np.integer):
            raise SceneError(f"{name}: face indices must be integers")
        if not np.all(np.isfinite(v)):
            raise SceneError(f"{name}: {int((~np.isfinite(v)).any(axis=1).sum())} vertices are NaN or infinite")
        f = f.astype(np.int64)
        values = None
        if face_values is not None:
            values = np.asarray(face_values, dtype=np.float64)
            values = values.reshape(-1, 1) if values.ndim == 1 else values
            if values.ndim != 2 or values.shape[0] != f.shape[0]:
                raise SceneError(
                    f"{name}: per-face values must have one row per face ({f.shape[0]}), got {values.shape}"
                )
        if f.min() < 0 or f.max() >= v.shape[0]:
            raise SceneError(f"{name}: face indices out of range [0, {v.shape[0] - 1}] (min {f.min()}, max {f.max()})")
        tri = v[f]
        area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        repeated = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])
        degenerate = repeated | ~(area2 > 0.0)
        if degenerate.all():
            raise SceneError(f"{name}: all {f.shape[0]} triangles are degenerate (zero area)")
        if degenerate.any():
            warn_once(f"{name}: dropped {int(degenerate.sum())} degenerate triangles of {f.shape[0]}")
            f = f[~degenerate]
            values = None if values is None else values[~degenerate]
        n = None
        if normals is not None:
            n = np.asarray(normals, dtype=np.float64)
            if n.shape != v.shape:
                raise SceneError(f"{name}: normals must have the vertices' shape {v.shape}, got {n.shape}")
            length = np.linalg.norm(n, axis=1)
            bad = ~np.isfinite(length) | (length < 1e-12)
            n = np.divide(n, length[:, None], out=np.zeros_like(n), where=~bad[:, None])
            if bad.any():
                used = np.zeros(v.shape[0], dtype=bool)
                used[f.reshape(-1)] = True
                if (bad & used).any():
                    warn_once(
                        f"{name}: replaced {int((bad & used).sum())} zero or invalid vertex normals by computed ones"
                    )
                    n[bad] = angle_weighted_normals(v, f)[bad]
        elif smooth:
            n = angle_weighted_normals(v, f)
        values = None if values is None else np.ascontiguousarray(values)
        if uvs is not None:
            uvs = np.asarray(uvs, dtype=np.float64)
            if uvs.shape != (v.shape[0], 2):
                raise SceneError(f"{name}: texture coordinates must be a ({v.shape[0]}, 2) array, got {uvs.shape}")
            if not np.all(np.isfinite(uvs)):
                raise SceneError(f"{name}: {int((~np.isfinite(uvs)).any(axis=1).sum())} texture coordinates are NaN "
                                 "or infinite")  # fmt: skip
            uvs = np.ascontiguousarray(uvs)
        if tangents is not None:
            tangents = np.array(tangents, dtype=np.float64)
            if tangents.shape != (v.shape[0], 4):
                raise SceneError(f"{name}: tangents must be a ({v.shape[0]}, 4) array, got {tangents.shape}")
            length = np.linalg.norm(tangents[:, :3], axis=1)
            if not np.all(np.isfinite(tangents)) or not np.all(length > 1e-12):
                warn_once(f"{name}: zero or non-finite tangents; tangents are generated from the texture coordinates "
                          "instead")  # fmt: skip
                tangents = None
            else:
                tangents[:, :3] /= length[:, None]
                tangents[:, 3] = np.where(tangents[:, 3] < 0.0, -1.0, 1.0)
        return cls(np.ascontiguousarray(v), np.ascontiguousarray(f), n, name, values, uvs, tangents)

    @classmethod
    def load(cls, path: str | os.PathLike, *, smooth: bool = True, face_values=None) -> TriangleMesh:
        """Read a mesh file through trimesh (``.ply.gz`` is decompressed first).  ``face_values``: per-face values
        (one row per face of the file) to keep with the faces, or ``"colors"`` for the file's face colours (RGB in
        [0, 1], as stored: 8-bit values / 255)."""
        import trimesh

        p = Path(path)
        if not p.exists():
            raise SceneError(f"{p}: no such file")
        try:
            if p.suffix.lower() == ".gz":
                with gzip.open(p, "rb") as fh:
                    loaded = trimesh.load(fh, file_type=Path(p.stem).suffix.lstrip(".").lower(), process=False)
            else:
                loaded = trimesh.load(p, process=False)
        except Exception as exc:  # trimesh raises many kinds of errors on bad files
            raise SceneError(f"{p}: cannot read mesh ({type(exc).__name__}: {exc})") from None
        if isinstance(loaded, trimesh.Scene):  # glTF and multi-object files: flatten with their transforms
            if not loaded.geometry:
                raise SceneError(f"{p}: the file contains no mesh")
            loaded = loaded.to_geometry() if hasattr(loaded, "to_geometry") else loaded.dump(concatenate=True)
        if not isinstance(loaded, trimesh.Trimesh):
            raise SceneError(f"{p}: not a triangle mesh ({type(loaded).__name__})")
        normals = np.asarray(loaded.vertex_normals) if "vertex_normals" in loaded._cache else None
        if isinstance(face_values, str) and face_values == "colors":
            face_values = _face_colors(loaded, p)
        return cls.from_arrays(
            loaded.vertices,
            loaded.faces,
            normals if smooth else None,
            smooth=smooth,
            name=str(p),
            face_values=face_values,
            uvs=_file_uvs(loaded),
        )

    def transformed(self, matrix) -> TriangleMesh:
        """This mesh under a 4x4 affine transform (normals by the inverse transpose)."""
        m = np.asarray(matrix, dtype=np.float64)
        linear, offset = m[:3, :3], m[:3, 3]
        v = self.vertices @ linear.T + offset
        n = None
        if self.normals is not None:
            n = self.normals @ np.linalg.inv(linear)
            n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
        det = np.linalg.det(linear)
        faces = self.faces if det > 0 else self.faces[:, ::-1].copy()  # keep outward winding
        tangents = None
        if self.tangents is not None:  # a direction on the surface: transformed like a point's offset
            tangents = self.tangents.copy()
            tangents[:, :3] = self.tangents[:, :3] @ linear.T
            tangents[:, :3] /= np.maximum(np.linalg.norm(tangents[:, :3], axis=1, keepdims=True), 1e-300)
            if det < 0:  # a mirror flips the bitangent's side
                tangents[:, 3] = -tangents[:, 3]
        return TriangleMesh(np.ascontiguousarray(v), np.ascontiguousarray(faces), n, self.name, self.face_values,
                            self.uvs, tangents)  # fmt: skip

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3): min and max corners."""
        return np.stack([self.vertices.min(axis=0), self.vertices.max(axis=0)])

    @property
    def triangle_count(self) -> int:
        return int(self.faces.shape[0])

    @cached_property
    def spheres(self) -> np.ndarray:
        """(centre x, y, z, outer radius^2, inner radius^2): the spheres that decide shadow rays without Embree
        (:func:`lightprobe.geometry.proxies.mesh_spheres`; inner radius^2 is ``NO_BALL`` unless the mesh is
        closed)."""
        from .proxies import mesh_spheres

        return mesh_spheres(self.vertices, self.faces)


def _file_uvs(loaded) -> np.ndarray | None:
    """The file's per-vertex texture coordinates in glTF's convention (v down the image), or None.  trimesh gives
    OBJ's and PLY's as stored, v up the image (OpenGL's), so v becomes 1 - v."""
    uv = getattr(loaded.visual, "uv", None)
    if uv is None:
        return None
    uv = np.asarray(uv, dtype=np.float64)
    if uv.shape != (len(loaded.vertices), 2):
        return None
    return np.column_stack([uv[:, 0], 1.0 - uv[:, 1]])


def _face_colors(loaded, path: Path) -> np.ndarray:
    """The face colours (F, 3) in [0, 1] of a mesh trimesh loaded, or an error naming the file if it has none."""
    visual = getattr(loaded, "visual", None)
    if visual is None or getattr(visual, "kind", None) != "face":
        raise SceneError(f"{path}: the file has no face colours (a PLY's face element needs red, green, blue)")
    return np.asarray(visual.face_colors, dtype=np.float64)[:, :3] / 255.0
