"""The HTML report, opened in headless Chromium: no script errors, every image decoded, a non-blank screenshot."""

from __future__ import annotations

import re
import shutil
import subprocess

import numpy as np
import pytest

from lightprobe.cli import main
from lightprobe.io.images import read_image

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
