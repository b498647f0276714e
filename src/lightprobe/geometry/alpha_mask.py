"""Alpha cut-outs (glTF's ``alphaMode = "MASK"``): hits on a mesh where its material's coverage is below the cutoff
do not exist, for every ray -- camera rays, BSDF rays, shadow rays, one at a time or in packets.

Coverage is the material's ``alpha_factor`` times the alpha of its base-colour texture (bilinear, as the colour)
at the hit's texture coordinates; a hit counts when coverage >= ``alpha_cutoff``.  The test runs inside Embree,
as the filter function of the mesh's geometry (``rtcSetGeometryIntersectFilterFunction`` and its occlusion twin):
Embree calls it for every candidate hit and goes on past the ones it rejects, so no stage of the renderer has to
know.  The function is a Numba ``cfunc`` (its address handed to Embree from Python, never baked into a kernel); it
reads the mesh's faces, the scene's texture coordinates and textures through a record of addresses that Embree
passes back as the geometry's user data.  Records and the arrays they point at are kept alive by the scene.

Cut-outs apply to meshes only; a masked mesh gets no inner proxy ball (``proxies.py``: a ball inside a mesh with
holes does not block), and an emissive mesh is never masked (its lights are sampled over whole triangles).
"""

from __future__ import annotations

import numpy as np
from numba import cfunc, types
from numba.core import cgutils
from numba.extending import intrinsic

from ..textures.image_texture import texture_lookup

__all__ = ["MaskRecords", "filter_address"]

# one record per masked geometry (int64 words): addresses and sizes of what the filter reads
_FACES, _UVS, _N_VERTICES, _TABLE, _N_TEXTURES, _BYTES, _N_BYTES, _FLOATS, _N_FLOATS, _ROW, _CONSTANTS = range(11)
RECORD_WORDS = 11


def _pointer_intrinsic(dtype):
    @intrinsic
    def as_pointer(typingctx, address):
        sig = types.CPointer(dtype)(types.int64)

        def codegen(context, builder, signature, args):
            return builder.inttoptr(args[0], context.get_value_type(types.CPointer(dtype)))

        return sig, codegen

    return as_pointer


_i64_pointer = _pointer_intrinsic(types.int64)
_i32_pointer = _pointer_intrinsic(types.int32)
_u32_pointer = _pointer_intrinsic(types.uint32)
_f32_pointer = _pointer_intrinsic(types.float32)
_f64_pointer = _pointer_intrinsic(types.float64)
_u8_pointer = _pointer_intrinsic(types.uint8)


@intrinsic
def _carray_2d(typingctx, pointer, rows, columns):
    """A C-contiguous (rows, columns) array over ``pointer`` (no owner: the caller keeps the memory alive)."""
    dtype = pointer.dtype
    array_type = types.Array(dtype, 2, "C")
    sig = array_type(pointer, types.int64, types.int64)

    def codegen(context, builder, signature, args):
        ptr, n_rows, n_cols = args
        array = context.make_array(array_type)(context, builder)
        itemsize = context.get_constant(types.intp, context.get_abi_sizeof(context.get_data_type(dtype)))
        shape = cgutils.pack_array(builder, [n_rows, n_cols])
        strides = cgutils.pack_array(builder, [builder.mul(n_cols, itemsize), itemsize])
        context.populate_array(array, data=ptr, shape=shape, strides=strides, itemsize=itemsize, meminfo=None)
        return array._getvalue()

    return sig, codegen


_FILTER_SIGNATURE = types.void(types.CPointer(types.int64))


@cfunc(_FILTER_SIGNATURE, cache=True, nopython=True)
def _coverage_filter(args):
    """RTCFilterFunctionN: args -> {int* valid, void* user, context, RTCRayN* ray, RTCHitN* hit, unsigned N}.
    RTCHitN is structure-of-arrays: Ng x, y, z, u, v, primID, geomID ... rows of N."""
    valid = args[0]
    record = _i64_pointer(args[1])
    hit = args[4]
    n = args[5] & 0xFFFFFFFF
    faces = _u32_pointer(record[_FACES])
    uvs = _carray_2d(_f64_pointer(record[_UVS]), record[_N_VERTICES], 2)
    table = _carray_2d(_i64_pointer(record[_TABLE]), record[_N_TEXTURES], 7)
    texel_bytes = _carray_2d(_u8_pointer(record[_BYTES]), record[_N_BYTES], 4)
    texel_floats = _carray_2d(_f32_pointer(record[_FLOATS]), record[_N_FLOATS], 4)
    row = record[_ROW]
    constants = _f64_pointer(record[_CONSTANTS])
    factor, cutoff = constants[0], constants[1]
    valid_words = _i32_pointer(valid)
    hit_floats = _f32_pointer(hit)
    hit_words = _u32_pointer(hit)
    for i in range(n):
        if valid_words[i] == 0:
            continue
        b1, b2 = np.float64(hit_floats[3 * n + i]), np.float64(hit_floats[4 * n + i])
        prim = np.int64(hit_words[5 * n + i])
        i0, i1, i2 = np.int64(faces[3 * prim]), np.int64(faces[3 * prim + 1]), np.int64(faces[3 * prim + 2])
        b0 = 1.0 - b1 - b2
        u = b0 * uvs[i0, 0] + b1 * uvs[i1, 0] + b2 * uvs[i2, 0]
        v = b0 * uvs[i0, 1] + b1 * uvs[i1, 1] + b2 * uvs[i2, 1]
        alpha = factor
        if row >= 0:
            alpha *= texture_lookup(table, texel_bytes, texel_floats, row, u, v, False)[3]
        if alpha < cutoff:
            valid_words[i] = 0


def filter_address() -> int:
    """The filter function's address, for ``rtcSetGeometryIntersectFilterFunction`` / ``...OccludedFilter...``."""
    return _coverage_filter.address


class MaskRecords:
    """The user-data records of the masked meshes of a compiled scene (``SceneArrays``): ``records[g]`` is the
    address of mesh g's record, 0 for a mesh without a cut-out.  Keeps every array it points at alive."""

    def __init__(self, arrays, faces_by_mesh: list[np.ndarray]):
        self.records: list[int] = []
        self._keep: list[np.ndarray] = []
        uvs = np.ascontiguousarray(arrays.mesh_uvs, dtype=np.float64)
        table = np.ascontiguousarray(arrays.texture_table, dtype=np.int64)
        texel_bytes = np.ascontiguousarray(arrays.texture_bytes)
        texel_floats = np.ascontiguousarray(arrays.texture_floats)
        self._keep += [uvs, table, texel_bytes, texel_floats]
        for g, faces in enumerate(faces_by_mesh):
            material = arrays.mesh_material[g]
            cutoff = arrays.material_alpha[material, 0]
            if cutoff < 0.0 or arrays.mesh_light_start[g] >= 0:  # opaque, or an emitter (never cut)
                self.records.append(0)
                continue
            constants = np.array([arrays.material_alpha[material, 1], cutoff])
            record = np.array(
                [faces.ctypes.data, uvs.ctypes.data, uvs.shape[0], table.ctypes.data, table.shape[0],
                 texel_bytes.ctypes.data, texel_bytes.shape[0], texel_floats.ctypes.data, texel_floats.shape[0],
                 arrays.material_textures[material, 0], constants.ctypes.data],
                dtype=np.int64,
            )  # fmt: skip
            self._keep += [constants, record]
            self.records.append(int(record.ctypes.data))
