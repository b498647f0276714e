"""BSDFs: chi-square of sample() against pdf(), pdf normalisation, consistency, energy, reciprocity."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lightprobe.analysis import chi2
from lightprobe.bsdfs import GGXConductor, Lambert, MetallicRoughness, Phong, RoughPlastic
from lightprobe.bsdfs.conductor import CONDUCTOR_PRESETS
from lightprobe.bsdfs.fresnel import fresnel_conductor, fresnel_dielectric
from lightprobe.bsdfs.microfacet import ggx_d
from lightprobe.errors import ParameterError
from lightprobe.geometry.frame import frame_matrix

from ..conftest import is_net


def wo_at(theta_deg: float, phi: float = 0.3) -> np.ndarray:
    t = math.radians(theta_deg)
    return np.array([math.sin(t) * math.cos(phi), math.sin(t) * math.sin(phi), math.cos(t)])


ANGLES = (0.0, 30.0, 60.0, 85.0, 89.5)  # 85 and 89.5 degrees: grazing
MATERIALS = {
    "lambert": Lambert(0.7),
    **{f"phong n={n:g}": Phong(0.3, 0.6, n) for n in (1, 10, 100, 1000, 10000)},
    "phong specular-only n=50": Phong(0.0, 0.9, 50),
    **{f"ggx alpha={a:g}": GGXConductor(a) for a in (0.01, 0.05, 0.1, 0.3, 1.0)},
    "ggx no fresnel": GGXConductor(0.2, fresnel=False),
    **{f"plastic alpha={a:g}": RoughPlastic([0.6, 0.15, 0.1], a) for a in (0.02, 0.3, 1.0)},
    "gltf dielectric roughness=0.5": MetallicRoughness([0.8, 0.2, 0.1], 0.0, 0.5),
    "gltf metal roughness=0.1": MetallicRoughness([0.9, 0.6, 0.2], 1.0, 0.1),
    "gltf half metal roughness=0.8": MetallicRoughness(0.5, 0.5, 0.8),
}
CASES = [(m, a) for m in MATERIALS for a in ANGLES]


@pytest.mark.parametrize(("name", "angle"), CASES)
def test_chi2(name, angle):
    result = chi2.check_bsdf_sampling(MATERIALS[name], wo_at(angle), test_count=len(CASES))
    assert result.passed, str(result)
    assert result.pdf_integral == pytest.approx(1.0, abs=2e-4)


@pytest.mark.parametrize("name", list(MATERIALS))
def test_sample_pdf_equals_pdf_and_weight_equals_f_cos_over_pdf(name):
    bsdf = MATERIALS[name]
    for angle in ANGLES:
        wo = wo_at(angle)
        wi, pdf, weight = bsdf.sample_weight(wo, np.random.default_rng(1).random((20_000, 3)))
        ok = pdf > 0
        np.testing.assert_allclose(bsdf.pdf(wo, wi[ok]), pdf[ok], rtol=1e-9)
        expected = bsdf.eval(wo, wi[ok]) * np.maximum(wi[ok, 2:3], 0) / pdf[ok, None]
        np.testing.assert_allclose(weight[ok], expected, rtol=1e-7, atol=1e-12)
        assert np.all(np.isfinite(weight)) and np.all(weight >= 0)


@pytest.mark.parametrize("name", list(MATERIALS))
def test_reciprocity(name):
    bsdf = MATERIALS[name]
    rng = np.random.default_rng(2)
    a, b = rng.normal(size=(2, 1000, 3))
    a[:, 2], b[:, 2] = np.abs(a[:, 2]), np.abs(b[:, 2])
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    np.testing.assert_allclose(bsdf.eval(a, b), bsdf.eval(b, a), rtol=1e-9, atol=1e-12)


def test_one_sided():
    for bsdf in MATERIALS.values():
        below = np.array([[0.3, 0.0, -0.9]]) / np.linalg.norm([0.3, 0.0, -0.9])
        above = wo_at(20.0)[None]
        assert np.all(bsdf.eval(above, below) == 0) and np.all(bsdf.eval(below, above) == 0)
        assert bsdf.pdf(below, above)[0] == 0.0
        _, pdf, weight = bsdf.sample_weight(below[0], np.full((4, 3), 0.5))
        assert np.all(pdf == 0) and np.all(weight == 0)


def directional_albedo(bsdf, wo, n=400_000, seed=3):
    _, _, weight = bsdf.sample_weight(wo, np.random.default_rng(seed).random((n, 3)))
    return weight.mean(axis=0), weight.std(axis=0) / math.sqrt(n)


def test_lambert_albedo_is_exact():
    mean, err = directional_albedo(Lambert([0.2, 0.5, 0.9]), wo_at(40.0))
    np.testing.assert_allclose(mean, [0.2, 0.5, 0.9], rtol=1e-10)  # summation rounding only
    np.testing.assert_allclose(err, 0.0, atol=1e-14)


def test_phong_diffuse_albedo_and_energy():
    mean, _ = directional_albedo(Phong(0.6, 0.0, 10), wo_at(50.0))
    np.testing.assert_allclose(mean, 0.6, rtol=1e-10)
    # At normal incidence the specular lobe is centred on the normal and nothing is lost below the horizon:
    # albedo = (n+2)/(2 pi) * 2 pi * integral of c^(n+1) dc over [0, 1] = 1 exactly (the seed's normalisation).
    for n in (1, 10, 100):
        mean, err = directional_albedo(Phong(0.0, 1.0, n), wo_at(0.0))
        assert mean[0] == pytest.approx(1.0, abs=5 * err[0] + 1e-12)
    # at grazing incidence part of the lobe falls below the horizon: energy is lost, never created
    mean, err = directional_albedo(Phong(0.0, 1.0, 10), wo_at(80.0))
    assert mean[0] < 1.0 - 10 * err[0]


def test_phong_chosen_lobe_estimator_is_unbiased():
    """The seed's sec. 2.4 estimator has the same expectation as the mixture (but more variance)."""
    wo = wo_at(35.0)
    mix, err_mix = directional_albedo(Phong(0.4, 0.5, 30), wo)
    chosen, err_chosen = directional_albedo(Phong(0.4, 0.5, 30, estimator="chosen_lobe"), wo)
    z = np.abs(mix - chosen) / np.sqrt(err_mix**2 + err_chosen**2)
    assert np.all(z < 5), z


def test_ggx_distribution_is_normalised():
    """The projected area of the microfacets is the macro surface: integral of D(m) cos(theta_m) dm = 1."""
    for alpha in (0.01, 0.1, 0.5, 1.0):

        def projected(m, a=alpha):
            return np.array([ggx_d(a, *v) * v[2] for v in m])

        edges = chi2.equal_mass_theta_edges(projected, 32, n_fine=512, n_phi=4)
        total = chi2.spherical_expected(projected, edges, np.linspace(0, 2 * np.pi, 3), max_depth=2).sum()
        assert total == pytest.approx(1.0, abs=1e-4), alpha


def test_ggx_white_furnace_albedo():
    """A perfect GGX reflector (F = 1) loses energy only to masking (single scattering).

    At normal incidence with alpha = 1: D = 1/pi, G1(wo) = 1, G1(wi) = 2c/(1 + c) with c = cos(theta_i), so
    f = 1/(2 pi (1 + c)) and the albedo is 2 pi * integral of c f dc = integral of c/(1 + c) dc = 1 - ln 2.
    Smooth surfaces keep nearly everything.
    """
    mean, err = directional_albedo(GGXConductor(1.0, fresnel=False), wo_at(0.0))
    assert mean[0] == pytest.approx(1.0 - math.log(2.0), abs=5 * err[0])
    mean, err = directional_albedo(GGXConductor(0.01, fresnel=False), wo_at(30.0))
    assert 0.999 < mean[0] <= 1.0


def _textbook_g1(alpha, cos_v):
    """G1 = 2 / (1 + sqrt(1 + alpha^2 tan^2)) as microfacet.py's docstring writes it (1 at normal incidence)."""
    c2 = cos_v**2
    return 2 / (1 + np.sqrt(1 + alpha * alpha * (1 - c2) / c2))


def _textbook_d(alpha, cos_m):
    return alpha * alpha / (np.pi * (cos_m**2 * (alpha * alpha - 1) + 1) ** 2)


def _textbook_microfacet(alpha, wo, wi):
    """D(h) G1(wi, h) G1(wo, h) / (4 cos_i cos_o) and cos(wi, h) in the order the definitions give them
    (normalized h, tan^2, two divisions per G1), for directions above the surface."""
    h = wo + wi
    h /= np.linalg.norm(h, axis=1, keepdims=True)

    def g1(v):
        return np.where(np.sum(v * h, axis=1) * v[:, 2] > 0, _textbook_g1(alpha, v[:, 2]), 0.0)

    return _textbook_d(alpha, h[:, 2]) * g1(wi) * g1(wo) / (4 * wi[:, 2] * wo[:, 2]), np.sum(wi * h, axis=1)


@pytest.mark.parametrize("alpha", [1e-3, 0.05, 0.3, 1.0])
def test_ggx_values_match_the_textbook_order(alpha):
    """The kernels fold D, G1 and the cosines into one division (decisions.md 62); the values are the definitions'.
    (Away from the peak of a narrow lobe: there the textbook's 1 - cos^2 loses the digits the folded form keeps.)"""
    rng = np.random.default_rng(5)
    wo = rng.normal(size=(4000, 3))
    wi = rng.normal(size=(4000, 3))
    wo[:, 2], wi[:, 2] = np.abs(wo[:, 2]) + 1e-3, np.abs(wi[:, 2]) + 1e-3
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo[:3] = [[0.0, 0.0, 1.0], [1e-9, 0.0, 1.0], [0.6, 0.0, 0.8]]  # normal incidence, G1 = 1 exactly
    product, cos_h = _textbook_microfacet(alpha, wo, wi)
    conductor = GGXConductor(alpha, material="Au")
    eta, k = CONDUCTOR_PRESETS["Au"]
    fresnel = np.array([[fresnel_conductor(c, e, kk) for e, kk in zip(eta, k, strict=True)] for c in cos_h])
    for i in range(len(wo)):
        got = conductor.eval(wo[i], wi[i : i + 1])[0]
        np.testing.assert_allclose(got, fresnel[i] * product[i], rtol=1e-11, atol=1e-300)
        # the density of reflected directions, G1(wo, h) D(h) / (4 cos_o), wi over the whole sphere
        np.testing.assert_allclose(
            conductor.pdf(wo[i], wi[i : i + 1] * [1, 1, -1])[0],
            _reflection_pdf_textbook(alpha, wo[i], wi[i] * [1, 1, -1]),
            rtol=1e-11,
            atol=1e-300,
        )
    plastic = RoughPlastic([0.6, 0.15, 0.1], alpha)
    diffuse = np.outer(plastic.diffuse_factor(wi[:, 2]) * plastic.diffuse_factor(wo[:, 2]) / np.pi, plastic.diffuse)
    specular = product * np.array([fresnel_dielectric(c, plastic.eta) for c in cos_h])
    for i in range(len(wo)):
        got = plastic.eval(wo[i], wi[i : i + 1])[0]
        np.testing.assert_allclose(got, specular[i] + diffuse[i], rtol=1e-11)


def _reflection_pdf_textbook(alpha, wo, wi):
    h = wo + wi
    if h[2] <= 0 or np.dot(wo, h) <= 0:
        return 0.0
    h = h / np.linalg.norm(h)
    return _textbook_g1(alpha, wo[2]) * _textbook_d(alpha, h[2]) / (4 * wo[2])


def test_conductor_fresnel_at_normal_incidence_matches_the_peer_scene():
    """scene.json lists Mitsuba's normal-incidence reflectance of its Al and Au presets."""
    expected = {"Al": (0.928, 0.9178, 0.9189), "Au": (0.9667, 0.802, 0.3241)}
    for name, (eta, k) in CONDUCTOR_PRESETS.items():
        got = [fresnel_conductor(1.0, e, kk) for e, kk in zip(eta, k, strict=True)]
        np.testing.assert_allclose(got, expected[name], atol=6e-4)
        # ((eta - 1)^2 + k^2) / ((eta + 1)^2 + k^2) is the closed form at normal incidence
        closed = [((e - 1) ** 2 + kk**2) / ((e + 1) ** 2 + kk**2) for e, kk in zip(eta, k, strict=True)]
        np.testing.assert_allclose(got, closed, rtol=1e-12)
        assert fresnel_conductor(0.0, eta[0], k[0]) == pytest.approx(1.0)


def test_conductor_fresnel_matches_the_complex_formula():
    """The real-arithmetic form against the textbook complex one, at every angle."""
    for eta, k in ((1.6575, 9.2238), (0.143, 3.983), (1.5, 0.0), (0.2, 0.5)):
        n = complex(eta, k)
        for c in np.linspace(0.0, 1.0, 101):
            cos_t = np.sqrt(1 - (1 - c * c) / (n * n))
            r_parl = (n * c - cos_t) / (n * c + cos_t)
            r_perp = (c - n * cos_t) / (c + n * cos_t)
            assert fresnel_conductor(c, eta, k) == pytest.approx(0.5 * (abs(r_parl) ** 2 + abs(r_perp) ** 2), abs=1e-12)
    # a dielectric is a conductor with k = 0
    assert fresnel_conductor(0.7, 1.5, 0.0) == pytest.approx(fresnel_dielectric(0.7, 1.5), abs=1e-12)


def test_dielectric_fresnel():
    assert fresnel_dielectric(1.0, 1.5) == pytest.approx(0.04)
    assert fresnel_dielectric(0.0, 1.5) == pytest.approx(1.0)
    assert fresnel_dielectric(-0.2, 1.5) == 1.0  # total internal reflection from inside
    # Brewster's angle: the parallel component vanishes, F = r_perp^2 / 2
    c = math.cos(math.atan(1.5))
    s = math.sqrt(1 - c * c) / 1.5
    ct = math.sqrt(1 - s * s)
    assert fresnel_dielectric(c, 1.5) == pytest.approx(0.5 * ((c - 1.5 * ct) / (c + 1.5 * ct)) ** 2)


def test_chi2_sees_a_wrong_roughness():
    """A test must be able to fail: GGX samples at alpha 0.1 against the pdf of alpha 0.105."""
    wo = wo_at(30.0)
    u = np.random.default_rng(0).random((1_000_000, 3))
    wi, pdf = GGXConductor(0.1).sample(wo, u)
    wrong = GGXConductor(0.105)
    frame = frame_matrix(np.array([-wo[0], -wo[1], wo[2]]))
    edges = chi2.equal_mass_theta_edges(lambda v: wrong.pdf(wo, v), 64, frame=frame)
    result = chi2.spherical_test(wi[pdf > 0], lambda v: wrong.pdf(wo, v), frame=frame, theta_edges=edges)
    assert not result.passed


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: Lambert(1.5), "albedo"),
        (lambda: Lambert([0.1, 0.2]), "albedo"),
        (lambda: Phong(0.5, 0.5, -1), "exponent"),
        (lambda: Phong(0.0, 0.0, 10), "reflects nothing"),
        (lambda: Phong(0.5, 0.5, 10, estimator="best"), "estimator"),
        (lambda: GGXConductor(0.0), "alpha"),
        (lambda: GGXConductor(2.0), "alpha"),
        (lambda: GGXConductor(0.1, material="Unobtainium"), "material"),
        (lambda: GGXConductor(0.1, material="Al", eta=1.0), "either"),
        (lambda: GGXConductor(0.1, eta=[0.0, 1, 1], k=1), "eta"),
        (lambda: RoughPlastic(0.5, 0.3, eta=0.9), "eta"),
        (lambda: RoughPlastic(0.5, 0.0), "alpha"),
    ],
)
def test_bad_parameters(make, match):
    with pytest.raises(ParameterError, match=match):
        make()


def test_bad_array_shapes():
    with pytest.raises(ParameterError, match=r"\(N, 3\)"):
        Lambert(0.5).sample([0, 0, 1], np.zeros((4, 2)))
    with pytest.raises(ParameterError, match="wo"):
        Lambert(0.5).eval(np.zeros((2, 3)), np.zeros((3, 3)))


def test_plastic_diffuse_factor_matches_mitsuba():
    """scene.json tabulates g(mu) measured from Mitsuba 3.9.1's roughplastic (alpha 0.3, eta 1.4895874)."""
    import json
    from pathlib import Path

    spec = Path(__file__).resolve().parents[3] / "shared" / "peers" / "scene.json"
    if not spec.exists():
        pytest.skip("../shared/peers/scene.json is absent")
    material = json.loads(spec.read_text())["materials"]["red_rough_plastic"]
    table = np.array(material["g_table_mu_g"])
    plastic = RoughPlastic(material["diffuse_reflectance"], material["alpha"], eta=material["eta"])
    np.testing.assert_allclose(plastic.diffuse_factor(table[:, 0]), table[:, 1], rtol=5e-4)


def test_a_coatings_tables_are_made_once_and_each_plastic_has_its_own_copy():
    from lightprobe.bsdfs import plastic

    plastic._coating_tables.cache_clear()
    first, second = RoughPlastic(0.5, 0.3), RoughPlastic([0.1, 0.2, 0.3], 0.3)
    assert plastic._coating_tables.cache_info().hits == 1
    assert first.internal_reflectance == second.internal_reflectance
    np.testing.assert_array_equal(first.transmittance, second.transmittance)
    first.transmittance[:] = 0.0  # one material's table written over leaves the other's and the next one's
    assert np.all(second.transmittance > 0) and np.all(RoughPlastic(0.5, 0.3).transmittance > 0)


def test_plastic_energy():
    """Never more than the incident energy; the coat alone reflects about the 4 % Fresnel of eta 1.49.

    The model (Mitsuba's) is not energy conserving for a white base: masking inside the rough coat loses light,
    and at normal incidence the diffuse lobe is about 0.69 x a Lambertian of the same reflectance (scene.json).
    """
    for alpha in (0.05, 0.3, 1.0):
        mean, _ = directional_albedo(RoughPlastic(1.0, alpha), wo_at(0.0))
        assert 0.3 < mean[0] < 1.0  # alpha = 1 keeps only 34 %
    mean, _ = directional_albedo(RoughPlastic(0.0, 0.05), wo_at(0.0))
    assert 0.035 < mean[0] < 0.042


def _net_256():
    """The first 256 points of Sobol's 2D sequence, moved to the centres of their cells: a (0, 8, 2)-net whose
    points sit 1/512 from every cell edge (so a round trip's rounding keeps each in its cell)."""
    from lightprobe.sampling.rng import sobol_2d

    xy = np.array([sobol_2d(i) for i in range(256)], dtype=np.float64) / 2.0**32
    return xy + 1.0 / 512.0


def test_a_two_lobe_bsdf_gives_each_lobe_a_stratum_of_the_pair():
    # Phong with rho_d = rho_s picks each lobe with probability 1/2, by the pair's second number rescaled
    # (choose_rescaled): each lobe's 128 directions, mapped back through its own warp, are a (0, 7, 2)-net.  The
    # lobe choice is the first column, drawn anew here: a BSDF that used it (the choice before decisions.md 67)
    # would give each lobe a scattered half of the net and fail.
    from lightprobe.geometry.frame import coordinate_system, to_local
    from lightprobe.sampling.kernels import cosine_hemisphere_to_square, phong_lobe_to_square

    n_exp = 10.0
    bsdf = Phong(0.45, 0.45, n_exp)
    wo = wo_at(30.0)
    net = _net_256()
    u = np.column_stack([np.random.default_rng(5).random(256), net])
    wi, _ = bsdf.sample(wo, u)
    diffuse = net[:, 1] < 0.5
    mirror = (-wo[0], -wo[1], wo[2])
    s, t = coordinate_system(*mirror)
    back = np.array(
        [
            cosine_hemisphere_to_square(*w) if d else phong_lobe_to_square(*to_local(s, t, mirror, *w), n_exp)
            for w, d in zip(wi, diffuse, strict=True)
        ]
    )
    for lobe in (diffuse, ~diffuse):
        assert lobe.sum() == 128
        np.testing.assert_allclose(back[lobe, 0], net[lobe, 0], atol=1e-9)
        assert is_net(back[lobe])
    scattered = back[diffuse].copy()
    scattered[:, 1] = np.random.default_rng(6).random(128)
    assert not is_net(scattered)  # the check can fail


def test_the_plastic_chooses_its_lobe_by_the_pairs_second_number():
    from lightprobe.bsdfs.plastic import _specular_probability
    from lightprobe.sampling.kernels import cosine_hemisphere_to_square

    bsdf = RoughPlastic([0.6, 0.15, 0.1], 0.3)
    wo = wo_at(40.0)
    ps = _specular_probability(bsdf.params, (wo[0], wo[1], wo[2]))
    assert 0.05 < ps < 0.95
    net = _net_256()
    rng = np.random.default_rng(7)
    wi_a, pdf_a = bsdf.sample(wo, np.column_stack([rng.random(256), net]))
    wi_b, pdf_b = bsdf.sample(wo, np.column_stack([rng.random(256), net]))
    np.testing.assert_array_equal(wi_a, wi_b)  # the first column chooses nothing
    np.testing.assert_array_equal(pdf_a, pdf_b)
    diffuse = net[:, 1] >= ps
    back = np.array([cosine_hemisphere_to_square(*w) for w in wi_a[diffuse]])
    np.testing.assert_allclose(back[:, 0], net[diffuse, 0], atol=1e-9)
    np.testing.assert_allclose(back[:, 1], (net[diffuse, 1] - ps) / (1.0 - ps), atol=1e-9)
