"""Hand-made pass records for testing one stage at a time: every field a pass has, zeros unless given."""

from __future__ import annotations

import numba
import numpy as np

from lightprobe.emitters.envmap import placeholder_environment
from lightprobe.emitters.selection import build_selector
from lightprobe.geometry.camera import Camera
from lightprobe.geometry.embree import PACKET, new_scratch
from lightprobe.integrators import outlines, pipeline
from lightprobe.integrators.accumulation import Accumulator
from lightprobe.integrators.pass_state import CameraSamples, PassConstants, Slots, camera_buffers, slot_buffers
from lightprobe.integrators.stages.ray_lanes import FIELDS as RAY_FIELDS
from lightprobe.integrators.stages.setup import SETUP_RUN
from lightprobe.integrators.techniques import STRATEGIES
from lightprobe.scene import Scene


def constants(m: int, **given) -> PassConstants:
    """PassConstants for ``m`` slots per camera sample: MIS with m // 2 BSDF slots, one thread's scratch, ..."""
    threads = numba.config.NUMBA_NUM_THREADS
    n_bsdf = given.pop("n_bsdf", m // 2)
    values = {
        "sampler": 0,
        "seed": 0,
        "strategy": STRATEGIES["mis"],
        "n_bsdf": n_bsdf,
        "n_light": m - n_bsdf,
        "n_per_light": m - n_bsdf,
        "m": m,
        "beta": 1.0,
        "light_strategy": 1,
        "env_candidates": 1,
        "bsdf_weighed": False,
        "compensate": np.zeros(2, np.bool_),
        "cam": np.zeros(16),
        "mesh_scene": 0,
        "scratch": new_scratch(),
        "ray_counts": np.zeros((threads, 8), np.int64),
        "numbers": np.zeros((threads, (SETUP_RUN * m + 7) // 8 * 8, 3)),
        "packet_slots": np.zeros((threads, PACKET), np.int64),
        "lane_rays": np.zeros((threads, RAY_FIELDS, 8)),
        "pixels": np.zeros(0, np.int64),
        "spp_pass": 1,
        "sample_start": 0,
        **outlines.pass_fields(None, None, None, enabled=False),
    }
    values.update(given)
    return PassConstants(**values)


def cameras(n: int, **given) -> CameraSamples:
    """n camera samples' arrays (zeros), with the given ones in their place (copied, C-contiguous)."""
    record = camera_buffers(n)._replace(**{k: np.ascontiguousarray(v) for k, v in given.items()})
    for name, a in record._asdict().items():
        if name not in given:
            a[...] = 0
    return record


def slots(nm: int, *, picks: bool = False, bounded: bool = False, hits: bool = False, **given) -> Slots:
    """nm slots' arrays (zeros), with the given ones in their place."""
    record = slot_buffers(nm, picks=picks, bounded_shadows=bounded, bsdf_hits=hits)._replace(
        **{k: np.ascontiguousarray(v) for k, v in given.items()}
    )
    for name, a in record._asdict().items():
        if name not in given:
            a[...] = 0
    return record


def records(c, cams, slots_, *, scene=None, env=None, arrays=None):
    """(s, env, lights, sel, c, cams, slots, acc) for ``run``: the scene's arrays (an empty scene's by default),
    the environment kernel ``env`` (a placeholder by default) and light table with its row."""
    scene = scene or Scene(Camera([0, 0, 0], [0, 0, -1], fov=40, resolution=(2, 2)))
    arrays = arrays if arrays is not None else scene.compile()
    lights = scene.light_table()
    environment = scene.environment
    sel = build_selector(
        "bvh", lights, env_irradiance=environment.irradiance_terms if environment is not None else None
    )
    env_kernel = env if env is not None else (environment or placeholder_environment()).kernel
    acc = Accumulator(max(1, int(c.pixels.max()) + 1) if c.pixels.size else 1).arrays()
    return arrays, env_kernel, lights, sel, c, cams, slots_, acc


def run(name: str, recs, threads: int | None = None) -> None:
    """Run stage ``name`` over ``recs`` with ``threads`` workers (all by default)."""
    pipeline.Launcher(threads or numba.get_num_threads()).run(pipeline.stage_id(name), recs)
