"""Every warp: chi-square against its own pdf, pdf integrates to 1, round trip, and negative controls."""

from __future__ import annotations

import numpy as np
import pytest

from lightprobe.analysis import chi2
from lightprobe.sampling import warps

N = 1_000_000

# (name, sample, pdf, invert, theta of the support's edge, if any: it becomes a cell edge)
SPHERICAL = [
    (
        "uniform_sphere",
        warps.square_to_uniform_sphere,
        warps.uniform_sphere_pdf,
        warps.uniform_sphere_to_square,
        None,
    ),
    (
        "uniform_hemisphere",
        warps.square_to_uniform_hemisphere,
        warps.uniform_hemisphere_pdf,
        warps.uniform_hemisphere_to_square,
        np.pi / 2,
    ),
    (
        "cosine_hemisphere",
        warps.square_to_cosine_hemisphere,
        warps.cosine_hemisphere_pdf,
        warps.cosine_hemisphere_to_square,
        np.pi / 2,
    ),
]
for _n in (0.0, 1.0, 10.0, 100.0, 1e3, 1e4):
    SPHERICAL.append(
        (
            f"phong_lobe n={_n:g}",
            lambda u, n=_n: warps.square_to_phong_lobe(u, n),
            lambda v, n=_n: warps.phong_lobe_pdf(v, n),
            lambda v, n=_n: warps.phong_lobe_to_square(v, n),
            np.pi / 2,
        )
    )
for _c in (-0.5, 0.0, 0.9, np.cos(np.radians(0.25))):
    SPHERICAL.append(
        (
            f"uniform_cone cos_max={_c:.6g}",
            lambda u, c=_c: warps.square_to_uniform_cone(u, c),
            lambda v, c=_c: warps.uniform_cone_pdf(v, c),
            lambda v, c=_c: warps.uniform_cone_to_square(v, c),
            float(np.arccos(_c)),
        )
    )
IDS = [s[0] for s in SPHERICAL]


def _edges(case):
    _, _, pdf, _, support_edge = case
    edges = chi2.equal_mass_theta_edges(pdf, 64)
    if support_edge is not None:
        edges = np.unique(np.concatenate([edges, [support_edge]]))
    return edges


@pytest.mark.parametrize("case", SPHERICAL, ids=IDS)
def test_chi2(case):
    _, sample, pdf, _, _ = case
    u = np.random.default_rng(7).random((N, 2))
    result = chi2.spherical_test(sample(u), pdf, theta_edges=_edges(case), test_count=len(SPHERICAL))
    assert result.passed, str(result)


@pytest.mark.parametrize("case", SPHERICAL, ids=IDS)
def test_pdf_integrates_to_one(case):
    pdf = case[2]
    total = chi2.spherical_expected(pdf, _edges(case), np.linspace(0, 2 * np.pi, 65), order=6).sum()
    assert total == pytest.approx(1.0, abs=2e-6)


@pytest.mark.parametrize("case", SPHERICAL, ids=IDS)
def test_round_trip_and_unit_length(case):
    _, sample, pdf, invert, _ = case
    u = np.random.default_rng(3).random((100_000, 2)) * 0.998 + 0.001
    v = sample(u)
    np.testing.assert_allclose(np.linalg.norm(v, axis=1), 1.0, atol=1e-12)
    assert np.all(pdf(v) > 0)
    np.testing.assert_allclose(invert(v), u, atol=1e-7)


def test_triangle_chi2_and_round_trip():
    u = np.random.default_rng(5).random((N, 2))
    b = warps.square_to_uniform_triangle(u)
    np.testing.assert_allclose(b.sum(axis=1), 1.0, atol=1e-12)
    assert np.all(b >= 0)
    np.testing.assert_allclose(warps.uniform_triangle_pdf(b), 2.0)
    # histogram over (b1, b2) in the unit square: cells inside the triangle expect 2 x area; the diagonal
    # cells are split exactly in half; cells beyond it expect nothing.
    k = 64
    counts, _, _ = np.histogram2d(b[:, 1], b[:, 2], bins=k, range=[[0, 1], [0, 1]])
    i, j = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    area = np.where(i + j < k - 1, 1.0, np.where(i + j == k - 1, 0.5, 0.0)) / k**2
    result = chi2.goodness_of_fit(counts, N * 2.0 * area)
    assert result.passed, str(result)
    np.testing.assert_allclose(warps.uniform_triangle_to_square(b[:1000]), u[:1000], atol=1e-9)


def test_cosine_is_the_seed_formula():
    """phi = 2 pi xi1, cos(theta) = sqrt(xi2) (Krivanek eqs. 6-10)."""
    u = np.array([[0.25, 0.36]])
    np.testing.assert_allclose(warps.square_to_cosine_hemisphere(u), [[0.0, 0.8, 0.6]], atol=1e-15)


def test_phong_lobe_is_the_seed_formula():
    """cos(theta) = xi2^(1/(n+1)) (Krivanek eq. 13), pdf (n+1)/(2 pi) cos^n."""
    v = warps.square_to_phong_lobe(np.array([[0.0, 0.5]]), 9.0)
    assert v[0, 2] == pytest.approx(0.5**0.1, rel=1e-14)
    assert warps.phong_lobe_pdf(v, 9.0)[0] == pytest.approx(10 / (2 * np.pi) * 0.5**0.9, rel=1e-12)


@pytest.mark.parametrize(
    "wrong_pdf",
    [
        lambda v: warps.phong_lobe_pdf(v, 105.0),  # samples with n = 100
        lambda v: warps.phong_lobe_pdf(v, 95.0),
    ],
    ids=["exponent+5%", "exponent-5%"],
)
def test_chi2_detects_a_wrong_exponent(wrong_pdf):
    """A test must be able to fail: a 5% error in the Phong exponent is caught."""
    u = np.random.default_rng(7).random((N, 2))
    result = chi2.spherical_test(
        warps.square_to_phong_lobe(u, 100.0),
        wrong_pdf,
        theta_edges=chi2.equal_mass_theta_edges(wrong_pdf, 64),
    )
    assert not result.passed


def test_chi2_detects_the_cosine_sampler_against_the_uniform_pdf():
    u = np.random.default_rng(8).random((N, 2))
    result = chi2.spherical_test(warps.square_to_cosine_hemisphere(u), warps.uniform_hemisphere_pdf)
    assert not result.passed


def test_chi2_detects_samples_outside_the_support():
    u = np.random.default_rng(8).random((N, 2))
    # coarse cells: each cell below the horizon holds samples but no mass, and the quadrature searches every such
    # cell six levels deep for a sliver of support (on the default 64 x 128 cells that took half a minute)
    theta, phi = np.arccos(np.linspace(1.0, -1.0, 17)), np.linspace(0.0, 2.0 * np.pi, 33)
    result = chi2.spherical_test(
        warps.square_to_uniform_sphere(u), warps.uniform_hemisphere_pdf, theta_edges=theta, phi_edges=phi
    )
    assert not result.passed
    assert "integrates to 0" in result.message or result.p_value < 1e-6


def test_bad_arguments():
    with pytest.raises(ValueError, match="exponent"):
        warps.square_to_phong_lobe(np.zeros((1, 2)), -1)
    with pytest.raises(ValueError, match="cos_max"):
        warps.square_to_uniform_cone(np.zeros((1, 2)), 1.0)
    with pytest.raises(ValueError, match=r"\(N, 2\)"):
        warps.square_to_uniform_sphere(np.zeros((3, 3)))


def test_sincos_turns_is_sin_and_cos_of_a_full_turn_within_2e_16():
    """The warps' azimuths: (sin 2 pi t, cos 2 pi t) against long-double references, on random turns, every
    1/4096 of a turn (octant and quadrant boundaries included) and turns outside [0, 1)."""
    import numba

    from lightprobe.sampling.kernels import sincos_turns

    if np.finfo(np.longdouble).eps > 1e-18:
        pytest.skip("the references need an extended-precision long double")

    @numba.njit
    def evaluate(t):
        out = np.empty((t.size, 2))
        for i in range(t.size):
            out[i, 0], out[i, 1] = sincos_turns(t[i])
        return out

    rng = np.random.default_rng(12)
    t = np.concatenate([rng.random(100_000), np.arange(4097) / 4096, [-0.3, -0.125, 1.7, 2.625, 1.0 - 2.0**-53]])
    pi = np.longdouble("3.14159265358979323846264338327950288")
    angle = 2 * pi * t.astype(np.longdouble)
    out = evaluate(t)
    assert np.abs(out[:, 0] - np.sin(angle)).max() <= 2e-16
    assert np.abs(out[:, 1] - np.cos(angle)).max() <= 2e-16
    quarter = np.arange(8) / 4  # exact at the quarter turns, signs included
    exact = evaluate(quarter)
    assert np.array_equal(exact[:, 0], [0, 1, 0, -1, 0, 1, 0, -1])
    assert np.array_equal(exact[:, 1], [1, 0, -1, 0, 1, 0, -1, 0])
