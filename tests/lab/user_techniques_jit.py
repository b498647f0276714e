"""User techniques written as numba.njit functions, right and wrong, for the tests of the laboratory's compiled path
(the right ones are examples/njit_sampling.py)."""

import numba
import numpy as np


@numba.njit
def _cosine(u):
    r, phi = np.sqrt(u[0]), 2.0 * np.pi * u[1]
    z = np.sqrt(max(0.0, 1.0 - u[0]))
    return (r * np.cos(phi), r * np.sin(phi), z), z / np.pi


class Cosine:
    kind = "bsdf"
    dimensions = 2
    support = "hemisphere"

    @staticmethod
    @numba.njit
    def sample(u, ctx):
        return _cosine(u)

    @staticmethod
    @numba.njit
    def pdf(wi, ctx):
        return max(wi[2], 0.0) / np.pi


class CosineUnnormalised(Cosine):
    """cos(theta) without the 1/pi."""

    @staticmethod
    @numba.njit
    def sample(u, ctx):
        wi, p = _cosine(u)
        return wi, p * np.pi

    @staticmethod
    @numba.njit
    def pdf(wi, ctx):
        return max(wi[2], 0.0)


class CosineBelow(Cosine):
    """Mirrors a quarter of its samples below the surface and still gives them a density."""

    @staticmethod
    @numba.njit
    def sample(u, ctx):
        (x, y, z), p = _cosine(u)
        if u[1] < 0.25:
            z = -z
        return (x, y, z), p

    @staticmethod
    @numba.njit
    def pdf(wi, ctx):
        return abs(wi[2]) / np.pi


class MapWithoutSinTheta:
    """The map's (u, v) distribution without the sin(theta) of the lat-long Jacobian: p(w) = p(u, v) / (2 pi^2)."""

    kind = "light"
    dimensions = 3

    def prepare(self, environment):
        lum = np.asarray(environment.luminance, dtype=np.float64)
        density = lum * lum.size / lum.sum()
        cdf = np.cumsum(lum.reshape(-1)) / lum.sum()
        self.data = (density, cdf, np.ascontiguousarray(environment.to_world, dtype=np.float64))

    @staticmethod
    @numba.njit
    def sample(u, ctx):
        density, cdf, rotation = ctx.data
        h, w = density.shape
        k = min(np.searchsorted(cdf, u[0], side="right"), h * w - 1)
        j, i = k // w, k % w
        uu, vv = (i + u[1]) / w, (j + u[2]) / h
        theta, phi = np.pi * vv, 2.0 * np.pi * uu
        local = np.array((np.sin(phi) * np.sin(theta), np.cos(theta), -np.cos(phi) * np.sin(theta)))
        return rotation @ local, density[j, i] / (2.0 * np.pi**2)

    @staticmethod
    @numba.njit
    def pdf(wi, ctx):
        density, _, rotation = ctx.data
        h, w = density.shape
        local = rotation.T @ np.ascontiguousarray(wi)
        uu = np.arctan2(local[0], -local[2]) / (2.0 * np.pi)
        uu = uu + 1.0 if uu < 0.0 else uu
        vv = np.arccos(min(max(local[1], -1.0), 1.0)) / np.pi
        return density[min(int(vv * h), h - 1), min(int(uu * w), w - 1)] / (2.0 * np.pi**2)


class Raises(Cosine):
    @staticmethod
    @numba.njit
    def sample(u, ctx):
        if u[0] > 0.5:
            raise ValueError("my njit bug")
        return _cosine(u)


class ReturnsNaN(Cosine):
    @staticmethod
    @numba.njit
    def sample(u, ctx):
        wi, p = _cosine(u)
        return wi, np.nan if u[0] > 0.5 else p


class NegativePdf(Cosine):
    @staticmethod
    @numba.njit
    def pdf(wi, ctx):
        return -1.0


class NotUnit(Cosine):
    @staticmethod
    @numba.njit
    def sample(u, ctx):
        (x, y, z), p = _cosine(u)
        return (2.0 * x, 2.0 * y, 2.0 * z), p


class DoesNotCompile(Cosine):
    @staticmethod
    @numba.njit
    def sample(u, ctx):
        return ctx.no_such_field, 1.0


class TakesSelf(Cosine):
    sample = numba.njit(lambda self, u, ctx: ((0.0, 0.0, 1.0), 1.0))


class OnlySampleIsNjit(Cosine):
    def pdf(self, wi, ctx):
        return np.maximum(wi[:, 2], 0.0) / np.pi


class Slow(Cosine):
    """About 20 microseconds a sample: a batch of 100,000 takes about a second per core."""

    @staticmethod
    @numba.njit
    def sample(u, ctx):
        s = 0.0
        for k in range(2_000):
            s += np.sin(k * u[0])
        return _cosine(u)[0], 1.0 / np.pi + 0.0 * s


class FailsLater(Cosine):
    """Right until it has drawn ``ctx.data[1]`` samples (its own counter, ctx.data[0], counts them), then raises:
    a render that meets it keeps the passes before."""

    def __init__(self, samples=10_000):
        self.data = (np.zeros(1), float(samples))

    @staticmethod
    @numba.njit
    def sample(u, ctx):
        ctx.data[0][0] += 1.0
        if ctx.data[0][0] > ctx.data[1]:
            raise RuntimeError("ran out of luck")
        return _cosine(u)


@numba.njit
def balance(n_f, p_f, n_g, p_g):
    a, b = n_f * p_f, n_g * p_g
    return a / (a + b) if a + b > 0.0 else 0.0


@numba.njit
def over_weighted(n_f, p_f, n_g, p_g):
    """The balance heuristic + 0.05: weights that sum to 1.1."""
    a, b = n_f * p_f, n_g * p_g
    return min(a / (a + b) + 0.05, 1.0) if a + b > 0.0 else 0.0
