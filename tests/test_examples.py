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


NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "examples").glob("*.ipynb"))


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.name)
def test_notebook_runs(path, tmp_path):
    """Every notebook executes top to bottom (its own asserts included), so none rots."""
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    notebook = nbformat.read(path, as_version=4)
    client = nbclient.NotebookClient(
        notebook, timeout=900, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}
    )
    client.execute()
    outputs = [o for cell in notebook.cells if cell.cell_type == "code" for o in cell.get("outputs", [])]
    assert not [o for o in outputs if o.get("output_type") == "error"]
    assert any("image/png" in o.get("data", {}) for o in outputs)  # the pictures were drawn


def test_the_gltf_asset_is_what_its_script_writes(tmp_path):
    """examples/assets/spheres.glb is examples/make_gltf_asset.py's output, byte for byte (so it can be remade)."""
    import importlib.util

    root = Path(__file__).resolve().parents[1] / "examples"
    spec = importlib.util.spec_from_file_location("make_gltf_asset", root / "make_gltf_asset.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    written = module.main(tmp_path / "spheres.glb")
    assert written.read_bytes() == (root / "assets" / "spheres.glb").read_bytes()


def test_the_textured_asset_script_writes_a_glb_that_loads_and_renders(tmp_path):
    """examples/make_textured_asset.py on its built-in icosphere with 64-texel textures: four textures (8-bit), UVs
    with the seam's copies at u + 1, and a finite render under a constant sky."""
    import importlib.util

    from lightprobe.emitters.envmap import EnvironmentMap
    from lightprobe.geometry import Camera
    from lightprobe.io.gltf import load_gltf
    from lightprobe.scene import Scene

    root = Path(__file__).resolve().parents[1] / "examples"
    spec = importlib.util.spec_from_file_location("make_textured_asset", root / "make_textured_asset.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    asset = load_gltf(module.main(tmp_path / "t.glb", size=64, mesh="icosphere"))
    bunny, ground = asset.meshes
    assert list(ground.material.textures.used()) == ["base_color"]
    textures = bunny.material.textures
    assert {k: t.pixels.shape for k, t in textures.used().items()} == {
        "base_color": (64, 64, 4), "metallic_roughness": (64, 64, 4), "normal": (64, 64, 4)
    }  # fmt: skip
    uvs = bunny.mesh.uvs
    assert uvs.min() >= 0.0 and uvs[:, 0].max() < 1.5 and uvs[:, 1].max() <= 1.0
    corner_u = uvs[bunny.mesh.faces, 0]
    # no triangle spans the seam (which would squeeze the whole texture into it); around the poles, where the
    # azimuth turns fast, a triangle spans up to 0.6
    assert (corner_u.max(axis=1) - corner_u.min(axis=1)).max() < 0.7
    scene = Scene(Camera([0.3, 0.9, 2.3], [0.0, 0.4, 0.0], fov=32, resolution=(24, 16)),
                  EnvironmentMap.from_array(np.full((8, 16, 3), 0.5)))  # fmt: skip
    asset.add_to(scene)
    image = render(scene, RenderSettings(spp=2)).image
    assert np.all(np.isfinite(image)) and image.mean() > 0.05
