"""The renderer's shading slots hand their sampler's 2D pair to the BSDF as its direction."""

from __future__ import annotations

import numba
import numpy as np
import pytest

from lightprobe.bsdfs import Lambert
from lightprobe.integrators.techniques import BRDF, COSINE, MIS, SLOT_BSDF, SLOT_HEMI, sample_direction, technique_slot
from lightprobe.sampling.kernels import cosine_hemisphere_to_square
from lightprobe.sampling.rng import SAMPLERS, sample_state, uniform, uniform_2d

from ..conftest import is_net

WO = (0.3, -0.2, np.sqrt(1.0 - 0.13))


# The numbers are drawn inside small kernels: a state tuple that crosses into Python comes back typed by its values
# (int64 below 2^63, uint64 above), and a dispatcher may run it through a specialization compiled for other types,
# giving numbers that depend on which test compiled first (this file's render test failed when run alone).
@numba.njit
def _own_number(sampler, seed, pixel, sample, dim):
    return uniform(sample_state(sampler, seed, pixel, sample), dim)


@numba.njit
def _own_pair(sampler, seed, pixel, sample, dim):
    return uniform_2d(sample_state(sampler, seed, pixel, sample), dim)


@numba.njit
def _grouped_pair(sampler, seed, pixel, sample, strategy, n_bsdf, n_env, j):
    rj, slot = technique_slot(sample_state(sampler, seed, pixel, sample), strategy, n_bsdf, n_env, j)
    return uniform_2d(rj, 2 + 3 * slot)


def _slot_points(technique, n=256, slot=1, pixel=7):
    """The unit-square points behind n directions of one slot of one pixel, from the renderer's Sobol' sampler."""
    bsdf = Lambert(0.5)
    points = np.empty((n, 2))
    for i in range(n):
        u0, u1, u2 = (_own_number(SAMPLERS["sobol"], 3, pixel, i, 2 + 3 * slot + c) for c in range(3))
        state, wi, pdf, _ = sample_direction(technique, bsdf.kind, bsdf.params, WO, u0, u1, u2)
        assert state == (SLOT_BSDF if technique == BRDF else SLOT_HEMI) and pdf > 0.0
        points[i] = cosine_hemisphere_to_square(*wi)
    return points


def test_bsdf_directions_come_from_the_slots_2d_pair():
    # cosine-hemisphere sampling inverts exactly, so a Lambertian's sampled directions map back to the numbers
    # that made them; from a (0, 2)-sequence pair those form a (0, 8, 2)-net.  A lobe choice taken from the pair
    # (the layout before issue 9's fix) mixes two pairs and breaks it.
    assert is_net(_slot_points(BRDF))
    assert is_net(_slot_points(COSINE))


def test_the_net_check_can_fail():
    rng = np.random.default_rng(1)
    assert not is_net(rng.random((256, 2)))
    mixed = _slot_points(BRDF)
    mixed[:, 1] = _slot_points(BRDF, slot=2)[:, 1]  # coordinates of two different pairs
    assert not is_net(mixed)


def _group_points(n_bsdf, n_env, group, camera_samples, pixel=7, sampler="sobol"):
    """The 2D numbers behind every slot of one technique (``group``: "bsdf" or "env") in camera samples
    0 .. camera_samples - 1 of one pixel, in sample order, as the renderer's shading setup takes them."""
    slots = range(n_bsdf) if group == "bsdf" else range(n_bsdf, n_bsdf + n_env)
    points = []
    for i in range(camera_samples):
        for j in slots:
            points.append(_grouped_pair(SAMPLERS[sampler], 3, pixel, i, MIS, n_bsdf, n_env, j))
    return np.array(points)


def test_slots_of_one_technique_share_one_stratified_set():
    # MIS with 2 (or 4) BSDF samples per camera sample: a pixel's 128 x 2 (64 x 4) BSDF directions are one
    # (0, 8, 2)-net, not two (four) smaller nets side by side; likewise 2 environment samples
    assert is_net(_group_points(2, 1, "bsdf", 128))
    assert is_net(_group_points(4, 1, "bsdf", 64))
    assert is_net(_group_points(2, 2, "env", 128))
    # one slot per group: the slot's own sequence, as before grouping
    single = _group_points(1, 1, "env", 256)
    assert np.array_equal(single, np.array([_own_pair(SAMPLERS["sobol"], 3, 7, i, 2 + 3 * 1) for i in range(256)]))


def test_slots_side_by_side_are_not_one_net():
    # negative control: each slot with its own pair (the layout before grouping) gives two 128-nets, which
    # together fail the 256-point check; the independent sampler keeps exactly that layout
    side_by_side = np.array([_own_pair(SAMPLERS["sobol"], 3, 7, i, 2 + 3 * j) for i in range(128) for j in range(2)])
    assert not is_net(side_by_side)
    independent = _group_points(2, 1, "bsdf", 4, sampler="independent")
    own = [_own_pair(SAMPLERS["independent"], 3, 7, i, 2 + 3 * j) for i in range(4) for j in range(2)]
    assert np.array_equal(independent, np.array(own))


@pytest.mark.parametrize("path", ["environment", "area lights"])
def test_the_renderer_takes_each_groups_numbers(path):
    # One pixel of a Lambertian ground (albedo 1) under an unoccluded sky, strategy "cosine" with 4 slots: each
    # slot contributes L(wi) (f cos / pdf = 1), so the pixel is the mean of L over the directions made from the
    # slots' numbers.  Recomputed here from technique_slot's numbers, it must match the render; with any other
    # layout (each slot its own pair, as before groups) the directions differ and so does the value.  A small
    # emitter under the ground, which no direction reaches, sends the render down the area-light path.
    from lightprobe.emitters.envmap import EnvironmentMap, env_eval
    from lightprobe.emitters.procedural import sky_with_sun
    from lightprobe.geometry.camera import Camera
    from lightprobe.geometry.frame import coordinate_system, to_world
    from lightprobe.geometry.shapes import Rectangle
    from lightprobe.integrators.techniques import STRATEGIES
    from lightprobe.integrators.wavefront import RenderSettings, render
    from lightprobe.sampling.kernels import square_to_cosine_hemisphere
    from lightprobe.scene import Scene

    env = EnvironmentMap.from_array(sky_with_sun(64, 32, sun_diameter_deg=20.0, sun_radiance=(8.0, 7.0, 6.0)))
    scene = Scene(Camera([0, 1.6, 4.5], [0, 0, 0], fov=1.0, resolution=(1, 1)), env)
    scene.add(Rectangle.ground(size=30), Lambert(1.0))
    if path == "area lights":
        scene.add(Rectangle([-0.1, -5, -0.1], [0.2, 0, 0], [0, 0, 0.2]), None, emission=1.0, name="hidden")
    spp, slots, seed = 16, 4, 9
    result = render(scene, RenderSettings(spp=spp, strategy="cosine", n_bsdf=slots, n_env=0, seed=seed))
    assert result.stats["area_lights"] == (1 if path == "area lights" else 0)
    image = result.image[0, 0]

    def expected(layout):
        ts, tt = coordinate_system(0.0, 1.0, 0.0)
        total = np.zeros(3)
        for i in range(spp):
            for j in range(slots):
                wi = square_to_cosine_hemisphere(*layout(i, j))
                total += env_eval(env.kernel, *to_world(ts, tt, (0.0, 1.0, 0.0), *wi))
        return total / (spp * slots)

    sobol = SAMPLERS["sobol"]
    grouped = expected(lambda i, j: _grouped_pair(sobol, seed, 0, i, STRATEGIES["cosine"], slots, 0, j))
    side_by_side = expected(lambda i, j: _own_pair(sobol, seed, 0, i, 2 + 3 * j))
    np.testing.assert_allclose(image, grouped, rtol=1e-5)
    assert not np.allclose(image, side_by_side, rtol=1e-3)


def test_a_camera_samples_light_picks_are_stratified():
    # the area-light path: K = 16 light slots per camera sample (MIS, 1 BSDF slot, one sample per light) pick with
    # the first number of their own 2D pair, which the group's stratification puts one in each sixteenth of [0, 1)
    # under sobol (the selector hands back what is left of it, so each light's samples keep the pair's net); under
    # independent, slot j's own pair.  With two samples per light the group's slots share the 1D number.
    from lightprobe.integrators.techniques import pick_number as _pick_number
    from lightprobe.integrators.techniques import pick_slot as _pick_slot

    k, n_bsdf = 16, 1

    @numba.njit
    def pick_number(sampler, sample, j, n_per_light):
        rs = sample_state(sampler, 3, 7, sample)
        rj, slot = technique_slot(rs, MIS, n_bsdf, k, j)
        u0, _ = uniform_2d(rj, 2 + 3 * slot)
        return _pick_number(rs, n_bsdf, n_per_light, n_bsdf + k, MIS, j, u0), u0

    @numba.njit
    def shared_number(sampler, sample, j, n_per_light):
        rp, picker = _pick_slot(sample_state(sampler, 3, 7, sample), n_bsdf, n_per_light, n_bsdf + k, MIS, j)
        return uniform(rp, 4 + 3 * picker)

    def picks(sampler, sample, n_per_light=1):
        return np.array([pick_number(SAMPLERS[sampler], sample, j, n_per_light) for j in range(n_bsdf, n_bsdf + k)])

    for sample in (0, 1, 5):
        chosen, u0 = picks("sobol", sample).T
        assert np.array_equal(chosen, u0)
        assert np.array_equal(np.sort((chosen * k).astype(int)), np.arange(k))
    chosen, u0 = picks("independent", 0).T
    own = [_own_pair(SAMPLERS["independent"], 3, 7, 0, 2 + 3 * j)[0] for j in range(n_bsdf, n_bsdf + k)]
    assert np.array_equal(chosen, own)
    assert not np.array_equal(np.sort((chosen * k).astype(int)), np.arange(k))
    for sampler in ("sobol", "independent"):
        chosen, u0 = picks(sampler, 3, n_per_light=2).T
        assert np.array_equal(chosen[0::2], chosen[1::2]) and not np.array_equal(chosen, u0)
        shared = [shared_number(SAMPLERS[sampler], 3, j, 2) for j in range(n_bsdf, n_bsdf + k)]
        assert np.array_equal(chosen, shared)
