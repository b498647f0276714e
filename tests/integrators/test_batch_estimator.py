"""The estimator at a batch of shading points (the laboratory's and the shading-point tables'): its terms against
the formula written out in NumPy, its shadow rays' origins, and the rows it must not ask about."""

from __future__ import annotations

import numpy as np
import pytest

from lightprobe.bsdfs import Phong
from lightprobe.emitters.envmap import EnvironmentMap
from lightprobe.emitters.procedural import sky_with_sun
from lightprobe.errors import ParameterError
from lightprobe.geometry.frame import frame_matrix
from lightprobe.integrators.batch_estimator import (
    Context,
    EnvironmentSampling,
    HemisphereSampling,
    MaterialSampling,
    add_samples,
    shade,
)
from lightprobe.integrators.shading_point import estimate
from lightprobe.sampling.mis import power_heuristic


@pytest.fixture(scope="module")
def point():
    env = EnvironmentMap.from_array(sky_with_sun(64, 32, sun_diameter_deg=8.0, sun_radiance=(20.0, 18.0, 15.0)))
    normal = np.array([0.3, 0.9, -0.2])
    normal /= np.linalg.norm(normal)
    frame = frame_matrix(normal)
    wo = frame @ (np.array([0.5, 0.7, 0.1]) / np.linalg.norm([0.5, 0.7, 0.1]))
    return env, Phong(0.4, 0.5, 25), frame, wo


def _power(n_f, p_f, n_g, p_g):
    return power_heuristic(p_f, p_g, n_f=n_f, n_g=n_g)


def test_the_terms_are_the_formula_written_out(point):
    """sum over techniques and samples of w f cos L V / (n p), with visibility from a wall, against NumPy."""
    env, bsdf, frame, wo = point
    n = 500
    ctx = Context.at_point(wo, frame, n, bsdf, env)
    techniques, counts = (MaterialSampling(), EnvironmentSampling()), (2, 3)
    rng = np.random.default_rng(4)
    numbers = [rng.random((c, n, t.dimensions)) for t, c in zip(techniques, counts, strict=True)]

    def blocked(d):
        return d[:, 0] > 0.25

    values, rays = shade(ctx, techniques, counts, _power, numbers, np.tile(frame[2], (n, 1)), np.zeros(n),
                         lambda origins, d: blocked(d))  # fmt: skip

    expected = np.zeros((n, 3))
    asked = 0
    for j, (tech, count) in enumerate(zip(techniques, counts, strict=True)):
        u = numbers[j].reshape(count * n, -1)
        every = ctx.subset(np.tile(np.arange(n), count))
        wi, pdf = tech.sample(u, every)
        local, world = (wi, wi @ frame) if tech.kind == "bsdf" else (wi @ frame.T, wi)
        other = techniques[1 - j]
        p_other = other.pdf(local if other.kind == "bsdf" else world, every)
        w = _power(count, pdf, counts[1 - j], p_other)
        f = bsdf.eval(every.wo, local)
        cos = np.maximum(local[:, 2], 0.0)
        live = (pdf > 0) & (cos > 0) & (w > 0) & np.any(f > 0, axis=1)
        d = world / np.linalg.norm(world, axis=1, keepdims=True)
        asked += int(live.sum())
        seen = live & ~blocked(d)
        term = np.zeros((count * n, 3))
        term[seen] = f[seen] * env.eval(d[seen]) * (w[seen] * cos[seen] / (count * pdf[seen]))[:, None]
        expected += term.reshape(count, n, 3).sum(axis=0)
    assert rays == asked and 0 < asked < 5 * n
    np.testing.assert_allclose(values, expected, rtol=1e-12, atol=1e-15)
    assert np.all(values >= 0) and values.max() > 0


def test_shadow_rays_leave_from_the_offset_point_on_the_directions_side(point):
    """Each live row's ray leaves from position + side * error * ng, side the sign of d . ng (as the core offsets)."""
    env, bsdf, frame, wo = point
    n = 64
    ctx = Context.at_point(wo, frame, n, bsdf, env)
    ctx.position = np.tile([10.0, -2.0, 3.0], (n, 1))
    ng = np.tile(frame[2], (n, 1))
    error = np.linspace(0.1, 0.7, n)
    wi = HemisphereSampling(cosine=True).sample(np.random.default_rng(1).random((n, 2)), ctx)[0]
    wi[::2, 2] *= -1.0  # below the shading normal: cos 0, no ray
    world = wi @ frame
    seen = {}

    def occluded(origins, d):
        seen["origins"], seen["d"] = origins, d
        return np.zeros(len(d), dtype=bool)

    out = np.zeros((n, 3))
    rays = add_samples(out, ctx, 1, wi, world, np.full(n, 0.3), np.ones(n), ng, error, occluded)
    assert rays == n // 2 == len(seen["d"])
    rows = np.arange(1, n, 2)
    side = np.sign(np.einsum("nk,nk->n", seen["d"], ng[rows]))
    np.testing.assert_allclose(seen["origins"], ctx.position[rows] + (side * error[rows])[:, None] * ng[rows])
    assert np.all(out[::2] == 0) and np.all(out[1::2].sum(axis=1) > 0)


def test_rows_without_weight_or_density_ask_no_ray(point):
    env, bsdf, frame, wo = point
    n = 8
    ctx = Context.at_point(wo, frame, n, bsdf, env)
    wi = np.tile([0.0, 0.6, 0.8], (n, 1))
    pdf, weight = np.full(n, 0.5), np.ones(n)
    pdf[:3] = 0.0
    weight[3:5] = 0.0
    calls = []

    def occluded(origins, d):
        calls.append(len(d))
        return np.ones(len(d), dtype=bool)  # everything blocked

    out = np.zeros((n, 3))
    assert add_samples(out, ctx, 1, wi, wi @ frame, pdf, weight, np.tile(frame[2], (n, 1)), np.zeros(n), occluded) == 3
    assert calls == [3] and np.all(out == 0)


def test_the_shading_point_tables_go_through_the_batch_estimator(point, monkeypatch):
    """estimate() is shade() with n copies of the point: replacing the shared terms changes its answer."""
    import lightprobe.integrators.batch_estimator as be

    env, bsdf, frame, wo = point
    before = estimate(env, bsdf, strategy="mis", n=2000, normal=frame[2], wo=frame.T @ wo, seed=2).mean
    calls = []
    real = be.add_samples

    def counted(out, *args):  # each technique's terms counted twice
        calls.append(out.shape[0])
        kept = out.copy()
        rays = real(out, *args)
        out[:] = kept + 2.0 * (out - kept)
        return rays

    monkeypatch.setattr(be, "add_samples", counted)
    after = estimate(env, bsdf, strategy="mis", n=2000, normal=frame[2], wo=frame.T @ wo, seed=2).mean
    assert calls == [2000, 2000]
    np.testing.assert_allclose(after, 2.0 * before, rtol=1e-12)


def test_the_chosen_lobe_estimator_is_refused_for_brdf_sampling(point):
    env = point[0]
    with pytest.raises(ParameterError, match="chosen_lobe"):
        estimate(env, Phong(0.4, 0.5, 25, estimator="chosen_lobe"), strategy="brdf")


def test_a_visibility_of_the_wrong_shape_is_one_clear_error(point):
    env, bsdf = point[0], point[1]
    with pytest.raises(ParameterError, match=r"visibility\(dirs\) must return one value per direction"):
        estimate(env, bsdf, strategy="cosine", n=100, visibility=lambda d: np.ones((len(d), 3)))
    half = estimate(env, bsdf, strategy="cosine", n=4000, visibility=lambda d: (d[:, 0] < 0)[:, None])
    assert np.all(half.mean < estimate(env, bsdf, strategy="cosine", n=4000).mean)
