"""The Krivanek exercise solved: lightprobe's reference solutions (the tests drop them into a fresh exercise).

Fill in every function marked TODO, in order; after each step run

    lightprobe exercise check .

which checks each technique against its own pdf (chi-square, the pdf integrating to 1, sample()'s pdf equal to
pdf()), tests your balance heuristic, and finally renders scene.toml with your techniques under MIS and compares
the image with lightprobe's own, pixel by pixel. It stops at the first step that is wrong and says how.

Conventions (lightprobe's; see README.md): a BSDF technique works in the local shading frame, the normal on +z, wo
toward the viewer; a light technique returns world directions (Y up). Every pdf is per unit solid angle. Arrays in,
arrays out: ``u`` is (N, dimensions) in [0, 1), ``wi`` (N, 3) unit vectors, pdfs (N,).
"""

import numpy as np

from lightprobe.lab import direction_to_uv, uv_to_direction


def frame_around(axis: np.ndarray):
    """Two unit vectors s, t (each (N, 3)) that make (s, t, axis) a right-handed orthonormal frame, for unit axes
    (N, 3) (Duff et al. 2017). A direction (x, y, z) in that frame is x s + y t + z axis. (Given: not a step.)"""
    sign = np.where(axis[:, 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + axis[:, 2])
    b = axis[:, 0] * axis[:, 1] * a
    s = np.stack([1.0 + sign * axis[:, 0] ** 2 * a, sign * b, -sign * axis[:, 0]], axis=1)
    t = np.stack([b, sign + axis[:, 1] ** 2 * a, -axis[:, 1]], axis=1)
    return s, t


# --- step 1 ---------------------------------------------------------------------------------------------------------
class UniformHemisphere:
    """Directions uniform over the hemisphere about the normal (+z): pdf = 1 / (2 pi).

    With u1, u2 uniform: cos(theta) = u1, phi = 2 pi u2; wi = (sin theta cos phi, sin theta sin phi, cos theta).
    """

    kind = "bsdf"
    dimensions = 2
    support = "hemisphere"

    def sample(self, u, ctx):
        z = u[:, 0]
        r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
        phi = 2.0 * np.pi * u[:, 1]
        wi = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
        return wi, np.where(z > 0.0, 1.0 / (2.0 * np.pi), 0.0)

    def pdf(self, wi, ctx):
        return np.where(wi[:, 2] > 0.0, 1.0 / (2.0 * np.pi), 0.0)


# --- step 2 ---------------------------------------------------------------------------------------------------------
class CosineHemisphere:
    """Directions with density cos(theta) / pi about the normal (Krivanek eq. 9).

    Malley's method: a point uniform on the unit disc (r = sqrt(u1), phi = 2 pi u2) lifted to the hemisphere,
    z = sqrt(1 - r^2).
    """

    kind = "bsdf"
    dimensions = 2
    support = "hemisphere"

    def sample(self, u, ctx):
        return _cosine(u[:, 0], u[:, 1])

    def pdf(self, wi, ctx):
        return np.maximum(wi[:, 2], 0.0) / np.pi


# --- step 3 ---------------------------------------------------------------------------------------------------------
class PhongLobes:
    """The modified Phong BRDF's two-lobe sampling (Krivanek eqs. 10-12 and 19).

    f(wo, wi) = rho_d / pi + rho_s (n + 2) / (2 pi) cos^n(alpha), alpha the angle between wi and the mirror
    direction of wo, (-wo.x, -wo.y, wo.z). The material is ``ctx.material`` (``rho_d``, ``rho_s`` RGB arrays,
    ``exponent`` n).

    Pick the diffuse lobe with probability P_d = mean(rho_d) / (mean(rho_d) + mean(rho_s)) using u[:, 2]; then
    - diffuse: cosine-weighted about the normal (step 2);
    - specular: about the mirror direction, cos(alpha) = u1^(1 / (n + 1)), phi = 2 pi u2, density
      (n + 1) / (2 pi) cos^n(alpha) per steradian (note: n + 1, not the BRDF's n + 2).
    The pdf of a direction is the mixture P_d cos(theta) / pi + (1 - P_d) (n + 1) / (2 pi) cos^n(alpha) -- whichever
    lobe produced it. The specular lobe can dip below the surface (support = "sphere"); such samples are valid, the
    renderer gives them the value 0.
    """

    kind = "bsdf"
    dimensions = 3
    support = "sphere"

    def sample(self, u, ctx):
        p_d = _diffuse_probability(ctx.material)
        n = ctx.material.exponent
        diffuse = u[:, 2] < p_d
        wi, _ = _cosine(u[:, 0], u[:, 1])
        mirror = _mirror(ctx.wo)
        s, t = frame_around(mirror)
        cos_a = u[:, 0] ** (1.0 / (n + 1.0))
        sin_a = np.sqrt(np.maximum(0.0, 1.0 - cos_a * cos_a))
        phi = 2.0 * np.pi * u[:, 1]
        lobe = (sin_a * np.cos(phi))[:, None] * s + (sin_a * np.sin(phi))[:, None] * t + cos_a[:, None] * mirror
        wi = np.where(diffuse[:, None], wi, lobe)
        wi /= np.linalg.norm(wi, axis=1, keepdims=True)
        return wi, self.pdf(wi, ctx)

    def pdf(self, wi, ctx):
        p_d = _diffuse_probability(ctx.material)
        n = ctx.material.exponent
        cos_a = np.maximum(np.einsum("nk,nk->n", wi, _mirror(ctx.wo)), 0.0)
        return p_d * np.maximum(wi[:, 2], 0.0) / np.pi + (1.0 - p_d) * (n + 1.0) / (2.0 * np.pi) * cos_a**n


# --- step 4 ---------------------------------------------------------------------------------------------------------
class EnvironmentMapSampler:
    """The environment map as a 2D piecewise-constant distribution (Krivanek section 4, pbrt's InfiniteAreaLightIS).

    ``prepare(environment)`` is called once per map: ``environment.luminance`` is (H, W), row 0 the zenith; texel
    (j, i) covers u in [i / W, (i + 1) / W), v in [j / H, (j + 1) / H). Weight each texel by its luminance times
    sin(theta) of its row (theta = pi v), so that texels near the poles, which cover less solid angle, are not
    over-sampled; build the marginal distribution over rows and the conditional one over the columns of each row.

    sample: pick a row from the marginal with u[:, 1], a column from that row's conditional with u[:, 0], a point
    uniform inside the texel; p(u, v) = W H weight(j, i) / sum(weights); the direction is
    uv_to_direction(environment, u, v), and its density per steradian is the lat-long Jacobian's
    p(w) = p(u, v) / (2 pi^2 sin theta).

    pdf: direction_to_uv(environment, wi) gives (u, v); the same formula.
    """

    kind = "light"
    dimensions = 2

    def prepare(self, environment):
        self.environment = environment
        lum = np.asarray(environment.luminance, dtype=np.float64)
        h, w = lum.shape
        weights = lum * np.sin(np.pi * (np.arange(h) + 0.5) / h)[:, None]
        self.shape = (h, w)
        self.density = weights * (w * h) / weights.sum()  # p(u, v) of each texel
        rows = weights.sum(axis=1)
        self.marginal = np.cumsum(rows) / rows.sum()
        self.conditional = np.cumsum(weights, axis=1) / np.maximum(rows, 1e-300)[:, None]

    def sample(self, u, ctx):
        h, w = self.shape
        j = np.minimum(np.searchsorted(self.marginal, u[:, 1], side="right"), h - 1)
        row_cdf = self.conditional[j]
        i = np.minimum((row_cdf <= u[:, 0][:, None]).sum(axis=1), w - 1)
        # a point uniform inside the texel: the numbers' remainders within the chosen cells
        lo_v = np.where(j > 0, self.marginal[np.maximum(j - 1, 0)], 0.0)
        dv = (u[:, 1] - lo_v) / np.maximum(self.marginal[j] - lo_v, 1e-300)
        lo_u = np.where(i > 0, row_cdf[np.arange(len(i)), np.maximum(i - 1, 0)], 0.0)
        du = (u[:, 0] - lo_u) / np.maximum(row_cdf[np.arange(len(i)), i] - lo_u, 1e-300)
        uu = (i + np.clip(du, 0.0, 1.0 - 1e-12)) / w
        vv = (j + np.clip(dv, 0.0, 1.0 - 1e-12)) / h
        wi = uv_to_direction(self.environment, uu, vv)
        return wi, self._pdf_uv(uu, vv)

    def pdf(self, wi, ctx):
        uu, vv = direction_to_uv(self.environment, wi)
        return self._pdf_uv(uu, vv)

    def _pdf_uv(self, uu, vv):
        h, w = self.shape
        i = np.minimum((uu * w).astype(int), w - 1)
        j = np.minimum((vv * h).astype(int), h - 1)
        sin_theta = np.sin(np.pi * vv)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(sin_theta > 0.0, self.density[j, i] / (2.0 * np.pi**2 * sin_theta), 0.0)


# --- step 5 ---------------------------------------------------------------------------------------------------------
def balance_heuristic(n_f, p_f, n_g, p_g):
    """Veach's balance heuristic (Krivanek eq. 17): the MIS weight of a sample of technique f, which draws n_f
    samples, against technique g (n_g samples): n_f p_f / (n_f p_f + n_g p_g), and 0 where both pdfs are 0.
    p_f and p_g are arrays (N,)."""
    a = n_f * np.asarray(p_f, dtype=np.float64)
    b = n_g * np.asarray(p_g, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(a + b > 0.0, a / (a + b), 0.0)


def _cosine(u1, u2):
    r = np.sqrt(u1)
    phi = 2.0 * np.pi * u2
    z = np.sqrt(np.maximum(0.0, 1.0 - u1))
    wi = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    return wi, z / np.pi


def _mirror(wo):
    return np.stack([-wo[:, 0], -wo[:, 1], wo[:, 2]], axis=1)


def _diffuse_probability(material):
    d, s = float(np.mean(material.rho_d)), float(np.mean(material.rho_s))
    return d / (d + s)


# step 6 is a render: `lightprobe exercise check .` renders scene.toml with PhongLobes and EnvironmentMapSampler
# under MIS weighted by your balance_heuristic, and z-tests it against lightprobe's own image.
