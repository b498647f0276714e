"""Techniques as users write them, right and wrong, for the laboratory's tests (loaded as FILE.py:NAME)."""

import sys
import time

import numpy as np

from lightprobe.lab import direction_to_uv, uv_to_direction


def _cosine(u):
    r = np.sqrt(u[:, 0])
    phi = 2.0 * np.pi * u[:, 1]
    z = np.sqrt(np.maximum(0.0, 1.0 - u[:, 0]))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1), z / np.pi


class Cosine:
    kind = "bsdf"

    def sample(self, u, ctx):
        return _cosine(u)

    def pdf(self, wi, ctx):
        return np.maximum(wi[:, 2], 0.0) / np.pi


class CosineUnnormalised(Cosine):
    """A non-normalised pdf: cos(theta) without the 1/pi."""

    def sample(self, u, ctx):
        wi, p = _cosine(u)
        return wi, p * np.pi

    def pdf(self, wi, ctx):
        return np.maximum(wi[:, 2], 0.0)


class CosineBelow(Cosine):
    """Directions below the surface with a non-zero pdf (the z flipped)."""

    def sample(self, u, ctx):
        wi, p = _cosine(u)
        wi[:, 2] = -wi[:, 2]
        return wi, p

    def pdf(self, wi, ctx):
        return np.abs(wi[:, 2]) / np.pi


class UniformClaimedCosine(Cosine):
    """Uniform directions that claim the cosine density, consistently: only the chi-square test sees it."""

    def sample(self, u, ctx):
        z = u[:, 0]
        r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
        phi = 2.0 * np.pi * u[:, 1]
        wi = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
        return wi, z / np.pi


class PhongWithCosinePdf:
    """The pdf of the wrong lobe: samples from the Phong lobe about the mirror direction, pdf() of the cosine lobe."""

    kind = "bsdf"
    support = "sphere"

    def sample(self, u, ctx):
        n = ctx.material.exponent
        mirror = np.stack([-ctx.wo[:, 0], -ctx.wo[:, 1], ctx.wo[:, 2]], axis=1)
        helper = np.where(np.abs(mirror[:, :1]) > 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
        s = np.cross(helper, mirror)
        s /= np.linalg.norm(s, axis=1, keepdims=True)
        t = np.cross(mirror, s)
        cos_a = u[:, 0] ** (1.0 / (n + 1.0))
        sin_a = np.sqrt(1.0 - cos_a**2)
        phi = 2.0 * np.pi * u[:, 1]
        wi = (sin_a * np.cos(phi))[:, None] * s + (sin_a * np.sin(phi))[:, None] * t + cos_a[:, None] * mirror
        return wi, (n + 1.0) / (2.0 * np.pi) * cos_a**n

    def pdf(self, wi, ctx):
        return np.maximum(wi[:, 2], 0.0) / np.pi


class UniformSphereLight:
    """A light technique: directions uniform on the sphere."""

    kind = "light"

    def sample(self, u, ctx):
        z = 1.0 - 2.0 * u[:, 0]
        r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
        phi = 2.0 * np.pi * u[:, 1]
        return np.stack([r * np.cos(phi), z, r * np.sin(phi)], axis=1), np.full(len(u), 1.0 / (4.0 * np.pi))

    def pdf(self, wi, ctx):
        return np.full(len(wi), 1.0 / (4.0 * np.pi))


class MapWithoutSinTheta:
    """The map's (u, v) distribution without the sin(theta) of the lat-long Jacobian: p(w) = p(u, v) / (2 pi^2)."""

    kind = "light"
    dimensions = 3

    def prepare(self, environment):
        self.environment = environment
        lum = np.asarray(environment.luminance, dtype=np.float64)
        self.shape = lum.shape
        self.density = lum * lum.size / lum.sum()
        self.cdf = np.cumsum(lum.reshape(-1)) / lum.sum()

    def sample(self, u, ctx):
        h, w = self.shape
        k = np.minimum(np.searchsorted(self.cdf, u[:, 0], side="right"), h * w - 1)
        j, i = np.divmod(k, w)
        uu = (i + u[:, 1]) / w
        vv = (j + u[:, 2]) / h
        return uv_to_direction(self.environment, uu, vv), self._pdf(uu, vv)

    def pdf(self, wi, ctx):
        return self._pdf(*direction_to_uv(self.environment, wi))

    def _pdf(self, uu, vv):
        h, w = self.shape
        i = np.minimum((uu * w).astype(int), w - 1)
        j = np.minimum((vv * h).astype(int), h - 1)
        return self.density[j, i] / (2.0 * np.pi**2)


class Raises(Cosine):
    def sample(self, u, ctx):
        raise ValueError("my bug")


class Exits(Cosine):
    def sample(self, u, ctx):
        sys.exit(0)


class ReturnsNaN(Cosine):
    def sample(self, u, ctx):
        wi, p = _cosine(u)
        p[3] = np.nan
        return wi, p


class NegativePdf(Cosine):
    def pdf(self, wi, ctx):
        out = np.maximum(wi[:, 2], 0.0) / np.pi
        out[0] = -1.0
        return out


class WrongShape(Cosine):
    def sample(self, u, ctx):
        wi, p = _cosine(u)
        return wi[:, :2], p


class NotUnit(Cosine):
    def sample(self, u, ctx):
        wi, p = _cosine(u)
        return 2.0 * wi, p


class TextResult(Cosine):
    def pdf(self, wi, ctx):
        return np.array(["a"] * len(wi))


class Slow(Cosine):
    def sample(self, u, ctx):
        time.sleep(5.0)
        return _cosine(u)


class FailsLater(Cosine):
    """Right for its first 3 calls (a pass of the exercise's scene makes one per material seen, 2 or 3), then raises:
    a render that meets it keeps its first pass."""

    def __init__(self):
        self.calls = 0

    def sample(self, u, ctx):
        self.calls += 1
        if self.calls > 3:
            raise RuntimeError("ran out of luck")
        return _cosine(u)


class SlowLater(FailsLater):
    """Right and quick for its first 3 calls (the first pass of the exercise's scene), then 100 s a call: longer
    than its own 60-s limit, so only a render's time limit ends it in time."""

    def sample(self, u, ctx):
        self.calls += 1
        if self.calls > 3:
            time.sleep(100.0)
        return _cosine(u)
