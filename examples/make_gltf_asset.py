"""Write examples/assets/spheres.glb: three spheres of glTF 2.0 metallic-roughness materials on a ground, a camera
named "Front" and a KHR_lights_punctual spot light -- the asset behind examples/gltf_spheres.toml.

    python examples/make_gltf_asset.py

The GLB is written with NumPy and json alone (the layout is the specification's: one binary buffer, a buffer view
and an accessor per array), so that the file shows what lightprobe's reader (lightprobe/io/gltf.py) takes.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import trimesh

HERE = Path(__file__).resolve().parent
SPHERES = [  # (name, centre, radius, base colour, metallic, roughness)
    ("red dielectric", [-1.3, 0.5, 0.0], 0.5, [0.8, 0.12, 0.08], 0.0, 0.45),
    ("gold", [0.0, 0.6, -0.3], 0.6, [1.0, 0.78, 0.34], 1.0, 0.25),
    ("half metal", [1.3, 0.45, 0.2], 0.45, [0.6, 0.65, 0.7], 0.5, 0.6),
]


class GlbBuffer:
    """One glTF binary buffer, built view by view (each padded to 4 bytes), and its writing as a .glb with the
    document: the layout of the specification (a JSON chunk, then the BIN chunk).  examples/make_textured_asset.py
    uses it too."""

    def __init__(self):
        self.blob = bytearray()
        self.views: list[dict] = []
        self.accessors: list[dict] = []

    def view(self, data: bytes, target: int | None = None) -> int:
        """A buffer view of ``data`` (``target``: 34962 vertex attributes, 34963 indices; images take none)."""
        offset = len(self.blob)
        self.blob.extend(data)
        self.blob.extend(b"\0" * (-len(self.blob) % 4))
        view = {"buffer": 0, "byteOffset": offset, "byteLength": len(data)}
        if target:
            view["target"] = target
        self.views.append(view)
        return len(self.views) - 1

    def accessor(self, array: np.ndarray, component: int, kind: str, target: int) -> int:
        """An accessor of ``array`` (one row per element) in a view of its own; VEC3s get their bounds."""
        accessor = {
            "bufferView": self.view(array.tobytes(), target),
            "componentType": component,
            "count": int(array.shape[0]),
            "type": kind,
        }
        if kind == "VEC3":
            accessor["min"], accessor["max"] = array.min(axis=0).tolist(), array.max(axis=0).tolist()
        self.accessors.append(accessor)
        return len(self.accessors) - 1

    def write(self, doc: dict, out: Path) -> Path:
        """``doc`` with this buffer's buffers, bufferViews and accessors, as the .glb ``out``."""
        doc = {**doc, "buffers": [{"byteLength": len(self.blob)}], "bufferViews": self.views,
               "accessors": self.accessors}  # fmt: skip
        text = json.dumps(doc, separators=(",", ":")).encode()
        text += b" " * (-len(text) % 4)

        def chunk(data: bytes, kind: int) -> bytes:
            return len(data).to_bytes(4, "little") + kind.to_bytes(4, "little") + data

        body = chunk(text, 0x4E4F534A) + chunk(bytes(self.blob), 0x004E4942)
        out.parent.mkdir(exist_ok=True)
        out.write_bytes(b"glTF" + (2).to_bytes(4, "little") + (12 + len(body)).to_bytes(4, "little") + body)
        return out


def main(out: Path | None = None) -> Path:
    buffer = GlbBuffer()
    meshes, materials, nodes = [], [], []
    add = buffer.accessor

    def add_mesh(name, vertices, normals, faces, material) -> None:
        position = add(vertices.astype(np.float32), 5126, "VEC3", 34962)
        normal = add(normals.astype(np.float32), 5126, "VEC3", 34962)
        indices = add(faces.astype(np.uint32).reshape(-1), 5125, "SCALAR", 34963)
        meshes.append(
            {
                "name": name,
                "primitives": [
                    {"attributes": {"POSITION": position, "NORMAL": normal}, "indices": indices, "material": material}
                ],
            }
        )

    ball = trimesh.creation.icosphere(subdivisions=3)  # unit sphere, 1,280 triangles (smooth normals)
    for name, centre, radius, colour, metallic, roughness in SPHERES:
        materials.append(
            {
                "name": name,
                "pbrMetallicRoughness": {
                    "baseColorFactor": [*colour, 1.0],
                    "metallicFactor": metallic,
                    "roughnessFactor": roughness,
                },
            }
        )
        add_mesh(name, ball.vertices, ball.vertex_normals, ball.faces, len(materials) - 1)
        nodes.append({"name": name, "mesh": len(meshes) - 1, "translation": centre, "scale": [radius] * 3})
    ground = np.array([[-6, 0, -6], [6, 0, -6], [6, 0, 6], [-6, 0, 6]], float)
    materials.append(
        {
            "name": "ground",
            "pbrMetallicRoughness": {
                "baseColorFactor": [0.45, 0.45, 0.45, 1.0],
                "metallicFactor": 0.0,
                "roughnessFactor": 0.9,
            },
        }
    )
    add_mesh("ground", ground, np.tile([0.0, 1.0, 0.0], (4, 1)), np.array([[0, 2, 1], [0, 3, 2]]), len(materials) - 1)
    nodes.append({"name": "ground", "mesh": len(meshes) - 1})
    # a camera 5.5 units in front, 1.6 up, looking 15 degrees down (rotation about +X)
    a = math.radians(-15.0) / 2
    nodes.append(
        {"name": "Front", "camera": 0, "translation": [0.0, 1.9, 5.5], "rotation": [math.sin(a), 0.0, 0.0, math.cos(a)]}
    )
    b = math.radians(-90.0) / 2  # the spot looks straight down
    nodes.append(
        {
            "name": "spot",
            "translation": [0.0, 4.0, 0.5],
            "rotation": [math.sin(b), 0.0, 0.0, math.cos(b)],
            "extensions": {"KHR_lights_punctual": {"light": 0}},
        }
    )
    doc = {
        "asset": {"version": "2.0", "generator": "lightprobe examples/make_gltf_asset.py"},
        "scene": 0,
        "scenes": [{"nodes": list(range(len(nodes)))}],
        "nodes": nodes,
        "meshes": meshes,
        "materials": materials,
        "cameras": [
            {
                "name": "Front",
                "type": "perspective",
                "perspective": {"yfov": math.radians(38.0), "znear": 0.1, "aspectRatio": 1.5},
            }
        ],
        "extensionsUsed": ["KHR_lights_punctual"],
        "extensions": {
            "KHR_lights_punctual": {
                "lights": [
                    {
                        "name": "spot",
                        "type": "spot",
                        "intensity": 12.0,
                        "color": [1.0, 0.95, 0.85],
                        "spot": {"innerConeAngle": 0.35, "outerConeAngle": 0.55},
                    }
                ]
            }
        },
    }
    out = buffer.write(doc, out or HERE / "assets" / "spheres.glb")
    print(f"wrote {out} ({out.stat().st_size:,} bytes)")
    return out


if __name__ == "__main__":
    main()
