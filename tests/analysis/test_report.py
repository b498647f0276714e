"""The HTML report, opened in headless Chromium: no script errors, every image decoded, a non-blank screenshot."""

from __future__ import annotations

import itertools
import re
import shutil
import subprocess

import numpy as np
import pytest

from lightprobe.cli import main
from lightprobe.images import read_image

CHROMIUM = next((shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome") if shutil.which(n)), None)


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    out = tmp_path_factory.mktemp("report") / "report.html"
    args = ["compare", "--demo", "--width", "48", "--spp", "4", "--reference-spp", "32", "-o", str(out), "-q"]
    assert main([*args, "--strategies", "env,brdf,mis-balance,mis-power/sampler=independent"]) == 0
    return out


def test_the_report_is_one_self_contained_file(report):
    text = report.read_text()
    assert text.startswith("<!doctype html>") and "</html>" in text
    assert not re.search(r'src="(?!data:)', text)  # no external image, script or style
    assert text.count('src="data:image/png;base64,') == 5 + 4 + 2  # views, error maps, two plots
    for label in ("env", "brdf", "mis-balance", "mis-power/sampler=independent", "relative to the best", "per object"):
        assert label in text
    assert "lightprobe compare --demo" not in text or "--spp 4" in text


def _chromium(*args, timeout=120):
    cmd = [CHROMIUM, "--headless=new", "--no-sandbox", "--disable-gpu", "--enable-logging=stderr", "--v=0", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)


@pytest.mark.skipif(CHROMIUM is None, reason="no Chromium found (Debian: apt-get install chromium)")
def test_the_report_in_headless_chromium(report, tmp_path):
    url = report.resolve().as_uri()
    dom = _chromium("--virtual-time-budget=5000", "--dump-dom", url)
    body = re.search(r"<body([^>]*)>", dom.stdout)
    assert body, dom.stderr[-2000:]
    attrs = dict(re.findall(r'data-(\w+)="([^"]*)"', body.group(1)))
    assert attrs.get("ready") == "1", attrs
    assert attrs.get("errors") == "", attrs
    assert int(attrs["images"]) == 11 and attrs["decoded"] == attrs["images"]
    console_errors = [
        line for line in dom.stderr.splitlines() if "CONSOLE" in line and ("Error" in line or "Uncaught" in line)
    ]
    assert not console_errors, console_errors
    shot = tmp_path / "shot.png"
    _chromium("--hide-scrollbars", "--window-size=1200,1400", "--virtual-time-budget=5000", f"--screenshot={shot}", url)
    image = read_image(shot)[:, :, :3]
    assert image.shape[:2] == (1400, 1200)
    background = np.all(np.abs(image - image[5, 5]) < 0.02, axis=2)
    assert background.mean() < 0.9 and image.std() > 0.05  # text, images and plots, not an empty page


def _x_labels(fig):
    """(text, window extent) of the x tick labels drawn inside the axes, left to right."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    ax = fig.axes[0]
    drawn = []
    for label in ax.get_xticklabels(which="both"):
        if not (label.get_text() and label.get_visible()):
            continue
        box = label.get_window_extent(renderer)
        if ax.bbox.x0 - 2 <= (box.x0 + box.x1) / 2 <= ax.bbox.x1 + 2:
            drawn.append((label.get_text(), box))
    return sorted(drawn, key=lambda item: item[1].x0)


@pytest.mark.parametrize("span", [1.5, 2.0, 5.0, 12.0, 20.0, 35.0, 300.0, 1e5])
def test_convergence_axes_labels_never_overlap(span):
    """The seconds of a report's rounds can span any range; matplotlib's default log labels collided on some (e.g.
    0.0316-0.047 s, 0.018-0.36 s)."""
    from types import SimpleNamespace

    import matplotlib.pyplot as plt

    from lightprobe.analysis.report import _convergence_figure

    for lo in np.geomspace(0.01, 10.0, 9):
        rounds = [{"seconds": x, "spp": x, "mse": 0.1 / x} for x in np.geomspace(lo, lo * span, 4)]
        runs = [SimpleNamespace(label="mis", rounds=rounds, metrics={"efficiency": 1.0})]
        fig = _convergence_figure(runs, "seconds", "seconds")
        labels = _x_labels(fig)
        plt.close(fig)
        texts = [text for text, _ in labels]
        collisions = [(a[0], b[0]) for a, b in itertools.pairwise(labels) if a[1].x1 > b[1].x0]
        assert not collisions, (lo, span, collisions)
        assert len(labels) >= (2 if span >= 2 else 1), (lo, span, texts)
