"""References: checkpointed in chunks, resumed after a stop or a kill, bit for bit an uninterrupted render."""

from __future__ import annotations

import dataclasses
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from lightprobe.analysis.reference import checkpoint_path, render_reference
from lightprobe.cli import main
from lightprobe.errors import LightprobeError
from lightprobe.images import read_image
from lightprobe.integrators.wavefront import RenderSettings, render
from lightprobe.io.scene_file import load_scene

SCENE = (
    "[camera]\norigin = [0, 1, 4]\ntarget = [0, 0, 0]\nresolution = [24, 16]\n"
    "[environment]\nsky = { sun_elevation = 35, sun_azimuth = 45, sun_diameter = 2.0, width = 64, height = 32 }\n"
    '[materials.white]\ntype = "lambert"\nalbedo = 0.5\n'
    '[materials.metal]\ntype = "conductor"\nalpha = 0.2\nmaterial = "Au"\n'
    '[[objects]]\ntype = "sphere"\ncenter = [0, 0, 0]\nradius = 1\nmaterial = "metal"\n'
    '[[objects]]\ntype = "rectangle"\norigin = [-3, -1, 3]\nedge_u = [6, 0, 0]\nedge_v = [0, 0, -6]\n'
    'material = "white"\n'
)


@pytest.fixture
def scene_file(tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text(SCENE)
    return path


def test_stopped_and_resumed_equals_uninterrupted(scene_file, tmp_path):
    scene, _ = load_scene(scene_file)
    # 16 spp, adaptive left automatic: a plain render would take adaptive counts, a reference takes uniform ones
    settings = RenderSettings(spp=16, seed=3)
    whole = render(scene, dataclasses.replace(settings, adaptive=False))
    out = tmp_path / "ref.exr"
    first = render_reference(scene, dataclasses.replace(settings, spp=4), out, chunk=3, scene_id="s")
    assert int(first.counts.min()) == 4 and checkpoint_path(out).exists()
    resumed = render_reference(scene, settings, out, chunk=5, scene_id="s")  # extends 4 -> 16 in other chunks
    assert resumed.stats["resumed_from_spp"] == 4
    np.testing.assert_array_equal(resumed.image, whole.image)
    np.testing.assert_array_equal(resumed.variance, whole.variance)
    # a finished reference resumes to itself without rendering
    again = render_reference(scene, settings, out, chunk=5, scene_id="s")
    np.testing.assert_array_equal(again.image, whole.image)


def test_a_reference_refuses_adaptive_counts(scene_file, tmp_path):
    scene, _ = load_scene(scene_file)
    with pytest.raises(LightprobeError, match="checkpointed sample ranges, which adaptive counts cannot be"):
        render_reference(scene, RenderSettings(spp=16, adaptive=True), tmp_path / "ref.exr", scene_id="s")
    assert not checkpoint_path(tmp_path / "ref.exr").exists()


def test_a_checkpoint_of_another_render_is_refused(scene_file, tmp_path):
    scene, _ = load_scene(scene_file)
    out = tmp_path / "ref.exr"
    render_reference(scene, RenderSettings(spp=2, seed=3), out, chunk=2, scene_id="s")
    with pytest.raises(LightprobeError, match=r"ref.exr.checkpoint.npz: checkpoint of a different render \(seed"):
        render_reference(scene, RenderSettings(spp=4, seed=4), out, chunk=2, scene_id="s")
    # each setting with what it was and what it is now (a default that changed since, say)
    with pytest.raises(LightprobeError, match=r"differ\): light_sampler 'learned' in the checkpoint, 'bvh' now; use"):
        render_reference(scene, RenderSettings(spp=4, seed=3, light_sampler="bvh"), out, chunk=2, scene_id="s")
    with pytest.raises(LightprobeError, match="scene differ"):
        render_reference(scene, RenderSettings(spp=4, seed=3), out, chunk=2, scene_id="other")
    checkpoint_path(out).write_bytes(b"not a checkpoint")
    with pytest.raises(LightprobeError, match=r"damaged checkpoint \(16 bytes that are not an \.npz archive"):
        render_reference(scene, RenderSettings(spp=4, seed=3), out, chunk=2, scene_id="s")


def test_a_checkpoint_made_under_another_automatic_rule_is_refused(scene_file, tmp_path, monkeypatch):
    """The checkpoint records the settings with the automatic choices made: a checkpoint whose automatic counts
    came to other values (here: made while the rule gave one light pick and one BSDF sample, as before decision 97,
    in a scene with a sky and a light) is another render, refused with the counts that differ, although both runs
    left the counts automatic; the same rule resumes it."""
    from lightprobe.emitters.punctual import PointLight
    from lightprobe.integrators.settings import RenderSettings as Settings

    scene, _ = load_scene(scene_file)
    scene.add_light(PointLight([0, 3, 1], 5.0))
    out = tmp_path / "ref.exr"
    resolved = Settings.resolved

    def old_rule(self, environment_only, one_delta_light=False, environment=False, resumed=False, bounded_lights=0):
        new = resolved(self, environment_only, one_delta_light, environment, resumed, bounded_lights)
        if environment_only:
            return new
        return dataclasses.replace(
            new,
            n_bsdf=self.n_bsdf if self.n_bsdf is not None else 1,
            lights_per_sample=self.lights_per_sample or 1,
        )

    with monkeypatch.context() as patch:
        patch.setattr(Settings, "resolved", old_rule)
        render_reference(scene, RenderSettings(spp=2, seed=3), out, chunk=2, scene_id="s")
    with pytest.raises(LightprobeError, match=r"\(lights_per_sample, n_bsdf differ\)"):
        render_reference(scene, RenderSettings(spp=4, seed=3), out, chunk=2, scene_id="s")
    with monkeypatch.context() as patch:
        patch.setattr(Settings, "resolved", old_rule)
        resumed = render_reference(scene, RenderSettings(spp=4, seed=3), out, chunk=2, scene_id="s")
    assert resumed.stats["resumed_from_spp"] == 2


def test_a_checkpoint_of_an_older_version_resumes_only_if_it_gave_every_count(scene_file, tmp_path):
    """Checkpoints written before the settings were recorded as resolved (no "counts" entry; None for an automatic
    count): one that gave every count resumes with the same counts given; one that left a count automatic is
    refused, naming it (this version may choose it differently)."""
    import json

    scene, _ = load_scene(scene_file)
    out = tmp_path / "ref.exr"
    given = {"n_bsdf": 2, "n_env": 3, "heuristic": "power", "lights_per_sample": 1}
    render_reference(scene, RenderSettings(spp=2, seed=3, **given), out, chunk=2, scene_id="s")
    path = checkpoint_path(out)

    def rewrite_as_older(**settings):
        with np.load(path) as data:
            arrays = {k: data[k] for k in data.files}
        identity = json.loads(str(arrays.pop("identity")))
        del identity["counts"]
        identity["settings"].update(settings)
        with open(path, "wb") as fh:
            np.savez(fh, identity=np.array(json.dumps(identity)), **arrays)

    rewrite_as_older()
    resumed = render_reference(scene, RenderSettings(spp=4, seed=3, **given), out, chunk=2, scene_id="s")
    assert resumed.stats["resumed_from_spp"] == 2
    rewrite_as_older(n_bsdf=None, heuristic=None)
    with pytest.raises(LightprobeError, match=r"older lightprobe that left heuristic, n_bsdf automatic"):
        render_reference(scene, RenderSettings(spp=6, seed=3), out, chunk=2, scene_id="s")


def _drop_from_identity(path, key):
    """Rewrite checkpoint ``path`` as a version that did not record ``key`` wrote it."""
    import json

    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    identity = json.loads(str(arrays.pop("identity")))
    del identity[key]
    with open(path, "wb") as fh:
        np.savez(fh, identity=np.array(json.dumps(identity)), **arrays)


def test_a_checkpoint_from_before_maps_beside_lights_were_compensated(scene_file, tmp_path):
    """Checkpoints written before they recorded the MIS compensation: the automatic choice was then the Lambertian
    materials with a map alone and none with a map beside other lights (decisions.md 98 compensates both).  A map
    alone resumes; a map beside a light with the compensation left automatic is refused, naming it; given
    explicitly, it resumes."""
    from lightprobe.emitters.punctual import PointLight

    alone, _ = load_scene(scene_file)
    beside, _ = load_scene(scene_file)
    beside.add_light(PointLight([0, 3, 1], 5.0))
    for scene, settings, resumes in (
        (alone, {}, True),
        (beside, {}, False),
        (beside, {"mis_compensation": False}, True),
    ):
        out = tmp_path / f"ref{len(scene.lights)}{settings}.exr"
        render_reference(scene, RenderSettings(spp=2, seed=3, **settings), out, chunk=2, scene_id="s")
        _drop_from_identity(checkpoint_path(out), "compensation")
        if resumes:
            again = render_reference(scene, RenderSettings(spp=4, seed=3, **settings), out, chunk=2, scene_id="s")
            assert again.stats["resumed_from_spp"] == 2
        else:
            with pytest.raises(LightprobeError, match=r"checkpoint of a different render \(mis_compensation differ"):
                render_reference(scene, RenderSettings(spp=4, seed=3, **settings), out, chunk=2, scene_id="s")


def _damaged(good: bytes, damage: str, n_pixels: int) -> bytes:
    """A checkpoint's bytes after ``damage``: cut short, overwritten in its arrays or at its start, emptied, an .npy
    array instead of the archive, or a readable archive whose arrays do not fit the image."""
    import io
    import json

    if damage == "truncated":
        return good[: len(good) // 3]
    if damage == "garbage in the arrays":
        return good[:2000] + b"\xab" * 400 + good[2400:]
    if damage == "garbage at the start":
        return b"\xab" * 64 + good[64:]
    if damage == "empty":
        return b""
    out = io.BytesIO()
    if damage == "an .npy array":
        np.save(out, np.zeros(4))
    else:  # the arrays of another image, or a mean with two channels
        identity = json.loads(str(np.load(io.BytesIO(good))["identity"]))
        arrays = {"mean": np.zeros((n_pixels, 2)), "m2": np.zeros((n_pixels, 3)), "count": np.full(n_pixels, 2)}
        np.savez(out, identity=np.array(json.dumps(identity)), nonfinite=np.zeros(n_pixels, np.int64), **arrays)
    return out.getvalue()


@pytest.mark.parametrize(
    "damage",
    ["truncated", "garbage in the arrays", "garbage at the start", "empty", "an .npy array", "arrays of wrong shape"],
)
def test_a_damaged_checkpoint_is_one_line_and_kept(scene_file, tmp_path, damage):
    """A checkpoint cut short, overwritten or emptied (a full disk, a bad copy) is refused in one line that names it
    and says what to do, and is left as it is: it may be all that is left of hours of rendering.  Before, numpy's
    zipfile.BadZipFile and EOFError escaped (a traceback, or "interrupted" at the command line)."""
    scene, _ = load_scene(scene_file)
    out = tmp_path / "ref.exr"
    render_reference(scene, RenderSettings(spp=2, seed=3), out, chunk=2, scene_id="s")
    ckpt = checkpoint_path(out)
    width, height = scene.camera.resolution
    damaged = _damaged(ckpt.read_bytes(), damage, width * height)
    ckpt.write_bytes(damaged)
    with pytest.raises(LightprobeError) as info:
        render_reference(scene, RenderSettings(spp=4, seed=3), out, chunk=2, scene_id="s")
    message = str(info.value)
    assert message.startswith(f"{ckpt}: damaged checkpoint") and "\n" not in message, message
    assert "remove it to start over, or choose another -o to keep it" in message, message
    assert ckpt.read_bytes() == damaged


def test_killed_mid_run_then_resumed_is_bit_identical(scene_file, tmp_path):
    """SIGKILL (no chance to clean up) after a checkpoint, then the same command again."""
    out = tmp_path / "ref.exr"
    cmd = [sys.executable, "-m", "lightprobe", "reference", str(scene_file), "-o", str(out), "--spp", "4000"]
    cmd += ["--chunk", "2", "--seed", "5"]
    proc = subprocess.Popen(cmd, stderr=subprocess.DEVNULL)
    ckpt = checkpoint_path(out)
    deadline = time.time() + 180
    while not ckpt.exists() and time.time() < deadline and proc.poll() is None:
        time.sleep(0.05)
    time.sleep(0.3)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=60)
    assert ckpt.exists() and not out.exists()
    with np.load(ckpt) as data:
        done = int(data["count"][0])
    assert 2 <= done < 4000 and done % 2 == 0
    # resume to a total a little above what the killed run reached
    total = done + 6
    assert main(["reference", str(scene_file), "-o", str(out), "--spp", str(total), "--chunk", "4", "--seed", "5"]) == 0
    scene, _ = load_scene(scene_file)
    whole = render(scene, RenderSettings(spp=total, seed=5, adaptive=False))
    image = read_image(out)
    np.testing.assert_array_equal(image[:, :, :3], whole.image)
    np.testing.assert_array_equal(image[:, :, 3:6], whole.variance)


def test_reference_quiet_prints_only_the_result(scene_file, tmp_path, capsys):
    args = ["reference", str(scene_file), "-o", str(tmp_path / "r.exr"), "--spp", "4", "--chunk", "2"]
    assert main(args) == 0
    loud = capsys.readouterr().err
    assert "checkpoint written" in loud
    assert main([*args[:3], str(tmp_path / "q.exr"), *args[4:], "-q"]) == 0
    quiet = capsys.readouterr().err
    assert "checkpoint written" not in quiet and quiet.count("\n") == 1 and quiet.startswith("wrote "), quiet


def test_reference_command_errors_are_one_line(scene_file, tmp_path, capsys):
    assert main(["reference", str(scene_file), "-o", str(tmp_path / "r.png")]) != 0
    assert "a reference is written as .exr" in capsys.readouterr().err
    assert main(["reference", str(scene_file), "-o", str(tmp_path / "r.exr"), "--chunk", "0"]) != 0
    assert "chunk must be >= 1" in capsys.readouterr().err
