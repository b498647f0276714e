"""Stage 4b, environment radiance: where the environment map is the scene's only light, the radiance of every live
slot's direction, looked up at the lat-long coordinates the two stages before gave it.

The lookups run 8 slots at a time in vector IR (``environment_lanes.radiance_block``): half the time of the scalar
lookup (decisions.md 42).  Every slot of a pass takes this path, so block boundaries never change a pixel.  One slot
at a time (``environment_radiance``) for the maps the lanes do not take (nearest lookups, one-row maps).  Kept apart
from the stages that sample: the map is megabytes, and in a small loop of independent lookups the CPU overlaps
their cache misses, where inside a large loop body it stalls on each (a bilinear lookup: 35 ns in its own loop,
150 ns inside the body; decisions.md 12, 41).
"""

from __future__ import annotations

from ..._numba import jit_body
from ...emitters.envmap import env_lookup
from ...simd import LANES
from ..techniques import SLOT_NONE
from .environment_lanes import radiance_block

__all__ = ["environment_radiance", "environment_radiance_lanes", "slot_blocks"]


def slot_blocks(c, cams, slots):
    """Items of the stages that take 8 consecutive slots at a time."""
    return (slots.state.shape[0] + LANES - 1) // LANES


@jit_body
def environment_radiance_lanes(env, slots, lo, hi):
    """Blocks lo .. hi - 1 of 8 slots."""
    for block in range(lo, hi):
        radiance_block(slots.radiance, env.image, slots.uv, slots.state, block * LANES)


@jit_body
def environment_radiance(env, slots, lo, hi):
    """Slots lo .. hi - 1, one lookup at a time."""
    for r in range(lo, hi):
        if slots.state[r] != SLOT_NONE:
            slots.radiance[r, 0], slots.radiance[r, 1], slots.radiance[r, 2] = env_lookup(
                env, slots.uv[r, 0], slots.uv[r, 1]
            )
