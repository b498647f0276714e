"""The light tree's eight importances at once (float32 vector IR) against the scalar importance, child by child."""

from __future__ import annotations

import numpy as np
import pytest

from lightprobe._numba import jit
from lightprobe.emitters.light_tree_lanes import (
    B_AXIS,
    B_CENTER,
    B_COS_E,
    B_COS_O,
    B_PHI,
    B_RADIUS,
    B_SIN_O,
    B_TWO_SIDED,
    BOUNDS_WIDTH,
    WIDTH,
    child_importances,
)
from lightprobe.emitters.selection import node_importance


@jit
def _both(wide, rows, receivers, vector, scalar):
    for k in range(receivers.shape[0]):
        p, n = receivers[k, 0:3], receivers[k, 3:6]
        node = k % wide.shape[0]
        w = child_importances(wide, node, p[0], p[1], p[2], n[0], n[1], n[2])
        for c in range(WIDTH):
            vector[k, c] = w[c]
            scalar[k, c] = node_importance(rows, node * WIDTH + c, p[0], p[1], p[2], n[0], n[1], n[2])


def _bounds(rng, nodes):
    """Random node bounds: boxes at distances 0-4 with radii 0-1.5 (receivers inside some), cones of every width,
    some two-sided, some emitting over less than a hemisphere; every eighth child empty (power 0, cos_e 2)."""
    rows = np.zeros((nodes * WIDTH, BOUNDS_WIDTH))
    rows[:, B_CENTER : B_CENTER + 3] = rng.normal(size=(nodes * WIDTH, 3)) * 2.0
    rows[:, B_RADIUS] = rng.random(nodes * WIDTH) * 1.5
    axis = rng.normal(size=(nodes * WIDTH, 3))
    rows[:, B_AXIS : B_AXIS + 3] = axis / np.linalg.norm(axis, axis=1, keepdims=True)
    rows[:, B_COS_O] = rng.uniform(-1.0, 1.0, nodes * WIDTH)
    rows[::5, B_COS_O] = 1.0  # one direction
    rows[:, B_SIN_O] = np.sqrt(1.0 - rows[:, B_COS_O] ** 2)
    rows[:, B_COS_E] = np.where(rng.random(nodes * WIDTH) < 0.2, 0.5, 0.0)
    rows[:, B_PHI] = rng.random(nodes * WIDTH) * 10.0
    rows[:, B_TWO_SIDED] = rng.random(nodes * WIDTH) < 0.3
    rows[WIDTH - 1 :: WIDTH, B_PHI] = 0.0
    rows[WIDTH - 1 :: WIDTH, B_COS_E] = 2.0
    wide = rows.reshape(nodes, WIDTH, BOUNDS_WIDTH).transpose(0, 2, 1).reshape(nodes, BOUNDS_WIDTH * WIDTH)
    return np.ascontiguousarray(wide), rows


@pytest.mark.parametrize("normal", ["unit", "zero"])
def test_eight_importances_at_once_are_the_scalar_ones(normal):
    rng = np.random.default_rng(7)
    wide, rows = _bounds(rng, 64)
    receivers = np.zeros((20_000, 6))
    receivers[:, 0:3] = rng.normal(size=(20_000, 3)) * 2.0
    receivers[::97, 0:3] = rows[: receivers[::97].shape[0], B_CENTER : B_CENTER + 3]  # at a box's centre: d = 0
    if normal == "unit":
        n = rng.normal(size=(20_000, 3))
        receivers[:, 3:6] = n / np.linalg.norm(n, axis=1, keepdims=True)
    vector, scalar = np.empty((20_000, WIDTH)), np.empty((20_000, WIDTH))
    _both(wide, rows, receivers, vector, scalar)
    assert np.all(np.isfinite(vector)) and np.all(vector >= 0.0)
    assert np.all(vector[:, WIDTH - 1] == 0.0)  # the empty child
    assert np.count_nonzero(scalar) > 0.5 * scalar.size and np.count_nonzero(scalar == 0.0) > 0.05 * scalar.size
    # the lanes compute in float32 after the float64 difference to the centre: within a thousandth of the child's
    # largest possible importance, phi / max(d^2, radius) (a sine taken as sqrt(d^2 - (a . d)^2) near 0 has an
    # error of sqrt(float32's epsilon), 3.5e-4; measured: 1.1e-3 relative to the importance itself at most)
    child = (np.arange(20_000) % 64)[:, None] * WIDTH + np.arange(WIDTH)[None, :]
    d2 = ((receivers[:, None, 0:3] - rows[child, B_CENTER : B_CENTER + 3]) ** 2).sum(axis=2)
    scale = rows[child, B_PHI] / np.maximum(d2, rows[child, B_RADIUS])
    assert np.all(np.abs(vector - scalar) <= 1e-3 * scale)
