"""A textured material at a camera ray's hit: its parameter block there and its normal-mapped shading frame.

The setup stage calls :func:`apply_textures` once per camera sample that hits a textured material; it writes the
block into the camera sample's row of ``CameraSamples.params``, which the later stages read instead of the
material's constant block (``material_parameters``), so each texture is looked up once per camera sample however
many shading slots it has.  ``apply_textures`` is a call, not inlined into the setup stage: it runs once per camera
sample that hits a textured material, and the first run's compile was shorter so (decisions.md 85).

Normal mapping follows the glTF sample renderer: with the mesh's tangent t (made orthogonal to the shading normal
n) and bitangent b = w cross(n, t), all three negated on the back of a two-sided surface, the shading normal becomes
normalize(x t + y b + z n) for the texel's (x, y, z) = (2 c - 1) (scale, scale, 1).  A texel that tilts nothing
(x = y = 0) leaves the frame as it was, bit for bit; one that would put the viewer below the new shading normal is
ignored at that point (the usual fallback for shading normals that face away).
"""

from __future__ import annotations

import math

from .._numba import jit, jit_inline
from ..bsdfs.dispatch import bsdf_textured
from ..geometry.frame import coordinate_system, to_local
from ..textures.image_texture import texture_lookup
from ..textures.material_textures import BASE_COLOR, METALLIC_ROUGHNESS, NORMAL

__all__ = ["apply_textures", "material_parameters"]


@jit_inline
def material_parameters(s, cams, k):
    """Camera sample k's material parameter block: its own row of ``cams.params`` for a textured material."""
    mat = cams.material[k]
    if s.material_textured[mat] == 1:
        return cams.params[k]
    return s.material_params[mat]


@jit_inline
def _unit_clamp(x):
    return min(max(x, 0.0), 1.0)


@jit
def apply_textures(s, cams, k, dx, dy, dz):
    """Camera sample k (ray direction d, a mesh hit of a textured material, frame already stored): its parameter
    block, and its frame and local wo under a normal map.  See the module docstring."""
    mat = cams.material[k]
    index, f = cams.index[k], s.mesh_face_start[cams.index[k]] + cams.prim[k]
    i0, i1, i2 = s.mesh_faces[f, 0], s.mesh_faces[f, 1], s.mesh_faces[f, 2]
    b1, b2 = cams.b1[k], cams.b2[k]
    b0 = 1.0 - b1 - b2
    uv = s.mesh_uvs
    u = b0 * uv[i0, 0] + b1 * uv[i1, 0] + b2 * uv[i2, 0]
    v = b0 * uv[i0, 1] + b1 * uv[i1, 1] + b2 * uv[i2, 1]
    uses = s.material_textures[mat]
    table, texel_bytes, texel_floats = s.texture_table, s.texture_bytes, s.texture_floats
    r = g = b = 1.0
    metallic = roughness = 1.0
    if uses[BASE_COLOR] >= 0:
        r, g, b, _ = texture_lookup(table, texel_bytes, texel_floats, uses[BASE_COLOR], u, v, True)
        r, g, b = _unit_clamp(r), _unit_clamp(g), _unit_clamp(b)
    if uses[METALLIC_ROUGHNESS] >= 0:
        _, roughness, metallic, _ = texture_lookup(table, texel_bytes, texel_floats, uses[METALLIC_ROUGHNESS], u, v,
                                                   False)  # fmt: skip
        roughness, metallic = _unit_clamp(roughness), _unit_clamp(metallic)
    bsdf_textured(s.material_kind[mat], s.material_params[mat], cams.params[k], r, g, b, metallic, roughness)
    if uses[NORMAL] < 0:
        return
    x, y, z, _ = texture_lookup(table, texel_bytes, texel_floats, uses[NORMAL], u, v, False)
    scale = s.material_normal_scale[mat]
    x, y, z = (2.0 * x - 1.0) * scale, (2.0 * y - 1.0) * scale, 2.0 * z - 1.0
    if x == 0.0 and y == 0.0:
        return
    frame = cams.frame
    nx, ny, nz = frame[k, 6], frame[k, 7], frame[k, 8]
    tg = s.mesh_tangents
    tx = b0 * tg[i0, 0] + b1 * tg[i1, 0] + b2 * tg[i2, 0]
    ty = b0 * tg[i0, 1] + b1 * tg[i1, 1] + b2 * tg[i2, 1]
    tz = b0 * tg[i0, 2] + b1 * tg[i1, 2] + b2 * tg[i2, 2]
    w = 1.0 if b0 * tg[i0, 3] + b1 * tg[i1, 3] + b2 * tg[i2, 3] >= 0.0 else -1.0
    d = tx * nx + ty * ny + tz * nz
    tx, ty, tz = tx - d * nx, ty - d * ny, tz - d * nz
    length = math.sqrt(tx * tx + ty * ty + tz * tz)
    if not length > 1e-12:
        return
    tx, ty, tz = tx / length, ty / length, tz / length
    # the back of a two-sided surface (store_shading_frame negated n there): negate t too, as b follows n
    vx = s.mesh_vertices
    ax, ay, az = vx[i1, 0] - vx[i0, 0], vx[i1, 1] - vx[i0, 1], vx[i1, 2] - vx[i0, 2]
    cx, cy, cz = vx[i2, 0] - vx[i0, 0], vx[i2, 1] - vx[i0, 1], vx[i2, 2] - vx[i0, 2]
    winding = (ay * cz - az * cy) * dx + (az * cx - ax * cz) * dy + (ax * cy - ay * cx) * dz
    if s.mesh_two_sided[index] == 1 and winding > 0.0:
        tx, ty, tz = -tx, -ty, -tz
    bx, by, bz = w * (ny * tz - nz * ty), w * (nz * tx - nx * tz), w * (nx * ty - ny * tx)
    mx, my, mz = x * tx + y * bx + z * nx, x * ty + y * by + z * ny, x * tz + y * bz + z * nz
    length = math.sqrt(mx * mx + my * my + mz * mz)
    if not length > 0.0:
        return
    mx, my, mz = mx / length, my / length, mz / length
    ts, tt = coordinate_system(mx, my, mz)
    ns = (mx, my, mz)
    wo = to_local(ts, tt, ns, -dx, -dy, -dz)
    if wo[2] <= 0.0:
        return
    for c in range(3):
        frame[k, c] = ts[c]
        frame[k, 3 + c] = tt[c]
        frame[k, 6 + c] = ns[c]
        cams.wo_local[k, c] = wo[c]
