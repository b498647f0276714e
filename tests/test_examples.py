"""Every example scene renders (at a tiny size), so none rots; scenes that need ../shared/data skip without it."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from lightprobe.integrators.wavefront import RenderSettings, render
from lightprobe.io.scene_file import load_scene

EXAMPLES = sorted((Path(__file__).resolve().parents[1] / "examples").glob("*.toml"))


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.name)
def test_example_renders(path):
    text = path.read_text()
    for rel in re.findall(r'file = "([^"]+)"', text):
        if not (path.parent / rel).exists():
            pytest.skip(f"{rel} is absent (../shared/data)")
    scene, defaults = load_scene(path)
    scene.camera = scene.camera.with_resolution(24, 16)
    result = render(scene, RenderSettings(spp=2))
    assert np.all(np.isfinite(result.image)) and result.image.mean() > 0
    assert defaults.get("spp", 1) >= 1
