"""Light selectors of your own, for ``lightprobe compare SCENE --selector examples/light_selectors.py:NAME``.

The report's "Light choice" section then lists each selector beside lightprobe's (uniform, power, bvh) and the
oracle, with the variance its choice of light adds at the camera's shading points (lightprobe/lab/selectors.py has
the contract; every call is checked: indices in range, pmfs summing to 1, picks that follow ``pmf()``).
"""

import numpy as np

#: the share of the picks the infinite lights (sky, sun, environment map) get, where the scene has any
INFINITE_SHARE = 0.2


class PowerOverDistance:
    """Each bounded light in proportion to its power over its squared distance from the point (what a light of
    that power at that distance gives a surface facing it), the infinite lights sharing a fixed fifth."""

    def weights(self, ctx) -> np.ndarray:
        lights = ctx.lights
        bounded = ~lights.infinite
        d2 = ((ctx.point[:, None, :] - lights.center[None, bounded, :]) ** 2).sum(axis=2)
        w = np.zeros((len(ctx), lights.count))
        w[:, bounded] = lights.power[bounded] / np.maximum(d2, 1e-4)
        w[:, bounded] /= np.maximum(w[:, bounded].sum(axis=1, keepdims=True), 1e-300)
        if lights.infinite.any():
            share = INFINITE_SHARE if bounded.any() else 1.0
            w[:, bounded] *= 1.0 - share
            w[:, lights.infinite] = share / lights.infinite.sum()
        return w

    def select(self, ctx, u):
        cdf = np.cumsum(self.weights(ctx), axis=1)
        light = np.minimum((cdf < u[:, None] * cdf[:, -1:]).sum(axis=1), ctx.lights.count - 1)
        return light, self.pmf(ctx, light)

    def pmf(self, ctx, light):
        return self.weights(ctx)[np.arange(len(ctx)), light]


class Uniform:
    """Every light alike: the baseline."""

    def select(self, ctx, u):
        n = ctx.lights.count
        light = np.minimum((u * n).astype(np.int64), n - 1)
        return light, np.full(len(ctx), 1.0 / n)

    def pmf(self, ctx, light):
        return np.full(len(ctx), 1.0 / ctx.lights.count)
