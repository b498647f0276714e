"""Write a textured glTF 2.0 asset: the Stanford bunny (from ../shared/data; an icosphere when it is absent) glazed
with procedural textures -- a base colour (blue glaze over terracotta, gold bands), a metallic-roughness map (smooth
glaze, rough clay, metallic gold) and a normal map (a hammered, dimpled surface) -- on a textured ground tile.

    python examples/make_textured_asset.py                       # -> examples/assets/textured_bunny.glb (not committed)
    lightprobe render examples/textured_bunny.toml -o bunny.png --spp 128

The textures are made here with NumPy (periodic in u, so the spherical UV layout has no seam in them); UVs are a
spherical projection about the mesh's centre, with the vertices of triangles that straddle the u = 0 / 1 seam
duplicated at u + 1 (the sampler repeats).  The file is written by make_gltf_asset.py's GlbBuffer (one binary
buffer holding geometry and images), the PNGs by OpenImageIO; no tangents are stored, so lightprobe generates them.
"""

from __future__ import annotations

import argparse
import importlib.util
import tempfile
from pathlib import Path

import numpy as np

from lightprobe.images import linear_to_srgb

HERE = Path(__file__).resolve().parent


def _mesh(path: Path | str | None):
    """(vertices, faces, normals, source name): ``path``'s mesh, the bunny from the shared data (None), or the
    built-in icosphere ("icosphere", or None without the data)."""
    import trimesh

    if path == "icosphere":
        path = None
    elif path is None:
        from lightprobe.data import data_dir

        root = data_dir()
        candidate = root / "meshes" / "stanford_bunny_pymeshlab.obj" if root else None
        path = candidate if candidate is not None and candidate.exists() else None
    mesh = trimesh.load(path, process=True) if path else trimesh.creation.icosphere(subdivisions=4)
    v = np.asarray(mesh.vertices, dtype=np.float64)
    v -= [(v[:, 0].max() + v[:, 0].min()) / 2, v[:, 1].min(), (v[:, 2].max() + v[:, 2].min()) / 2]
    v /= v[:, 1].max()  # one unit tall, standing on y = 0, centred in x and z
    normals = np.asarray(trimesh.Trimesh(v, mesh.faces, process=False).vertex_normals)
    return v, np.asarray(mesh.faces, dtype=np.int64), normals, (path.name if path else "icosphere")


def _spherical_uvs(vertices, faces, normals):
    """u = azimuth / 2 pi, v = polar angle / pi (down the image) about the centre; seam triangles get copies of
    their low-u vertices at u + 1."""
    centre = np.array([0.0, 0.5, 0.0])
    d = vertices - centre
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
    azimuth, polar = np.arctan2(d[:, 0], d[:, 2]), np.arccos(np.clip(d[:, 1], -1.0, 1.0))
    uvs = np.column_stack([azimuth / (2 * np.pi) + 0.5, polar / np.pi])
    faces = faces.copy()
    corner_u = uvs[faces, 0]
    seam = corner_u.max(axis=1) - corner_u.min(axis=1) > 0.5
    extra_vertices, extra_normals, extra_uvs = [], [], []
    copies: dict[int, int] = {}
    for f in np.nonzero(seam)[0]:
        for c in range(3):
            i = faces[f, c]
            if uvs[i, 0] < 0.5:
                if i not in copies:
                    copies[i] = vertices.shape[0] + len(extra_vertices)
                    extra_vertices.append(vertices[i])
                    extra_normals.append(normals[i])
                    extra_uvs.append([uvs[i, 0] + 1.0, uvs[i, 1]])
                faces[f, c] = copies[i]
    if extra_vertices:
        vertices = np.concatenate([vertices, extra_vertices])
        normals = np.concatenate([normals, extra_normals])
        uvs = np.concatenate([uvs, extra_uvs])
    return vertices, faces, normals, uvs


def _textures(size: int):
    """(base colour RGBA uint8, metallic-roughness RGB uint8, normal RGB uint8), periodic in u and v."""
    j, i = np.mgrid[0:size, 0:size]
    x, y = 2 * np.pi * (i + 0.5) / size, 2 * np.pi * (j + 0.5) / size  # angles: every term below is periodic
    rng = np.random.default_rng(2026)
    noise = np.zeros((size, size))
    for octave in range(1, 6):
        for _ in range(3):
            a, b = rng.integers(-3 * octave, 3 * octave + 1, size=2)
            noise += np.sin(a * x + b * y + rng.uniform(0, 2 * np.pi)) / octave
    noise = (noise - noise.min()) / (noise.max() - noise.min())
    band = np.abs(np.sin(6 * y)) > 0.97  # thin gold bands around the bunny
    glaze = noise + 0.3 * np.cos(y) > 0.45  # glaze where the noise is high, more of it near the top
    terracotta = np.array([0.62, 0.30, 0.18]) * (0.85 + 0.3 * noise[..., None])
    blue = np.array([0.08, 0.22, 0.55]) * (0.9 + 0.2 * noise[..., None])
    gold = np.array([1.0, 0.78, 0.34])
    colour = np.where(band[..., None], gold, np.where(glaze[..., None], blue, terracotta))
    base = np.dstack([np.round(linear_to_srgb(colour) * 255), np.full((size, size), 255)]).astype(np.uint8)
    roughness = np.where(band, 0.3, np.where(glaze, 0.12, 0.75 + 0.2 * noise))
    metallic = np.where(band, 1.0, 0.0)
    mr = np.dstack([np.zeros((size, size)), roughness, metallic])
    mr = np.round(mr * 255).astype(np.uint8)
    # hammered dimples on a hexagonal-ish lattice, shallow, plus the noise: a height field, then its normal
    height = 0.6 * (np.cos(24 * x) * np.cos(24 * y) + np.cos(24 * x + 24 * y)) * (~glaze) + 0.5 * noise
    dh_du = (np.roll(height, -1, axis=1) - np.roll(height, 1, axis=1)) * size / 2
    dh_dv_down = (np.roll(height, -1, axis=0) - np.roll(height, 1, axis=0)) * size / 2
    strength = 0.004
    n = np.dstack([-dh_du * strength, dh_dv_down * strength, np.ones((size, size))])  # +Y toward the image's top
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    normal = np.round((n * 0.5 + 0.5) * 255).astype(np.uint8)
    return base, mr, normal


def _gltf_writer():
    """examples/make_gltf_asset.py as a module, for its GlbBuffer (loaded by path: this script runs from anywhere)."""
    spec = importlib.util.spec_from_file_location("make_gltf_asset", HERE / "make_gltf_asset.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _png(pixels: np.ndarray) -> bytes:
    import OpenImageIO as oiio

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "t.png"
        h, w, c = pixels.shape
        out = oiio.ImageOutput.create(str(path))
        out.open(str(path), oiio.ImageSpec(w, h, c, oiio.UINT8))
        out.write_image(pixels)
        out.close()
        return path.read_bytes()


def main(out: Path | None = None, *, size: int = 1024, mesh: Path | str | None = None) -> Path:
    vertices, faces, normals, source = _mesh(mesh)
    vertices, faces, normals, uvs = _spherical_uvs(vertices, faces, normals)
    base, mr, normal = _textures(size)
    rows, columns = np.indices((64, 64))
    checker = ((rows // 8 + columns // 8) % 2).astype(np.float64)
    tile = np.round(255 * (0.35 + 0.25 * checker))[..., None].repeat(3, axis=2).astype(np.uint8)

    buffer = _gltf_writer().GlbBuffer()
    add, add_view = buffer.accessor, buffer.view

    def primitive(v, n, uv, f, material):
        attributes = {"POSITION": add(v.astype(np.float32), 5126, "VEC3", 34962),
                      "NORMAL": add(n.astype(np.float32), 5126, "VEC3", 34962),
                      "TEXCOORD_0": add(uv.astype(np.float32), 5126, "VEC2", 34962)}  # fmt: skip
        return {"attributes": attributes, "indices": add(f.astype(np.uint32).reshape(-1), 5125, "SCALAR", 34963),
                "material": material}  # fmt: skip

    images = [{"name": name, "mimeType": "image/png", "bufferView": add_view(_png(pixels))}
              for name, pixels in (("base colour", base), ("metallic-roughness", mr), ("normal", normal),
                                   ("ground tile", tile))]  # fmt: skip
    ground = np.array([[-4, 0, -4], [4, 0, -4], [4, 0, 4], [-4, 0, 4]], float)
    doc = {
        "asset": {"version": "2.0", "generator": f"lightprobe examples/make_textured_asset.py ({source})"},
        "scene": 0,
        "scenes": [{"nodes": [0, 1]}],
        "nodes": [{"name": "bunny", "mesh": 0}, {"name": "ground", "mesh": 1}],
        "meshes": [
            {"name": "bunny", "primitives": [primitive(vertices, normals, uvs, faces, 0)]},
            {
                "name": "ground",
                "primitives": [
                    primitive(
                        ground,
                        np.tile([0.0, 1.0, 0.0], (4, 1)),
                        (ground[:, [0, 2]] + 4) / 2,
                        np.array([[0, 2, 1], [0, 3, 2]]),
                        1,
                    )
                ],
            },
        ],
        "materials": [
            {
                "name": "glazed terracotta",
                "normalTexture": {"index": 2, "scale": 1.0},
                "pbrMetallicRoughness": {
                    "baseColorTexture": {"index": 0},
                    "metallicRoughnessTexture": {"index": 1},
                    "metallicFactor": 1.0,
                    "roughnessFactor": 1.0,
                },
            },
            {
                "name": "ground tiles",
                "pbrMetallicRoughness": {
                    "baseColorTexture": {"index": 3},
                    "metallicFactor": 0.0,
                    "roughnessFactor": 0.8,
                },
            },
        ],
        "samplers": [{"wrapS": 10497, "wrapT": 10497, "magFilter": 9729}],
        "textures": [{"source": k, "sampler": 0} for k in range(4)],
        "images": images,
    }
    out = buffer.write(doc, out or HERE / "assets" / "textured_bunny.glb")
    print(f"wrote {out} ({out.stat().st_size:,} bytes; {source}, {faces.shape[0]:,} triangles, "
          f"{size}x{size} textures)")  # fmt: skip
    return out


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", nargs="?", type=Path, help="the .glb to write (default examples/assets/...)")
    parser.add_argument("--size", type=int, default=1024, help="texture size in texels (default 1024)")
    parser.add_argument("--mesh", type=Path, help="a mesh file instead of the bunny")
    args = parser.parse_args()
    main(args.out, size=args.size, mesh=args.mesh)
