"""Shared fixtures of the laboratory's tests."""

import pytest

from lightprobe.integrators.settings import RenderSettings
from lightprobe.integrators.wavefront import render
from lightprobe.io.scene_file import load_scene
from lightprobe.lab.exercise import init_exercise


@pytest.fixture(scope="module")
def exercise_scene(tmp_path_factory):
    """The exercise's scene at 48x36 and the render core's 1024-spp image of it (one per test module)."""
    root = tmp_path_factory.mktemp("exercise")
    init_exercise(root)
    scene, _ = load_scene(root / "scene.toml")
    scene.camera = scene.camera.with_resolution(48, 36)
    reference = render(scene, RenderSettings(spp=1024, seed=99, heuristic="balance"))
    return scene, reference
