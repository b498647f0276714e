"""Light selectors for the tests: each but the last breaks the contract (lightprobe/lab/selectors.py) in one way."""

import numpy as np


class _Uniform:
    def select(self, ctx, u):
        n = ctx.lights.count
        light = np.minimum((u * n).astype(np.int64), n - 1)
        return light, np.full(len(ctx), 1.0 / n)

    def pmf(self, ctx, light):
        return np.full(len(ctx), 1.0 / ctx.lights.count)


class OutOfRange(_Uniform):
    def select(self, ctx, u):
        light, pmf = super().select(ctx, u)
        return light + 1, pmf  # the last light's pick is past the table


class ZeroForItsPick(_Uniform):
    def select(self, ctx, u):
        light, pmf = super().select(ctx, u)
        return light, np.where(light == 0, 0.0, pmf)


class NotNormalised(_Uniform):
    def pmf(self, ctx, light):
        return np.full(len(ctx), 1.1 / ctx.lights.count)


class SelectSaysOtherwise(_Uniform):
    def select(self, ctx, u):
        light, pmf = super().select(ctx, u)
        return light, pmf * 0.5


class PicksTheFirstTooOften(_Uniform):
    """Its pmf() is uniform, its picks are not: light 0 gets half of them."""

    def select(self, ctx, u):
        n = ctx.lights.count
        light = np.where(u < 0.5, 0, np.minimum(((u - 0.5) * 2 * n).astype(np.int64), n - 1))
        return light, np.full(len(ctx), 1.0 / n)


class Raises(_Uniform):
    def pmf(self, ctx, light):
        raise RuntimeError("no pmf today")


class WrongShape(_Uniform):
    def pmf(self, ctx, light):
        return np.full((len(ctx), 2), 0.5)


class FloatIndices(_Uniform):
    def select(self, ctx, u):
        light, pmf = super().select(ctx, u)
        return light.astype(np.float64), pmf


class FailsOnLargeBatches(_Uniform):
    """Passes the check before the renders (64 points), fails where the light choice measures it (more)."""

    def pmf(self, ctx, light):
        if len(ctx) > 100:
            raise ValueError("too many points")
        return super().pmf(ctx, light)


class ByPower:
    """One that keeps the contract: bounded lights in proportion to their power, the infinite ones sharing a tenth
    (all of it where no bounded light emits)."""

    def prepare(self, lights):
        weights = np.where(lights.infinite, 0.0, lights.power)
        infinite = lights.infinite.sum()
        share = 0.1 if weights.sum() > 0 and infinite else 1.0
        if weights.sum() > 0:
            weights = weights / weights.sum() * (1.0 - share if infinite else 1.0)
        self.table = np.where(lights.infinite, share / max(infinite, 1), weights)
        self.cdf = np.cumsum(self.table)

    def select(self, ctx, u):
        light = np.minimum(np.searchsorted(self.cdf, u * self.cdf[-1], side="right"), len(self.cdf) - 1)
        return light, self.table[light]

    def pmf(self, ctx, light):
        return self.table[light]
