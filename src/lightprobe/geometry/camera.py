"""Perspective pinhole camera.

``fov`` is the full angle in degrees along ``fov_axis`` ("y": vertical, the default; "x": horizontal, as
Mitsuba's default).  Pixel (i, j), i the column from the left and j the row from the top, with sample offsets
(xi1, xi2) in [0, 1)^2 (a box filter with jitter: each sample counts only for its own pixel)::

    sx = 2 (i + xi1) / W - 1,   sy = 1 - 2 (j + xi2) / H
    d  = normalize(forward + sx tan_x right + sy tan_y up)

with forward = normalize(target - origin), right = normalize(forward x up), up' = right x forward, and
tan_y = tan_x H / W.  The viewer's right is world +X when looking down -Z with +Y up (the image is not mirrored).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._numba import jit, jit_inline
from .._worksharing import in_threads
from ..errors import SceneError

__all__ = ["Camera", "camera_batch", "camera_ray"]


@dataclass(frozen=True)
class Camera:
    origin: np.ndarray
    target: np.ndarray
    up: np.ndarray
    fov: float
    resolution: tuple[int, int]
    fov_axis: str = "y"

    def __init__(
        self, origin, target, up=(0.0, 1.0, 0.0), *, fov: float = 40.0, resolution=(512, 512), fov_axis: str = "y"
    ):
        from .shapes import _vec3

        o, t, u = _vec3(origin, "camera origin"), _vec3(target, "camera target"), _vec3(up, "camera up")
        if np.linalg.norm(t - o) == 0:
            raise SceneError("camera target must differ from its origin")
        if np.linalg.norm(np.cross(t - o, u)) < 1e-9 * np.linalg.norm(t - o) * max(np.linalg.norm(u), 1e-300):
            raise SceneError("camera up must not be parallel to the viewing direction")
        fov = float(fov)
        if not (0.0 < fov < 180.0):
            raise SceneError(f"camera fov must be in (0, 180) degrees, got {fov}")
        if fov_axis not in ("x", "y"):
            raise SceneError(f"camera fov_axis must be 'x' or 'y', got {fov_axis!r}")
        try:
            w, h = (int(r) for r in resolution)
        except (TypeError, ValueError):
            raise SceneError(f"camera resolution must be [width, height], got {resolution!r}") from None
        if w < 1 or h < 1 or w * h > 1 << 28:
            raise SceneError(f"camera resolution must be positive and at most 2^28 pixels, got {w}x{h}")
        for name, value in (
            ("origin", o),
            ("target", t),
            ("up", u),
            ("fov", fov),
            ("resolution", (w, h)),
            ("fov_axis", fov_axis),
        ):
            object.__setattr__(self, name, value)

    @property
    def width(self) -> int:
        return self.resolution[0]

    @property
    def height(self) -> int:
        return self.resolution[1]

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        forward = (self.target - self.origin) / np.linalg.norm(self.target - self.origin)
        right = np.cross(forward, self.up)
        right /= np.linalg.norm(right)
        return forward, right, np.cross(right, forward)

    def kernel_array(self) -> np.ndarray:
        """[origin, forward, right, up, tan_x, tan_y, width, height] for :func:`camera_ray`."""
        forward, right, up = self.basis()
        w, h = self.resolution
        half = math.tan(math.radians(self.fov) / 2.0)
        tan_x, tan_y = (half, half * h / w) if self.fov_axis == "x" else (half * w / h, half)
        return np.concatenate([self.origin, forward, right, up, [tan_x, tan_y, w, h]])

    def with_resolution(self, width: int, height: int) -> Camera:
        return Camera(
            self.origin, self.target, self.up, fov=self.fov, resolution=(width, height), fov_axis=self.fov_axis
        )

    def rays(self, pixels, offsets) -> tuple[np.ndarray, np.ndarray]:
        """Origins and unit directions (N, 3) for flat pixel indices (N,) and offsets (N, 2) (object masks, tests)."""
        cam = self.kernel_array()
        pix = np.ascontiguousarray(pixels, dtype=np.int64).reshape(-1)
        off = np.ascontiguousarray(offsets, dtype=np.float64).reshape(-1, 2)
        if off.shape[0] != pix.shape[0]:
            raise ValueError(f"{pix.shape[0]} pixels but {off.shape[0]} offsets")
        d = camera_batch(cam, pix, off)  # compiled loops: a Python call per ray took 6-10 us
        return np.broadcast_to(self.origin, d.shape).copy(), d


@jit_inline
def camera_ray(cam, pixel, xi1, xi2):
    """Unit direction of the ray through flat pixel index ``pixel`` (row-major) at offsets (xi1, xi2)."""
    w = int(cam[14])
    h = int(cam[15])
    i = pixel % w
    j = pixel // w
    sx = (2.0 * (i + xi1) / w - 1.0) * cam[12]
    sy = (1.0 - 2.0 * (j + xi2) / h) * cam[13]
    dx = cam[3] + sx * cam[6] + sy * cam[9]
    dy = cam[4] + sx * cam[7] + sy * cam[10]
    dz = cam[5] + sx * cam[8] + sy * cam[11]
    inv = 1.0 / math.sqrt(dx * dx + dy * dy + dz * dz)
    return dx * inv, dy * inv, dz * inv


# a range kernel run by threads (``_worksharing.in_threads``), not a ``prange`` loop: the same values, and Numba's
# parallel-loop passes made such loops slow to compile (decisions.md 129)
@jit
def _camera_range(cam, pixels, jitter, out, lo, hi):
    for i in range(lo, hi):
        out[i, 0], out[i, 1], out[i, 2] = camera_ray(cam, pixels[i], jitter[i, 0], jitter[i, 1])


def camera_batch(cam, pixels, jitter) -> np.ndarray:
    """Unit directions (N, 3) of the rays of the camera's kernel array ``cam`` through flat pixel indices (N,) at
    offsets ``jitter`` (N, 2) (C-contiguous int64 and float64)."""
    out = np.empty((pixels.shape[0], 3))
    in_threads(_camera_range, pixels.shape[0], cam, pixels, jitter, out)
    return out
