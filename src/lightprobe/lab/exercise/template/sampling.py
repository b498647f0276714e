"""The Krivanek exercise: the sampling of an image-based lighting renderer, written by you.

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

from lightprobe.lab import direction_to_uv, uv_to_direction  # noqa: F401 (step 4 uses them)


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
        # TODO step 1: return wi (N, 3) and its pdf (N,)
        raise NotImplementedError("step 1: UniformHemisphere.sample")

    def pdf(self, wi, ctx):
        # TODO step 1: 1 / (2 pi) above the surface, 0 below it
        raise NotImplementedError("step 1: UniformHemisphere.pdf")


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
        # TODO step 2
        raise NotImplementedError("step 2: CosineHemisphere.sample")

    def pdf(self, wi, ctx):
        # TODO step 2: max(cos theta, 0) / pi
        raise NotImplementedError("step 2: CosineHemisphere.pdf")


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
        # TODO step 3 (frame_around(mirror) gives the lobe's frame)
        raise NotImplementedError("step 3: PhongLobes.sample")

    def pdf(self, wi, ctx):
        # TODO step 3: the mixture pdf
        raise NotImplementedError("step 3: PhongLobes.pdf")


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
        # TODO step 4: the marginal and conditional CDFs (np.cumsum), kept on self
        self.environment = environment

    def sample(self, u, ctx):
        # TODO step 4
        raise NotImplementedError("step 4: EnvironmentMapSampler.sample")

    def pdf(self, wi, ctx):
        # TODO step 4
        raise NotImplementedError("step 4: EnvironmentMapSampler.pdf")


# --- step 5 ---------------------------------------------------------------------------------------------------------
def balance_heuristic(n_f, p_f, n_g, p_g):
    """Veach's balance heuristic (Krivanek eq. 17): the MIS weight of a sample of technique f, which draws n_f
    samples, against technique g (n_g samples): n_f p_f / (n_f p_f + n_g p_g), and 0 where both pdfs are 0.
    p_f and p_g are arrays (N,)."""
    # TODO step 5
    raise NotImplementedError("step 5: balance_heuristic")


# step 6 is a render: `lightprobe exercise check .` renders scene.toml with PhongLobes and EnvironmentMapSampler
# under MIS weighted by your balance_heuristic, and z-tests it against lightprobe's own image.
