"""Embree 4 through its C API, called from inside the Numba kernels (one ray per call).

The library is the ``libembree4`` that ``embreex``'s wheel ships.  It is opened twice: with ``ctypes``, to build
scenes from Python, and into LLVM's symbol table (``llvmlite.binding.load_library_permanently``), so that kernels
call ``rtcOccluded1`` and ``rtcIntersect1`` as external functions *by name*.  A ctypes function pointer baked into
a kernel would make Numba refuse to cache it; a symbol name is resolved when the cached code is loaded.  Calling
Embree inside the kernels drops the gather, float32 copy, thread pool and scatter that batches through ``embreex``
needed (decisions.md 30 has the measurements).

Ray structs live in ``scratch``, one 640-byte row per thread (the renderer's worker index, or a batch kernel's
``numba.get_thread_id()``): the functions here take the caller's row.  Embree wants them 16-byte aligned (NumPy's
allocations are), and rows a cache line apart keep the two threads from sharing lines.
Layout of ``RTCRayHit`` in this build (instance arrays enabled: 96 bytes), in 32-bit words: origin 0-2, tnear 3,
direction 4-6, time 7, tfar 8, mask 9, id 10, flags 11, geometric normal 12-14, u 15, v 16, primID 17, geomID 18,
instID 19, instPrimID 20.  ``rtcOccluded1`` reads the first 12 words (``RTCRay``) and reports a blocked ray by
setting tfar to -inf; ``rtcIntersect1`` leaves primID/geomID untouched on a miss, so they are set to -1 first.
Inputs are rounded to float32 as Embree stores them; the scene is built robust (watertight), as ``embreex`` did.

Shadow rays also go 8 at a time (``rtcOccluded8``, decisions.md 55) where the CPU has native 8-wide packets
(:func:`packets_native`): the ``RTCRay8`` is structure-of-arrays, 12 rows of 8 words (origin x, y, z, tnear,
direction x, y, z, time, tfar, mask, id, flags), 32-byte aligned, followed here by the packet's valid mask (8 words,
-1 for a ray, 0 for a lane left empty).  It lives further along the thread's scratch row, at the first 64-byte
boundary from word 32.  A lane's answer does not depend on the other lanes: the same image whatever the packets
hold.
"""

from __future__ import annotations

import ctypes
import glob
import os

import numba
import numpy as np
from numba import types

from .._numba import jit, jit_inline
from .._worksharing import in_threads
from ..errors import LightprobeError

__all__ = [
    "EmbreeScene",
    "closest_mesh_hit",
    "intersect_batch",
    "mesh_occluded",
    "new_scratch",
    "occluded_batch",
    "occluded_packet",
    "occluded_packets_batch",
    "packet_ray",
    "packet_words",
    "packets_native",
]

INVALID_ID = 0xFFFFFFFF  # RTC_INVALID_GEOMETRY_ID
_RTC_SCENE_FLAG_ROBUST = 1 << 2
_RTC_GEOMETRY_TYPE_TRIANGLE = 0
_RTC_BUFFER_TYPE_INDEX, _RTC_BUFFER_TYPE_VERTEX = 0, 1
_RTC_FORMAT_UINT3, _RTC_FORMAT_FLOAT3 = 0x5003, 0x9003
# one row of ``scratch``: a 96-byte RTCRayHit padded to 128 bytes (two cache lines), then up to 60 bytes to a
# 64-byte boundary, a 384-byte RTCRay8 and its 32-byte valid mask (640 bytes: the rows stay 64-byte multiples)
SCRATCH_WORDS = 160
PACKET = 8  # rays per rtcOccluded8 call
_PACKET_WORDS = 13 * PACKET  # RTCRay8's 12 rows and the valid mask
FAR = np.float32(3e38)  # tfar of a ray with no nearer analytic hit (as before, so hits are bit-identical)


def _library_path() -> str:
    try:
        import embreex
    except ImportError as exc:  # pragma: no cover - embreex is a dependency
        raise LightprobeError("lightprobe needs embreex (pip install embreex): it ships the Embree 4 library") from exc
    libs = os.path.join(os.path.dirname(os.path.dirname(embreex.__file__)), "embreex.libs")
    found = sorted(glob.glob(os.path.join(libs, "libembree4*")))
    if not found:  # pragma: no cover - a wheel without the bundled library
        raise LightprobeError(f"no libembree4 in {libs}: reinstall embreex")
    return found[0]


def _load():
    import llvmlite.binding as llvm

    path = _library_path()
    lib = ctypes.CDLL(path)
    llvm.load_library_permanently(path)
    vp, uint, size = ctypes.c_void_p, ctypes.c_uint, ctypes.c_size_t
    signatures = {
        "rtcNewDevice": (vp, [ctypes.c_char_p]),
        "rtcReleaseDevice": (None, [vp]),
        "rtcGetDeviceError": (ctypes.c_int, [vp]),
        "rtcNewScene": (vp, [vp]),
        "rtcSetSceneFlags": (None, [vp, ctypes.c_int]),
        "rtcCommitScene": (None, [vp]),
        "rtcReleaseScene": (None, [vp]),
        "rtcNewGeometry": (vp, [vp, ctypes.c_int]),
        "rtcSetSharedGeometryBuffer": (None, [vp, ctypes.c_int, uint, ctypes.c_int, vp, size, size, size]),
        "rtcCommitGeometry": (None, [vp]),
        "rtcAttachGeometry": (uint, [vp, vp]),
        "rtcReleaseGeometry": (None, [vp]),
        "rtcGetDeviceProperty": (ctypes.c_ssize_t, [vp, ctypes.c_int]),
        "rtcSetGeometryUserData": (None, [vp, vp]),
        "rtcSetGeometryIntersectFilterFunction": (None, [vp, vp]),
        "rtcSetGeometryOccludedFilterFunction": (None, [vp, vp]),
    }
    for name, (restype, argtypes) in signatures.items():
        fn = getattr(lib, name)
        fn.restype, fn.argtypes = restype, argtypes
    return lib


_lib = _load()

# void rtcOccluded1(RTCScene, RTCRay*, RTCOccludedArguments*) and rtcIntersect1(RTCScene, RTCRayHit*,
# RTCIntersectArguments*); pointers pass as 64-bit integers (the same registers under the x86-64 and AArch64 ABIs),
# null arguments select Embree's defaults
_rtc_occluded1 = types.ExternalFunction("rtcOccluded1", types.void(types.intp, types.intp, types.intp))
_rtc_intersect1 = types.ExternalFunction("rtcIntersect1", types.void(types.intp, types.intp, types.intp))
# void rtcOccluded8(const int* valid, RTCScene, RTCRay8*, RTCOccludedArguments*)
_rtc_occluded8 = types.ExternalFunction("rtcOccluded8", types.void(types.intp, types.intp, types.intp, types.intp))
_RTC_DEVICE_PROPERTY_NATIVE_RAY8_SUPPORTED = 33
_native_packets: list[bool] = []


def packets_native() -> bool:
    """Does this CPU run Embree's 8-ray packets natively (AVX and up)?  Without, shadow rays go one at a time."""
    if not _native_packets:
        device = _lib.rtcNewDevice(None)
        if not device:
            raise LightprobeError("Embree could not create a device")
        _native_packets.append(bool(_lib.rtcGetDeviceProperty(device, _RTC_DEVICE_PROPERTY_NATIVE_RAY8_SUPPORTED)))
        _lib.rtcReleaseDevice(device)
    return _native_packets[0]


class EmbreeScene:
    """Triangle meshes in one Embree scene; mesh g is geometry g (so geomID is the mesh index).

    ``handle`` is the ``RTCScene`` pointer as an integer, for the kernels.  The vertex and index arrays are shared
    with Embree (not copied), so the scene keeps them alive until :meth:`close`.  ``arrays`` (the compiled scene)
    gives the meshes with alpha cut-outs their filter function (``alpha_mask.py``).
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, face_start: np.ndarray, *, arrays=None):
        self._scene = self._device = None  # so that close() (and __del__) work however far this gets
        self.handle = 0
        self._device = _lib.rtcNewDevice(None)
        if not self._device:
            raise LightprobeError("Embree could not create a device")
        self._scene = _lib.rtcNewScene(self._device)
        _lib.rtcSetSceneFlags(self._scene, _RTC_SCENE_FLAG_ROBUST)
        # Embree may read 16 bytes at the last vertex (its documented padding rule), hence the spare row
        self._vertices = np.zeros((vertices.shape[0] + 1, 3), np.float32)
        self._vertices[:-1] = vertices
        self._indices = [
            np.ascontiguousarray(faces[face_start[g] : face_start[g + 1]], dtype=np.uint32)
            for g in range(face_start.shape[0] - 1)
        ]
        self._masks = None
        if arrays is not None and np.any(arrays.material_alpha[:, 0] >= 0.0):
            from .alpha_mask import MaskRecords, filter_address

            self._masks = MaskRecords(arrays, self._indices)
        for g, idx in enumerate(self._indices):
            geom = _lib.rtcNewGeometry(self._device, _RTC_GEOMETRY_TYPE_TRIANGLE)
            _lib.rtcSetSharedGeometryBuffer(
                geom, _RTC_BUFFER_TYPE_VERTEX, 0, _RTC_FORMAT_FLOAT3, self._vertices.ctypes.data, 0, 12,
                vertices.shape[0],
            )  # fmt: skip
            _lib.rtcSetSharedGeometryBuffer(
                geom, _RTC_BUFFER_TYPE_INDEX, 0, _RTC_FORMAT_UINT3, idx.ctypes.data, 0, 12, idx.shape[0]
            )
            if self._masks is not None and self._masks.records[g]:
                _lib.rtcSetGeometryUserData(geom, self._masks.records[g])
                _lib.rtcSetGeometryIntersectFilterFunction(geom, filter_address())
                _lib.rtcSetGeometryOccludedFilterFunction(geom, filter_address())
            _lib.rtcCommitGeometry(geom)
            _lib.rtcAttachGeometry(self._scene, geom)
            _lib.rtcReleaseGeometry(geom)
        _lib.rtcCommitScene(self._scene)  # builds the BVH now, outside any timed query
        error = _lib.rtcGetDeviceError(self._device)
        if error:
            self.close()
            raise LightprobeError(f"Embree could not build the mesh scene (RTCError {error})")
        self.handle = int(self._scene)

    def close(self) -> None:
        if self._scene:
            _lib.rtcReleaseScene(self._scene)
            self._scene = None
        if self._device:
            _lib.rtcReleaseDevice(self._device)
            self._device = None
        self.handle = 0

    def __del__(self):
        self.close()


def new_scratch() -> np.ndarray:
    """Ray structs for the kernels: one row per Numba thread."""
    return np.zeros((numba.config.NUMBA_NUM_THREADS, SCRATCH_WORDS), np.uint32)


@jit_inline
def _put_ray(words, floats, ox, oy, oz, dx, dy, dz, tfar):
    floats[0], floats[1], floats[2], floats[3] = np.float32(ox), np.float32(oy), np.float32(oz), np.float32(0.0)
    floats[4], floats[5], floats[6], floats[7] = np.float32(dx), np.float32(dy), np.float32(dz), np.float32(0.0)
    floats[8] = np.float32(tfar)
    words[9] = INVALID_ID  # mask: every geometry
    words[10] = 0
    words[11] = 0


@jit_inline
def mesh_occluded(scene, words, ox, oy, oz, dx, dy, dz, tfar):
    """Does a mesh triangle block the ray on (0, tfar)?  (tfar float32: pass ``FAR`` for an unbounded ray.)
    ``words``: the caller's scratch row."""
    floats = words.view(np.float32)
    _put_ray(words, floats, ox, oy, oz, dx, dy, dz, tfar)
    _rtc_occluded1(scene, words.ctypes.data, 0)
    return floats[8] == -np.inf


@jit_inline
def packet_words(words):
    """The RTCRay8 and valid mask in a scratch row: 104 of its words, 64-byte aligned."""
    start = 32 + ((64 - words.ctypes.data % 64) % 64) // 4
    return words[start : start + _PACKET_WORDS]


@jit_inline
def packet_ray(packet, floats, i, ox, oy, oz, dx, dy, dz, tfar):
    """Lane i of the packet (``floats`` is ``packet.view(np.float32)``): the ray on (0, tfar), as :func:`_put_ray`."""
    floats[i], floats[8 + i], floats[16 + i], floats[24 + i] = (
        np.float32(ox), np.float32(oy), np.float32(oz), np.float32(0.0)
    )  # fmt: skip
    floats[32 + i], floats[40 + i], floats[48 + i], floats[56 + i] = (
        np.float32(dx), np.float32(dy), np.float32(dz), np.float32(0.0)
    )  # fmt: skip
    floats[64 + i] = np.float32(tfar)
    packet[72 + i] = INVALID_ID  # mask: every geometry
    packet[80 + i] = 0
    packet[88 + i] = 0


@jit_inline
def occluded_packet(scene, packet, floats, count):
    """Trace the packet's first ``count`` lanes (set by :func:`packet_ray`); bit i of the result: is lane i's ray
    blocked?  (Embree marks a blocked ray by its tfar set to -inf, as for one ray.)"""
    for i in range(PACKET):
        packet[96 + i] = INVALID_ID if i < count else 0  # the valid mask: all bits set (-1) for a ray
    _rtc_occluded8(packet.ctypes.data + 96 * 4, scene, packet.ctypes.data, 0)
    blocked = 0
    for i in range(count):
        if floats[64 + i] == -np.inf:
            blocked |= 1 << i
    return blocked


@jit_inline
def closest_mesh_hit(scene, words, ox, oy, oz, dx, dy, dz, tfar):
    """The nearest triangle hit closer than tfar: (t, mesh, face, b1, b2); mesh -1 when there is none.  ``words``:
    the caller's scratch row."""
    floats = words.view(np.float32)
    _put_ray(words, floats, ox, oy, oz, dx, dy, dz, tfar)
    words[17] = INVALID_ID
    words[18] = INVALID_ID
    _rtc_intersect1(scene, words.ctypes.data, 0)
    if words[18] == INVALID_ID:
        return np.float32(tfar), -1, -1, np.float32(0.0), np.float32(0.0)
    return floats[8], np.int64(words[18]), np.int64(words[17]), floats[15], floats[16]


# The batches are range kernels run by threads, each with its own scratch row (``_worksharing.in_threads``), not
# ``prange`` loops: the same answers, and Numba's parallel-loop passes made them slow to compile (decisions.md 129).
@jit
def _occluded_range(words, scene, origins, dirs, tfar, blocked, lo, hi):
    for i in range(lo, hi):
        blocked[i] = mesh_occluded(
            scene, words, origins[i, 0], origins[i, 1], origins[i, 2], dirs[i, 0], dirs[i, 1], dirs[i, 2], tfar[i]
        )


def occluded_batch(scene, scratch, origins, dirs, tfar):
    """Boolean (N,): does a mesh of ``scene`` block each segment (0, tfar)?  ``scratch``: :func:`new_scratch`."""
    blocked = np.empty(dirs.shape[0], np.bool_)
    in_threads(_occluded_range, dirs.shape[0], scene, origins, dirs, tfar, blocked, scratch=scratch)
    return blocked


@jit
def _occluded_packets_range(words, scene, origins, dirs, tfar, blocked, lo, hi):
    n = dirs.shape[0]
    packet = packet_words(words)
    floats = packet.view(np.float32)
    for p in range(lo, hi):
        first = p * PACKET
        count = min(PACKET, n - first)
        for i in range(count):
            q = first + i
            packet_ray(packet, floats, i, origins[q, 0], origins[q, 1], origins[q, 2], dirs[q, 0], dirs[q, 1],
                       dirs[q, 2], tfar[q])  # fmt: skip
        bits = occluded_packet(scene, packet, floats, count)
        for i in range(count):
            blocked[first + i] = bits >> i & 1 == 1


def occluded_packets_batch(scene, scratch, origins, dirs, tfar):
    """:func:`occluded_batch` through :func:`occluded_packet`, 8 rays a call (the last packet partly empty)."""
    n = dirs.shape[0]
    blocked = np.empty(n, np.bool_)
    in_threads(_occluded_packets_range, (n + PACKET - 1) // PACKET, scene, origins, dirs, tfar, blocked,
               scratch=scratch)  # fmt: skip
    return blocked


@jit
def _intersect_range(words, scene, origins, dirs, tfar, t, geom, prim, u, v, lo, hi):
    for i in range(lo, hi):
        t[i], geom[i], prim[i], u[i], v[i] = closest_mesh_hit(
            scene, words, origins[i, 0], origins[i, 1], origins[i, 2], dirs[i, 0], dirs[i, 1], dirs[i, 2], tfar[i]
        )


def intersect_batch(scene, scratch, origins, dirs, tfar):
    """The nearest mesh hit of each ray closer than tfar: (t, mesh, face, b1, b2), mesh -1 where there is none."""
    n = dirs.shape[0]
    t = np.empty(n, np.float32)
    geom = np.empty(n, np.int64)
    prim = np.empty(n, np.int64)
    u = np.empty(n, np.float32)
    v = np.empty(n, np.float32)
    in_threads(_intersect_range, n, scene, origins, dirs, tfar, t, geom, prim, u, v, scratch=scratch)
    return t, geom, prim, u, v
