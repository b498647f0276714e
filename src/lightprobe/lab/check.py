"""``lightprobe check``: the project's own verification of a sampler, applied to a user's technique.

For each test context (a BSDF technique: a material seen from two directions; a light technique: a small map with
a bright patch), in this order, each check stopping the rest of its context when it fails:

1. **runs**: ``sample`` and ``pdf`` return arrays of the right shape and dtype, finite, pdf >= 0, unit directions
   (:class:`~lightprobe.lab.techniques.GuardedTechnique`);
2. **below the surface** (BSDF techniques declared ``support = "hemisphere"``): no sample below the surface with a
   non-zero pdf, and ``pdf`` is 0 there;
3. **sample pdf = pdf()**: the pdf ``sample`` returns equals ``pdf(wi)`` to 1e-3 (relative);
4. **integrates to 1**: the pdf's integral over the sphere (adaptive Gauss-Legendre quadrature on the chi-square
   cells) within 1 % of 1, with a hint when the factor is a familiar mistake (a missing sin theta of the lat-long
   Jacobian, a missing 1/pi, the BRDF's normalisation in a Phong lobe's pdf);
5. **chi-square**: the samples' histogram against the pdf's integral over each cell (``analysis/chi2.py``, cells of
   equal mass about the mirror direction for BSDF techniques, texel-aligned for light techniques), Sidak-corrected
   significance 0.01 over the contexts.

:func:`figure_png` draws observed and expected histograms side by side; :func:`write_html` puts the verdict, the
numbers and that picture in one self-contained page.
"""

from __future__ import annotations

import base64
import html
import io
import math
from dataclasses import dataclass, field

import numpy as np

from ..analysis import chi2
from ..errors import LightprobeError
from .techniques import Context, GuardedTechnique, TechniqueError

__all__ = ["CheckItem", "CheckReport", "check_technique", "default_environment", "default_material"]

PDF_TOLERANCE = 1e-3
INTEGRAL_TOLERANCE = 1e-2
#: the local wo of a BSDF technique's contexts: 30 and 65 degrees from the normal
WO_ANGLES = (30.0, 65.0)


@dataclass
class CheckItem:
    """One check in one context: its name, verdict, one-line message and numbers."""

    context: str
    name: str
    passed: bool
    message: str
    numbers: dict = field(default_factory=dict)


@dataclass
class Histogram:
    """Observed and expected counts of one context over (theta, phi) cells."""

    context: str
    observed: np.ndarray
    expected: np.ndarray
    axis: str


@dataclass
class CheckReport:
    label: str
    kind: str
    samples: int
    items: list[CheckItem] = field(default_factory=list)
    histograms: list[Histogram] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return bool(self.items) and all(i.passed for i in self.items)

    @property
    def first_failure(self) -> CheckItem | None:
        return next((i for i in self.items if not i.passed), None)

    def text(self) -> str:
        lines = [f"{self.label} ({self.kind} technique, {self.samples:,} samples per context)"]
        for i in self.items:
            lines.append(f"  {'ok  ' if i.passed else 'FAIL'} {i.context}: {i.name}: {i.message}")
        failure = self.first_failure
        verdict = "passed" if self.passed else f"FAILED ({failure.name}, {failure.context})"
        lines.append(f"verdict: {verdict}")
        return "\n".join(lines)

    def as_dict(self) -> dict:
        return {
            "technique": self.label,
            "kind": self.kind,
            "samples": self.samples,
            "passed": self.passed,
            "checks": [vars(i) for i in self.items],
        }


def default_material():
    """The material of a BSDF technique's contexts: the Krivanek exercise's modified Phong."""
    from ..bsdfs.phong import Phong

    return Phong(rho_d=0.3, rho_s=0.6, exponent=20.0, estimator="mixture")


def default_environment():
    """The map of a light technique's contexts: 64 x 32 texels, a sky gradient and a 12-degree sun of radiance 50."""
    from ..emitters.envmap import EnvironmentMap
    from ..emitters.procedural import sky_with_sun

    image = sky_with_sun(64, 32, sun_diameter_deg=12.0, sun_radiance=(50.0, 48.0, 45.0), supersampling=4)
    return EnvironmentMap.from_array(image, source="check map (64x32 sky with a 12-degree sun)", pdf="exact")


def _contexts(tech: GuardedTechnique):
    """(name, wo) of the contexts; the wo is local (BSDF) or a fixed viewer (light: unused by the map)."""
    if tech.kind == "bsdf":
        return [
            (f"wo {a:g} deg from the normal", (math.sin(math.radians(a)), 0.0, math.cos(math.radians(a))))
            for a in WO_ANGLES
        ]
    return [("environment", (0.0, 0.0, 1.0))]


def check_technique(
    tech: GuardedTechnique,
    *,
    samples: int = 200_000,
    seed: int = 0,
    material=None,
    environment=None,
    alpha: float = 0.01,
) -> CheckReport:
    """Run every check of the module docstring on ``tech``; a failure is an item of the report, never raised."""
    if samples < 1000:
        raise LightprobeError(f"samples must be >= 1000 for a chi-square test, got {samples}")
    material = material if material is not None else default_material()
    environment = environment if environment is not None else default_environment()
    report = CheckReport(tech.label, tech.kind, samples)
    contexts = _contexts(tech)
    rng = np.random.default_rng(seed)
    for name, wo in contexts:
        u = rng.random((samples, tech.dimensions))
        try:
            _check_context(report, tech, name, wo, u, material, environment, alpha, len(contexts))
        except TechniqueError as exc:
            report.items.append(CheckItem(name, "runs", False, str(exc)))
    return report


def _check_context(report, tech, name, wo, u, material, environment, alpha, test_count) -> None:
    n = u.shape[0]

    def ctx(count: int) -> Context:
        return Context.local(wo, count, material, environment)

    def density(v: np.ndarray) -> np.ndarray:
        return tech.pdf(np.ascontiguousarray(v), ctx(v.shape[0]))

    def add(check: str, passed: bool, message: str, **numbers) -> bool:
        report.items.append(CheckItem(name, check, passed, message, numbers))
        return passed

    wi, pdf = tech.sample(u, ctx(n))
    valid = pdf > 0
    add("runs", True, f"sample and pdf return finite values, pdf >= 0, unit directions ({int(valid.sum()):,} of "
        f"{n:,} samples with pdf > 0)", accepted=int(valid.sum()))  # fmt: skip
    if not valid.any():
        add("sample pdf = pdf()", False, "every sample has pdf 0: the technique produced nothing")
        return

    if tech.kind == "bsdf" and tech.support == "hemisphere":
        below = valid & (wi[:, 2] <= 0.0)
        probe = _lower_hemisphere(4096)
        p_below = density(probe)
        if below.any():
            i = int(np.argmax(below))
            return add(
                "below the surface", False,
                f"sample {i} is below the surface (wi = {_vec(wi[i])}, z = {wi[i, 2]:.4g}) with pdf {pdf[i]:.4g} "
                f"> 0 ({int(below.sum()):,} of {n:,} samples): a hemisphere technique must keep z > 0 (flip or "
                "reject), or declare support = 'sphere' if its lobe really dips below the surface",
                fraction=float(below.mean()),
            )  # fmt: skip
        if np.any(p_below > 0):
            i = int(np.argmax(p_below > 0))
            return add(
                "below the surface", False,
                f"pdf({_vec(probe[i])}) = {p_below[i]:.4g} > 0 below the surface: a hemisphere technique's pdf is "
                "0 where z <= 0",
            )  # fmt: skip
        add("below the surface", True, "no sample below the surface, pdf 0 there")

    p_again = density(wi[valid])
    ps = pdf[valid]
    rel = np.abs(ps - p_again) / np.maximum(np.maximum(ps, p_again), 1e-300)
    worst = float(rel.max())
    if worst > PDF_TOLERANCE:
        first = int(np.argmax(rel > PDF_TOLERANCE))  # the first offending sample
        i = int(np.nonzero(valid)[0][first])
        bad = int(np.sum(rel > PDF_TOLERANCE))
        return add(
            "sample pdf = pdf()", False,
            f"sample {i}: sample() says pdf {ps[first]:.6g}, pdf(wi) says {p_again[first]:.6g} (u = {_vec(u[i])}, "
            f"wi = {_vec(wi[i])}; {bad:,} of {int(valid.sum()):,} samples differ by more than {PDF_TOLERANCE:g}): "
            "pdf() must return the density sample() draws from (the same lobes, the same mixture)",
            max_relative_difference=worst,
        )  # fmt: skip
    add("sample pdf = pdf()", True, f"equal to {worst:.1e} (relative) at every sample",
        max_relative_difference=worst)  # fmt: skip

    frame, theta, phi, kwargs = _cells(tech, density, wo, environment)
    counts = chi2.spherical_counts(wi[valid], theta, phi, frame=frame)
    expected = valid.sum() * chi2.spherical_expected(
        density, theta, phi, frame=frame, atol=0.01 / n, refine=counts > 0, **kwargs
    )
    integral = float(expected.sum() / valid.sum())
    report.histograms.append(Histogram(name, counts, expected, "mirror direction" if tech.kind == "bsdf" else "+Y"))
    if not abs(integral - 1.0) <= INTEGRAL_TOLERANCE:
        hint = _integral_hint(integral, tech, density, frame, theta, phi, material, environment)
        return add("integrates to 1", False, f"the pdf integrates to {integral:.4g}, not 1{hint}", integral=integral)
    add("integrates to 1", True, f"the pdf integrates to {integral:.5f}", integral=integral)

    result = chi2.goodness_of_fit(counts, expected, alpha=alpha, test_count=test_count)
    numbers = {"statistic": result.statistic, "dof": result.dof, "p_value": result.p_value, "alpha": result.alpha}
    add(
        "chi-square",
        result.passed,
        f"statistic {result.statistic:.1f}, dof {result.dof}, p = {result.p_value:.3g} (alpha {result.alpha:.2g}): "
        + ("the samples follow the pdf" if result.passed else f"the samples do not follow the pdf; {result.message}"),
        **numbers,
    )


def _vec(a) -> str:
    return "(" + ", ".join(f"{x:.4g}" for x in np.asarray(a).reshape(-1)) + ")"


def _lower_hemisphere(n: int) -> np.ndarray:
    from ..sampling import warps

    u = np.random.default_rng(12345).random((n, 2))
    d = warps.square_to_uniform_hemisphere(u)
    d[:, 2] = -np.maximum(d[:, 2], 1e-6)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _cells(tech, density, wo, environment):
    """(frame, theta edges, phi edges, quadrature options) of the chi-square cells."""
    if tech.kind == "light":
        h, w = environment.luminance.shape
        theta = chi2.texel_edges(h, h * max(1, 32 // h), np.pi)
        phi = chi2.texel_edges(w, w * max(1, 64 // w), 2.0 * np.pi)
        frame = chi2.ENV_TO_LATLONG_ANGLES @ environment.to_world.T
        return frame, theta, phi, {"order": 4, "max_depth": 4}
    from ..geometry.frame import frame_matrix

    mirror = np.array([-wo[0], -wo[1], wo[2]])
    frame = frame_matrix(mirror)
    try:
        theta = chi2.equal_mass_theta_edges(density, 48, frame=frame)
    except ValueError:  # the pdf integrates to zero: uniform rings, and the integral check says so
        theta = np.arccos(np.linspace(1.0, -1.0, 65))
    return frame, theta, np.linspace(0.0, 2.0 * np.pi, 97), {"order": 4, "max_depth": 6}


_FACTORS = [
    (math.pi, "pi: a missing 1/pi?"),
    (1.0 / math.pi, "1/pi: a 1/pi too many?"),
    (2.0 * math.pi, "2 pi: a missing 1/(2 pi)?"),
    (1.0 / (2.0 * math.pi), "1/(2 pi): a 1/(2 pi) too many?"),
    (4.0 * math.pi, "4 pi: a missing 1/(4 pi)?"),
    (2.0, "2: the pdf counts the sphere where the samples cover a hemisphere, or a factor 2?"),
    (0.5, "1/2: the pdf of a hemisphere where samples cover the sphere, or a factor 2?"),
]


def _integral_hint(integral, tech, density, frame, theta, phi, material, environment) -> str:
    """A guess at the mistake behind a pdf that does not integrate to 1, or ''."""
    near = [text for factor, text in _FACTORS if abs(integral / factor - 1.0) < 0.02]
    if tech.kind == "light":
        rotation = environment.to_world

        def sin_theta(v):
            return np.sqrt(np.maximum(1.0 - (v @ rotation)[:, 1] ** 2, 1e-12))

        corrections = [
            (lambda v: density(v) / sin_theta(v), "the pdf is missing the sin theta of the lat-long Jacobian "
             "(p(w) = p(u, v) / (2 pi^2 sin theta))"),
            (lambda v: density(v) / sin_theta(v) ** 2, "the pdf multiplies by sin theta where the lat-long Jacobian "
             "divides (p(w) = p(u, v) / (2 pi^2 sin theta))"),
            (lambda v: density(v) / (2.0 * math.pi**2), "the pdf is missing the 1 / (2 pi^2) of the lat-long "
             "Jacobian (p(w) = p(u, v) / (2 pi^2 sin theta))"),
        ]  # fmt: skip
        for corrected, text in corrections:
            value = float(chi2.spherical_expected(corrected, theta, phi, frame=frame, order=4, max_depth=3).sum())
            if abs(value - 1.0) < 0.02:
                return f": {text}"
    exponent = getattr(material, "exponent", None)
    if tech.kind == "bsdf" and exponent is not None:
        # a Phong lobe whose pdf carries the BRDF's (n + 2) / (2 pi): the lobe integrates to (n + 2) / (n + 1), a
        # mixture of it with a right diffuse lobe to something between 1 and that
        top = (exponent + 2.0) / (exponent + 1.0)
        if 1.0 + INTEGRAL_TOLERANCE < integral <= top + 0.005:
            return (
                f": between 1 and (n + 2) / (n + 1) = {top:.4g} for exponent n = {exponent:g}, as when the "
                "specular lobe's pdf uses the BRDF's normalisation (n + 2) / (2 pi) instead of (n + 1) / (2 pi) "
                "(Krivanek eq. 12)"
            )
    return f": off by a factor {near[0]}" if near else ""


# --- pictures -----------------------------------------------------------------------------------------------------
def figure_png(report: CheckReport) -> bytes:
    """Observed, expected and (observed - expected) / sqrt(expected) per context, as PNG bytes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    rows = max(1, len(report.histograms))
    fig, axes = plt.subplots(rows, 3, figsize=(11, 2.9 * rows), squeeze=False)
    for r, h in enumerate(report.histograms):
        top = max(float(h.observed.max()), float(h.expected.max()), 1.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.where(h.expected > 0, (h.observed - h.expected) / np.sqrt(h.expected), 0.0)
        panels = [(h.observed, "observed", "viridis", 0.0, top), (h.expected, "expected", "viridis", 0.0, top),
                  (z, "(obs - exp) / sqrt(exp)", "RdBu_r", -4.0, 4.0)]  # fmt: skip
        positive = h.expected[h.expected > 0]
        wide = positive.size and top / max(float(positive.min()), 1e-300) > 100.0  # a sun: counts on a log scale
        for c, (data, title, cmap, lo, hi) in enumerate(panels):
            ax = axes[r, c]
            if c < 2 and wide:
                norm = LogNorm(vmin=max(0.5, float(positive.min())), vmax=top)
                image = ax.imshow(
                    np.maximum(data, norm.vmin), aspect="auto", cmap=cmap, norm=norm, interpolation="nearest"
                )
                title += " (log)"
            else:
                image = ax.imshow(data, aspect="auto", cmap=cmap, vmin=lo, vmax=hi, interpolation="nearest")
            ax.set_title(f"{h.context}: {title}", fontsize=8)
            ax.set_xlabel("phi cell", fontsize=7)
            ax.set_ylabel(f"theta cell (from the {h.axis})", fontsize=7)
            ax.tick_params(labelsize=6)
            fig.colorbar(image, ax=ax, fraction=0.046, pad=0.02).ax.tick_params(labelsize=6)
    if not report.histograms:
        axes[0, 0].text(0.5, 0.5, "no histogram: the technique failed before the chi-square test", ha="center")
        for ax in axes[0]:
            ax.set_axis_off()
    fig.suptitle(f"{report.label}: {'passed' if report.passed else 'FAILED'}", fontsize=10)
    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110)
    plt.close(fig)
    return buffer.getvalue()


def write_html(report: CheckReport, path, picture: bytes | None = None) -> None:
    """A self-contained page: the verdict, one table row per check, the histograms (``picture``, the PNG of
    :func:`figure_png`, drawn here when not given)."""
    png = base64.b64encode(picture if picture is not None else figure_png(report)).decode("ascii")
    rows = "".join(
        f"<tr class='{'ok' if i.passed else 'fail'}'><td>{html.escape(i.context)}</td><td>{html.escape(i.name)}</td>"
        f"<td>{'ok' if i.passed else 'FAIL'}</td><td>{html.escape(i.message)}</td></tr>"
        for i in report.items
    )
    verdict = "passed" if report.passed else "FAILED"
    page = (
        "<!doctype html><html><head><meta charset='utf-8'>"
        f"<title>lightprobe check: {html.escape(report.label)}</title><style>"
        "body{font-family:sans-serif;margin:2em;max-width:1200px}table{border-collapse:collapse}"
        "td,th{border:1px solid #ccc;padding:4px 8px;text-align:left;vertical-align:top;font-size:14px}"
        "tr.fail td{background:#fdd}tr.ok td:nth-child(3){color:#070}img{max-width:100%}</style></head><body>"
        f"<h1>{html.escape(report.label)}: <span id='verdict'>{verdict}</span></h1>"
        f"<p>{html.escape(report.kind)} technique, {report.samples:,} samples per context.</p>"
        f"<table><tr><th>context</th><th>check</th><th>verdict</th><th>numbers</th></tr>{rows}</table>"
        f"<h2>Observed against expected</h2><img alt='histograms' src='data:image/png;base64,{png}'>"
        "</body></html>"
    )
    with open(path, "w", encoding="utf-8") as f:
        f.write(page)
