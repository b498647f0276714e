"""Write tests/data/mikktspace_reference.json: three small meshes (a sphere with spherical UVs, a wavy grid with a
smooth non-uniform UV layout, the same grid mirrored in u) and, per triangle corner, the tangents of the reference
MikkTSpace code (npm package ``mikktspace``, Mikkelsen's C code built to WebAssembly), w negated for glTF's UV
convention as that package's README says.  Needs Node.js and npm (not the suite):

    python tests/data/make_mikktspace_reference.py
"""

from __future__ import annotations

import json
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import trimesh

HERE = Path(__file__).resolve().parent
NODE = """
const { generateTangents } = require('mikktspace');
const fs = require('fs');
const inputs = JSON.parse(fs.readFileSync(process.argv[2]));
const out = {};
for (const [name, c] of Object.entries(inputs)) {
  const n = c.faces.length * 3;
  const P = new Float32Array(n * 3), N = new Float32Array(n * 3), T = new Float32Array(n * 2);
  c.faces.forEach((f, i) => f.forEach((vi, k) => {
    const r = i * 3 + k;
    for (let d = 0; d < 3; d++) { P[r * 3 + d] = c.vertices[vi][d]; N[r * 3 + d] = c.normals[vi][d]; }
    T[r * 2] = c.uvs[vi][0]; T[r * 2 + 1] = c.uvs[vi][1];
  }));
  const t = generateTangents(P, N, T);
  const rows = [];
  for (let r = 0; r < n; r++) rows.push([t[r * 4], t[r * 4 + 1], t[r * 4 + 2], -t[r * 4 + 3]]);
  out[name] = rows;
}
fs.writeFileSync(process.argv[3], JSON.stringify(out));
"""


def meshes() -> dict:
    cases = {}
    sphere = trimesh.creation.icosphere(1)
    v = np.asarray(sphere.vertices)
    n = v / np.linalg.norm(v, axis=1, keepdims=True)
    uv = np.column_stack([np.arctan2(v[:, 0], v[:, 2]) / (2 * np.pi) + 0.5, np.arccos(np.clip(v[:, 1], -1, 1)) / np.pi])
    cases["sphere"] = (v, np.asarray(sphere.faces), n, uv)
    g = 6
    x, z = np.meshgrid(np.linspace(-1, 1, g), np.linspace(-1, 1, g))
    v = np.column_stack([x.ravel(), (0.2 * np.sin(2 * x) * np.cos(3 * z)).ravel(), z.ravel()])
    faces = []
    for i in range(g - 1):
        for j in range(g - 1):
            a, b, c, d = i * g + j, i * g + j + 1, (i + 1) * g + j + 1, (i + 1) * g + j
            faces += [[a, c, b], [a, d, c]]
    faces = np.array(faces)
    n = np.asarray(trimesh.Trimesh(v, faces, process=False).vertex_normals)
    uv = np.column_stack([(x.ravel() + 1) / 2 + 0.1 * z.ravel() ** 2, (z.ravel() + 1) / 2 * 0.8])
    cases["grid"] = (v, faces, n, uv)
    cases["mirrored"] = (v, faces, n, uv * [-1.0, 1.0] + [1.0, 0.0])
    return {
        name: {"vertices": v.tolist(), "faces": f.tolist(), "normals": n.tolist(), "uvs": uv.tolist()}
        for name, (v, f, n, uv) in cases.items()
    }


def main() -> None:
    inputs = meshes()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        subprocess.run(["npm", "install", "--silent", "mikktspace@1.1.1"], cwd=work, check=True)
        (work / "run.js").write_text(NODE)
        (work / "in.json").write_text(json.dumps(inputs))
        subprocess.run(["node", "run.js", "in.json", "out.json"], cwd=work, check=True)
        tangents = json.loads((work / "out.json").read_text())
    for name in inputs:
        inputs[name]["mikktspace_tangents"] = tangents[name]
    out = HERE / "mikktspace_reference.json"
    out.write_text(json.dumps(inputs, separators=(",", ":")))
    print(f"wrote {out} ({out.stat().st_size:,} bytes)")


if __name__ == "__main__":
    main()
