"""A self-contained HTML report of a comparison: one file, every image embedded as a PNG data URI.

Sections: the images side by side (reference first) with one zoom and one crop for all (drag or click to move the
crop, the wheel or the slider to zoom), false-colour relative error maps on one shared scale, log-log convergence
plots (MSE against samples per pixel and against seconds, with the 1/N slope of Monte Carlo), the metrics table
with each strategy's efficiency relative to the best, and the exact command and settings to reproduce the report.
The page reports its own state in ``<body data-...>`` (images decoded, script errors), which the tests read back
from headless Chromium.
"""

from __future__ import annotations

import base64
import html
import io
import json
import math
import os
from pathlib import Path

import numpy as np

from ..images import linear_to_srgb

__all__ = ["write_gallery", "write_report"]


def _png(rgb8: np.ndarray) -> str:
    import matplotlib.image

    buf = io.BytesIO()
    matplotlib.image.imsave(buf, rgb8, format="png")
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _tonemapped(image: np.ndarray, exposure: float) -> str:
    data = np.where(np.isfinite(image), image, 0.0)[:, :, :3] * 2.0**exposure
    return _png(np.round(linear_to_srgb(np.clip(data, 0.0, None)) * 255).astype(np.uint8))


def _error_map(image: np.ndarray, reference: np.ndarray, vmax: float) -> str:
    import matplotlib

    rel = np.abs(image[:, :, :3] - reference[:, :, :3]).mean(axis=2) / (np.abs(reference[:, :, :3]).mean(axis=2) + 0.01)
    colours = matplotlib.colormaps["magma"](np.clip(rel / vmax, 0.0, 1.0))
    return _png(np.round(colours[:, :, :3] * 255).astype(np.uint8))


def _figure_uri(fig) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _log_ticks(axis, lo: float, hi: float) -> None:
    """Labelled ticks of a log axis over [lo, hi] that never overlap: plain numbers at 1, 2, 5 x 10^k (every decade
    over wide ranges, finer steps over narrow ones), no labels on minor ticks.  Matplotlib's default labels minor ticks
    (2x10^-2, 3x10^-2, ...) whenever the range spans less than about 1.5 decades, and those collided."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    decades = math.log10(hi / lo) if hi > lo > 0 else 0.0
    # the widest gap between ticks (in decades) stays under the range, so that at least two are labelled, and the
    # narrowest stays wide enough on a 5.6-inch figure for labels such as "0.006"
    if decades > 2.5:
        subs = (1.0,)
    elif decades > 0.8:
        subs = (1.0, 2.0, 5.0)
    elif decades > 0.5:
        subs = (1.0, 2.0, 3.0, 5.0)
    else:
        subs = (1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0)
    axis.set_major_locator(LogLocator(base=10.0, subs=subs, numticks=24))
    axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    axis.set_minor_locator(LogLocator(base=10.0, subs=tuple(float(k) for k in range(2, 10)), numticks=24))
    axis.set_minor_formatter(NullFormatter())


def _pyplot():
    """matplotlib.pyplot on the file-only Agg backend (reports are written on machines without a display)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _convergence_figure(runs, axis: str, xlabel: str):
    """MSE against ``axis`` (spp or seconds) of every run's rounds, log-log, with the 1/N slope."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(5.6, 4.0))
    for r in runs:
        xs = [row[axis] for row in r.rounds]
        ys = [max(row["mse"], 1e-30) for row in r.rounds]
        ax.loglog(xs, ys, "o-", ms=3, label=r.label)
    first = max(runs, key=lambda r: r.metrics["efficiency"]).rounds
    if len(first) > 1:  # the Monte Carlo slope through the best strategy's first point
        x0, y0 = first[0][axis], first[0]["mse"]
        x1 = first[-1][axis]
        ax.loglog([x0, x1], [y0, y0 * x0 / x1], "k--", lw=1, label="1/N")
    lo, hi = ax.get_xlim()
    _log_ticks(ax.xaxis, lo, hi)
    ax.set_xlim(lo, hi)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("MSE against the reference")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def _convergence_plots(runs) -> tuple[str, str]:
    plt = _pyplot()
    uris = []
    for axis, xlabel in (("spp", "samples per pixel"), ("seconds", "seconds")):
        fig = _convergence_figure(runs, axis, xlabel)
        uris.append(_figure_uri(fig))
        plt.close(fig)
    return uris[0], uris[1]


_STYLE = """
body { font: 14px/1.4 system-ui, sans-serif; margin: 24px; color: #222; background: #fafafa; }
h1 { font-size: 22px; } h2 { font-size: 17px; margin-top: 28px; }
.grid { display: flex; flex-wrap: wrap; gap: 12px; }
figure { margin: 0; } figcaption { font-size: 12px; text-align: center; }
.frame { overflow: hidden; border: 1px solid #bbb; background: #000; cursor: crosshair; position: relative; }
.frame img { display: block; image-rendering: pixelated; transform-origin: 0 0; }
.marker { position: absolute; border: 1px solid #0f0; pointer-events: none; }
canvas.crop { border: 1px solid #bbb; image-rendering: pixelated; background: #000; }
table { border-collapse: collapse; } td, th { border: 1px solid #ccc; padding: 3px 8px; text-align: right; }
th { background: #eee; } td:first-child, th:first-child { text-align: left; }
pre { background: #eee; padding: 8px; overflow-x: auto; }
.best { font-weight: bold; }
.bound { font-style: italic; }
"""

_SCRIPT = """
(function () {
  const state = { zoom: 1, cx: 0.5, cy: 0.5 };
  document.body.dataset.errors = "";
  window.addEventListener("error", (e) => { document.body.dataset.errors += (e.message || "error") + ";"; });
  const frames = Array.from(document.querySelectorAll(".frame"));
  const crops = Array.from(document.querySelectorAll("canvas.crop"));
  const slider = document.getElementById("zoom");
  function apply() {
    for (const frame of frames) {
      const img = frame.querySelector("img");
      const w = frame.clientWidth, h = frame.clientHeight;
      const x = Math.min(Math.max(state.cx * w * state.zoom - w / 2, 0), w * (state.zoom - 1));
      const y = Math.min(Math.max(state.cy * h * state.zoom - h / 2, 0), h * (state.zoom - 1));
      img.style.transform = "translate(" + (-x) + "px," + (-y) + "px) scale(" + state.zoom + ")";
      const marker = frame.querySelector(".marker");
      const size = 0.125;
      marker.style.left = ((state.cx - size / 2) * w * state.zoom - x) + "px";
      marker.style.top = ((state.cy - size / 2) * h * state.zoom - y) + "px";
      marker.style.width = (size * w * state.zoom) + "px";
      marker.style.height = (size * h * state.zoom) + "px";
    }
    for (const canvas of crops) {
      const img = document.getElementById(canvas.dataset.source);
      const ctx = canvas.getContext("2d");
      ctx.imageSmoothingEnabled = false;
      const sw = Math.max(1, Math.round(img.naturalWidth * 0.125));
      const sh = Math.max(1, Math.round(img.naturalHeight * 0.125));
      const sx = Math.min(Math.max(Math.round(state.cx * img.naturalWidth - sw / 2), 0), img.naturalWidth - sw);
      const sy = Math.min(Math.max(Math.round(state.cy * img.naturalHeight - sh / 2), 0), img.naturalHeight - sh);
      ctx.clearRect(0, 0, canvas.width, canvas.height);
      ctx.drawImage(img, sx, sy, sw, sh, 0, 0, canvas.width, canvas.height);
    }
    slider.value = state.zoom;
  }
  function point(frame, event) {
    const rect = frame.getBoundingClientRect();
    const img = frame.querySelector("img");
    const w = frame.clientWidth, h = frame.clientHeight;
    const x = Math.min(Math.max(state.cx * w * state.zoom - w / 2, 0), w * (state.zoom - 1));
    const y = Math.min(Math.max(state.cy * h * state.zoom - h / 2, 0), h * (state.zoom - 1));
    state.cx = Math.min(Math.max((event.clientX - rect.left + x) / (w * state.zoom), 0), 1);
    state.cy = Math.min(Math.max((event.clientY - rect.top + y) / (h * state.zoom), 0), 1);
    apply();
  }
  for (const frame of frames) {
    let dragging = false;
    frame.addEventListener("mousedown", (e) => { dragging = true; point(frame, e); e.preventDefault(); });
    frame.addEventListener("mousemove", (e) => { if (dragging) point(frame, e); });
    window.addEventListener("mouseup", () => { dragging = false; });
    frame.addEventListener("wheel", (e) => {
      state.zoom = Math.min(Math.max(state.zoom * (e.deltaY < 0 ? 1.25 : 0.8), 1), 32);
      apply();
      e.preventDefault();
    }, { passive: false });
  }
  slider.addEventListener("input", () => { state.zoom = Number(slider.value); apply(); });
  document.getElementById("reset").addEventListener("click", () => {
    state.zoom = 1; state.cx = 0.5; state.cy = 0.5; apply();
  });
  window.addEventListener("load", () => {
    const images = Array.from(document.images);
    const decoded = images.filter((i) => i.complete && i.naturalWidth > 0);
    apply();
    document.body.dataset.images = String(images.length);
    document.body.dataset.decoded = String(decoded.length);
    document.body.dataset.ready = "1";
  });
})();
"""


def _fmt(x, spec: str) -> str:
    return format(x, spec) if isinstance(x, int | float) and np.isfinite(x) else str(x)


def write_report(
    path: str | os.PathLike,
    *,
    title: str,
    runs,
    reference: np.ndarray,
    command: str,
    settings: dict,
    notes: str = "",
    exposure: float = 0.0,
    light_choice=None,
) -> Path:
    """Write the report of ``runs`` (:class:`~lightprobe.experiments.compare.StrategyRun`) to ``path``;
    ``light_choice``: a :class:`~lightprobe.experiments.light_choice.LightChoice` for its section (the oracle and
    the split of the variance), or None."""
    p = Path(path)
    width = reference.shape[1]
    shown = max(160, min(360, width))
    views = [("reference", reference)] + [(r.label, r.image) for r in runs]
    rel = [
        np.abs(r.image[:, :, :3] - reference[:, :, :3]).mean(axis=2) / (np.abs(reference[:, :, :3]).mean(axis=2) + 0.01)
        for r in runs
    ]
    vmax = float(max(np.percentile(e, 99) for e in rel)) or 1.0
    parts = [
        "<!doctype html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>{html.escape(title)}</title><style>{_STYLE}</style></head><body>",
        f"<h1>{html.escape(title)}</h1>",
        f"<p>{html.escape(notes)}</p>" if notes else "",
        "<h2>Images</h2>",
        '<p>zoom <input type="range" id="zoom" min="1" max="32" step="0.25" value="1"> '
        '<button id="reset">reset</button> &mdash; drag or click on any image to move the crop (green box), '
        "the mouse wheel zooms all images together.</p>",
        '<div class="grid">',
    ]
    for i, (label, image) in enumerate(views):
        parts.append(
            f'<figure><div class="frame" style="width:{shown}px"><img id="view{i}" width="{shown}" '
            f'src="{_tonemapped(image, exposure)}" alt="{html.escape(label)}"><div class="marker"></div></div>'
            f"<figcaption>{html.escape(label)}</figcaption></figure>"
        )
    parts.append("</div><h2>Crops</h2><div class='grid'>")
    crop_w = min(240, shown)
    crop_h = max(1, round(crop_w * reference.shape[0] / reference.shape[1]))  # the crop keeps the image's aspect
    for i, (label, _) in enumerate(views):
        parts.append(
            f'<figure><canvas class="crop" width="{crop_w}" height="{crop_h}" '
            f'data-source="view{i}"></canvas><figcaption>{html.escape(label)}</figcaption></figure>'
        )
    parts.append(f"</div><h2>Relative error |x - ref| / (ref + 0.01), 0 to {vmax:.3g} (magma)</h2><div class='grid'>")
    for r, _ in zip(runs, rel, strict=True):
        parts.append(
            f'<figure><img width="{shown}" src="{_error_map(r.image, reference, vmax)}" '
            f'alt="error {html.escape(r.label)}"><figcaption>{html.escape(r.label)}</figcaption></figure>'
        )
    by_spp, by_time = _convergence_plots(runs)
    parts += [
        "</div><h2>Convergence</h2><div class='grid'>",
        f'<img src="{by_spp}" alt="MSE against samples per pixel">',
        f'<img src="{by_time}" alt="MSE against seconds">',
        "</div><h2>Metrics</h2><table><tr><th>strategy</th><th>spp</th><th>seconds</th><th>MSE</th><th>relMSE</th>"
        "<th>PSNR dB</th><th>FLIP</th><th>bias (95 % interval)</th><th>efficiency 1/(MSE s)</th>"
        "<th>relative to the best</th></tr>",
    ]
    for r in sorted(runs, key=lambda r: -r.metrics["efficiency"]):
        m = r.metrics
        best = ' class="best"' if m["relative_efficiency"] == 1.0 else ""
        parts.append(
            f"<tr{best}><td>{html.escape(r.label)}</td><td>{_fmt(r.spp, '.1f')}</td><td>{_fmt(r.seconds, '.2f')}</td>"
            f"<td>{_fmt(m['mse'], '.3g')}</td><td>{_fmt(m['relmse'], '.3g')}</td><td>{_fmt(m['psnr'], '.1f')}</td>"
            f"<td>{_fmt(m['flip'], '.3f')}</td><td>{_fmt(m['bias'], '.2g')} ({_fmt(m['bias_low'], '.2g')}, "
            f"{_fmt(m['bias_high'], '.2g')})</td><td>{_fmt(m['efficiency'], '.3g')}</td>"
            f"<td>{_fmt(m['relative_efficiency'], '.2f')}</td></tr>"
        )
    objects = sorted({name for r in runs for name in r.metrics.get("objects", {})})
    if objects:
        parts.append(
            "</table><h2>MSE per object (pixel centres that see it)</h2><table><tr><th>strategy</th>"
            + "".join(f"<th>{html.escape(o)}</th>" for o in objects)
            + "</tr>"
        )
        for r in runs:
            cells = "".join(
                f"<td>{_fmt(r.metrics['objects'][o]['mse'], '.3g') if o in r.metrics['objects'] else '-'}</td>"
                for o in objects
            )
            parts.append(f"<tr><td>{html.escape(r.label)}</td>{cells}</tr>")
    parts.append("</table>")
    if light_choice is not None:
        parts += _light_choice_section(light_choice)
    parts += [
        "<h2>Reproduce</h2>",
        f"<pre>{html.escape(command)}</pre>",
        f"<pre>{html.escape(json.dumps(settings, indent=2, default=str))}</pre>",
        f"<script>{_SCRIPT}</script>",
        "</body></html>",
    ]
    tmp = p.with_name(f".{p.name}.partial-{os.getpid()}")
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        tmp.write_text("\n".join(parts), encoding="utf-8")
        os.replace(tmp, p)
    finally:
        tmp.unlink(missing_ok=True)
    return p


def _share(x: float, total: float) -> str:
    if not (np.isfinite(x) and np.isfinite(total)) or total <= 0.0:
        return _fmt(x, ".3g")
    return f"{_fmt(x, '.3g')} ({100.0 * x / total:.0f} %)"


def _light_choice_section(choice) -> list[str]:
    """The report's "Light choice" section: the selectors against the oracle, and each strategy's variance split."""
    parts = ['<h2 id="light-choice">Light choice</h2>']
    if choice.skipped:
        return [*parts, f"<p>Not measured: {html.escape(choice.skipped)}.</p>"]
    left_out = f" ({choice.textured} pixels with textured materials left out)" if choice.textured else ""
    parts += [
        f"<p>At {choice.points} shading points of the camera's first hits{left_out}, each of the {choice.lights} "
        f"lights estimated by brute force ({choice.per_light} samples each with its shadow ray, "
        f"{choice.bsdf_samples} BSDF "
        f"samples a point; {choice.seconds:.1f} s). {100.0 * choice.arriving:.1f} % of the light the lights would "
        "give the points without shadows reaches them. Figures are shares of a one-sample relMSE (variance / "
        "(mean<sup>2</sup> + 0.01), averaged over the image; independent samples).</p>",
        "<h3>Selectors against the oracle (light sampling alone)</h3>",
        "<p>The <b>oracle</b> picks each light in proportion to what it gives the point, shadows included: "
        "the choice of light adds nothing. The <b>unoccluded oracle</b> does the same ignoring shadows: the best a "
        "selector blind to visibility can do. The <b>variance-optimal</b> choice (in proportion to the RMS of what a "
        "light gives) has the least light-sample variance of all. The best selector a render can use is in bold; "
        "the three bounds in italics.</p>",
        '<table class="light-choice-selectors"><tr><th>selector</th><th>variance the choice of light adds</th>'
        "<th>light-sample variance</th><th>&times; the oracle's</th></tr>",
    ]
    bounds = ("unoccluded oracle", "oracle", "variance-optimal")  # not selectors a render can use: references
    best = min((r.vs_oracle for r in choice.selectors if r.name not in bounds), default=None)
    for r in choice.selectors:
        mark = ' class="best"' if r.vs_oracle == best else ' class="bound"' if r.name in bounds else ""
        parts.append(
            f"<tr{mark}><td>{html.escape(r.name)}</td><td>{_fmt(r.choice, '.3g')}</td><td>{_fmt(r.total, '.3g')}</td>"
            f"<td>{_fmt(r.vs_oracle, '.2f')}</td></tr>"
        )
    parts += [
        "</table><h3>Where each strategy's variance comes from</h3>",
        "<p>One camera sample's variance, split by the law of total variance: which light is picked, which point of "
        "it, visibility (what the shadows' unevenness over a light adds), the BSDF sample, and where in the pixel the "
        "sample lands (edges and emitters seen directly, without the outline control variate). <i>Measured</i> is "
        "the same quantity from the strategy's own samples, for comparison (it also counts the rare bright samples "
        "the points may miss).</p>",
        '<table class="light-choice-split"><tr><th>strategy</th><th>selector</th><th>choice of light</th>'
        "<th>point on the light</th><th>visibility</th><th>BSDF sample</th><th>pixel</th><th>total</th>"
        "<th>measured</th></tr>",
    ]
    for sp in choice.splits:
        total = sp.total
        cells = "".join(f"<td>{_share(x, total)}</td>" for x in (sp.choice, sp.point, sp.visibility, sp.bsdf, sp.pixel))
        measured = choice.measured.get(sp.label, float("nan"))
        pilot = "*" if sp.selector == "learned" and sp.label in choice.measured else ""
        parts.append(
            f"<tr><td>{html.escape(sp.label)}</td><td>{html.escape(sp.selector)}</td>{cells}"
            f"<td>{_fmt(total, '.3g')}</td><td>{_fmt(measured, '.3g')}{pilot}</td></tr>"
        )
    parts.append("</table>")
    if any(sp.selector == "learned" for sp in choice.splits):
        parts.append(
            "<p>* A learned selection's render picks as the BVH for its first 4 samples, which it learns from: its "
            "measured spread pools those with the learned ones; the split is the learned selection's alone.</p>"
        )
    for label, why in choice.unsplit.items():
        parts.append(f"<p>{html.escape(label)}: not split ({html.escape(why)}).</p>")
    return parts


def write_gallery(
    path: str | os.PathLike, *, title: str, rows: list[dict], images: list[Path], notes: str = ""
) -> Path:
    """A self-contained page of PNG images (embedded) under a table of ``rows`` (dicts with the same keys), for
    experiments that write their images themselves (the lecture's)."""
    p = Path(path)
    keys = list(rows[0]) if rows else []
    parts = [
        "<!doctype html>",
        f'<html lang="en"><head><meta charset="utf-8"><title>{html.escape(title)}</title><style>{_STYLE}</style>',
        f"</head><body><h1>{html.escape(title)}</h1>",
        f"<p>{html.escape(notes)}</p>" if notes else "",
        "<table><tr>" + "".join(f"<th>{html.escape(k)}</th>" for k in keys) + "</tr>",
    ]
    for row in rows:
        cells = "".join(f"<td>{html.escape(_fmt(row[k], '.4g'))}</td>" for k in keys)
        parts.append(f"<tr>{cells}</tr>")
    parts.append("</table><div class='grid'>")
    for image in images:
        uri = "data:image/png;base64," + base64.b64encode(Path(image).read_bytes()).decode("ascii")
        parts.append(
            f'<figure><img width="320" src="{uri}" alt="{html.escape(image.stem)}">'
            f"<figcaption>{html.escape(image.stem)}</figcaption></figure>"
        )
    parts.append("</div></body></html>")
    p.write_text("\n".join(parts), encoding="utf-8")
    return p
