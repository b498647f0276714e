"""The command line on tiny inputs: every command runs, user errors are one line and exit status 2."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from lightprobe.cli import main
from lightprobe.emitters.procedural import sky_with_sun
from lightprobe.images import read_image, write_image


@pytest.fixture
def sky(tmp_path):
    return write_image(tmp_path / "sky.exr", sky_with_sun(64, 32, sun_diameter_deg=6.0))


# First in the file, as tests/conftest.py's FIRST_FILES assumes: this render compiles the render core while the
# other worker runs tests that need none of it (decisions.md 89).
def test_render_demo_with_variance_png_and_sidecar(tmp_path):
    out = tmp_path / "demo.exr"
    preview = tmp_path / "demo.png"
    assert (
        main(
            [
                "render",
                "--demo",
                "--width",
                "40",
                "--spp",
                "2",
                "-o",
                str(out),
                "--variance",
                "--png",
                str(preview),
                "-q",
            ]
        )
        == 0
    )
    img = read_image(out)
    assert img.shape == (25, 40, 6) and np.all(np.isfinite(img))
    assert read_image(preview).shape[:2] == (25, 40)
    meta = json.loads((tmp_path / "demo.exr.json").read_text())
    for key in ("seconds", "samples_per_s", "rays_per_s", "spp_done", "strategy", "seed", "machine"):
        assert key in meta
    assert meta["spp_done"] == 2 and meta["strategy"] == "mis"


def test_experiment_shading_point(capsys, tmp_path):
    out = tmp_path / "table.md"
    assert (
        main(
            [
                "experiment",
                "shading-point",
                "--maps",
                "constant",
                "--exponents",
                "1,100",
                "--samples",
                "2000",
                "-o",
                str(out),
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    assert "| constant | phong n=100 |" in text and "| constant | lambert |" in text
    assert "phong n=1 " in out.read_text()


def test_envmap_info(capsys, sky):
    assert main(["envmap", "info", str(sky)]) == 0
    assert "64x32 lat-long" in capsys.readouterr().out
    assert main(["envmap", "info", str(sky), "--json"]) == 0
    stats = json.loads(capsys.readouterr().out)
    assert stats["width"] == 64 and stats["max_luminance"] > 1000


def test_envmap_convert_round_trip(tmp_path, sky):
    angular = tmp_path / "probe.hdr"
    assert main(["envmap", "convert", str(sky), str(angular), "--to", "angular", "--size", "128"]) == 0
    assert read_image(angular).shape == (128, 128, 3)
    back = tmp_path / "back.exr"
    assert main(["envmap", "convert", str(angular), str(back), "--to", "latlong"]) == 0
    assert read_image(back).shape == (64, 128, 3)


def test_envmap_pdf_picture(tmp_path, sky):
    out = tmp_path / "pdf.png"
    assert main(["envmap", "pdf", str(sky), "-o", str(out), "--compensated"]) == 0
    assert read_image(out).shape[2] in (3, 4)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["envmap", "info", "missing.exr"], "missing.exr: no such file"),
        (["envmap", "pdf", "SKY", "--pdf", "magic"], "pdf must be one of"),
        (["envmap", "convert", "SKY", "out.exr", "--to", "cube"], "--to must be"),
        (["experiment", "shading-point", "--maps", "nowhere", "--samples", "100"], "nowhere"),
        (["experiment", "shading-point", "--exponents", "a,b"], "--exponents"),
    ],
)
def test_user_errors_are_one_line(capsys, tmp_path, sky, args, message):
    args = [str(sky) if a == "SKY" else a for a in args]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("lightprobe: error:") and message in err[0], err


def test_nan_map_is_one_line(capsys, tmp_path):
    img = np.ones((4, 8, 3), np.float32)
    img[0, 0, 0] = np.nan
    path = write_image(tmp_path / "nan.exr", img)
    assert main(["envmap", "info", str(path)]) == 2
    assert "nan.exr: 1 texels are NaN" in capsys.readouterr().err


def test_console_entry_point_and_usage_errors():
    ok = subprocess.run([sys.executable, "-m", "lightprobe", "--help"], capture_output=True, text=True)
    assert ok.returncode == 0 and "envmap" in ok.stdout
    bad = subprocess.run([sys.executable, "-m", "lightprobe", "envmap", "info"], capture_output=True, text=True)
    assert bad.returncode == 2 and "Traceback" not in bad.stderr


@pytest.mark.parametrize(
    ("command", "expected"),
    [("render", "Random seed [0]."), ("reference", "Random seed [0]."), ("compare", "[default: spp]")],
)
def test_help_texts_keep_their_bracketed_defaults(command, expected):
    """Defaults are written in brackets ("Random seed [0]."); rendered as Rich markup they vanished ("Random seed
    .")."""
    out = subprocess.run([sys.executable, "-m", "lightprobe", command, "--help"], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert expected in out.stdout, out.stdout
    lines = [line.rstrip() for line in out.stdout.splitlines()]
    assert not [line for line in lines if line.endswith(" .") or " . " in line], out.stdout


def test_render_scene_file_with_defaults_and_overrides(tmp_path, capsys):
    (tmp_path / "s.toml").write_text(
        "[camera]\norigin = [0, 0, 4]\ntarget = [0, 0, 0]\nresolution = [16, 12]\n"
        "[environment]\nconstant = [1.0, 1.0, 1.0]\n"
        '[materials.white]\ntype = "lambert"\nalbedo = 0.5\n'
        '[[objects]]\ntype = "sphere"\ncenter = [0, 0, 0]\nradius = 1\nmaterial = "white"\n'
        '[render]\nspp = 3\nstrategy = "cosine"\n'
    )
    out = tmp_path / "s.pfm"
    assert main(["render", str(tmp_path / "s.toml"), "-o", str(out), "--seed", "5", "-q"]) == 0
    meta = json.loads((tmp_path / "s.pfm.json").read_text())
    assert meta["spp_done"] == 3 and meta["strategy"] == "cosine" and meta["seed"] == 5
    img = read_image(out)
    assert img[6, 8, 0] == pytest.approx(0.5, rel=1e-6)  # white furnace, exactly (cosine sampling of Lambert)
    assert "wrote" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["render", "missing.toml"], "missing.toml: no such file"),
        (["render"], "give a SCENE file or --demo"),
        (["render", "--demo", "--strategy", "best"], "strategy must be one of"),
        (["render", "--demo", "--spp", "0"], "spp must be"),
        (["render", "--demo", "--width", "8", "--spp", "1", "-o", "OUT.png", "--variance", "-q"], "needs an .exr"),
        (["render", "--demo", "-o", "OUT.tiff", "--width", "8", "--spp", "1", "-q"], "unsupported output format"),
    ],
)
def test_render_user_errors(capsys, tmp_path, args, message):
    args = [str(tmp_path / a.lower()) if a.startswith("OUT.") else a for a in args]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("lightprobe: error:") and message in err[0], err


def test_ctrl_c_before_the_render_is_an_interruption_not_a_success(tmp_path, monkeypatch, capsys):
    """Ctrl-C while the scene loads: Typer hands main() exit code 130 instead of raising, which main() once
    dropped (exit 0, no message)."""
    import lightprobe.demo

    def interrupted():
        raise KeyboardInterrupt

    monkeypatch.setitem(lightprobe.demo.DEMOS, "default", interrupted)
    assert main(["render", "--demo", "-o", str(tmp_path / "x.exr"), "-q"]) == 130
    assert "interrupted" in capsys.readouterr().err and not (tmp_path / "x.exr").exists()


def test_ctrl_c_writes_what_was_accumulated(tmp_path):
    """A real SIGINT to a running render: it stops, writes the image and says so."""
    import signal
    import time

    out = tmp_path / "partial.exr"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "lightprobe",
            "render",
            "--demo",
            "--width",
            "64",
            "--spp",
            "1000000",
            "-o",
            str(out),
            "-q",
        ],
        stderr=subprocess.PIPE,
        text=True,
    )
    line = proc.stderr.readline()  # the scene summary, printed once the scene is built
    assert "demo" in line
    # early, possibly before the first pass (while kernels load or compile): the render still stops only once
    # every pixel holds a sample
    time.sleep(0.5)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err
    assert "interrupted" in err and out.exists()
    meta = json.loads((tmp_path / "partial.exr.json").read_text())
    assert meta["interrupted"] is True and 1 <= meta["spp_done"] < 1000000
    image = read_image(out)
    assert np.all(np.isfinite(image)) and image.mean() > 0.01


def _scene_file(tmp_path, render_table: str = "") -> Path:
    path = tmp_path / "s.toml"
    path.write_text(
        "[camera]\norigin = [0, 0, 4]\ntarget = [0, 0, 0]\nresolution = [16, 12]\n"
        "[environment]\nconstant = [1.0, 1.0, 1.0]\n"
        '[materials.white]\ntype = "lambert"\nalbedo = 0.5\n'
        '[[objects]]\ntype = "sphere"\ncenter = [0, 0, 0]\nradius = 1\nmaterial = "white"\n'
        f"[render]\n{render_table}\n"
    )
    return path


@pytest.mark.parametrize(
    ("entry", "message"),
    [
        ('seed = "1"', "seed must be an integer"),
        ('bsdf_samples = "2"', "bsdf_samples must be an integer"),
        ("spp = 2.5", "spp must be an integer"),
        ("spp = 0", "spp must be >= 1"),
        ('strategy = "best"', "strategy must be one of"),
        ("mis_compensation = 1", "mis_compensation must be true or false"),
        ("env_samples = -1", "env_samples must be >= 0"),
        ("adaptive = 1", "adaptive must be true or false"),
        ("adaptive = true\nspp = 3", "adaptive sampling needs spp >= 4"),
    ],
)
def test_wrong_typed_render_keys_are_one_line(capsys, tmp_path, entry, message):
    path = _scene_file(tmp_path, entry)
    assert main(["render", str(path), "-o", str(tmp_path / "o.exr"), "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("lightprobe: error:") and message in err[0], err
    assert "[render]" in err[0] and "s.toml" in err[0]
    assert not (tmp_path / "o.exr").exists()


def _unwritable_folder(tmp_path):
    """A folder no new file can be made in, even by root: a read-only folder, else sysfs."""
    import os

    if os.geteuid() != 0:
        folder = tmp_path / "read-only"
        folder.mkdir()
        folder.chmod(0o555)
        return folder
    return Path("/sys")


@pytest.mark.parametrize("case", ["parent-is-a-file", "read-only-folder", "disk-full", "extension"])
def test_an_unwritable_output_fails_before_rendering(capsys, tmp_path, monkeypatch, case):
    """One line naming the path, exit status 2, and no render: the error comes before the first pass."""
    import lightprobe.integrators.wavefront as wavefront

    rendered = []
    monkeypatch.setattr(wavefront, "render", lambda *a, **k: rendered.append(1))
    if case == "parent-is-a-file":
        (tmp_path / "file").write_text("x")
        out = tmp_path / "file" / "out.exr"
        message = "is a file, not a folder"
    elif case == "read-only-folder":
        folder = _unwritable_folder(tmp_path)
        out = folder / "lightprobe-out.exr"
        try:
            out.with_name("lightprobe-probe").write_text("x")
            pytest.skip(f"{folder} accepts new files here")
        except OSError:
            pass
        message = "cannot write"
    elif case == "disk-full":
        import shutil

        import lightprobe.io.outputs as outputs

        out = tmp_path / "out.exr"
        monkeypatch.setattr(outputs.shutil, "disk_usage", lambda p: shutil._ntuple_diskusage(10**9, 10**9, 1000))
        message = "not enough free space"
    else:
        out = tmp_path / "out.tiff"
        message = "unsupported output format"
    path = _scene_file(tmp_path)
    assert main(["render", str(path), "-o", str(out), "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("lightprobe: error:") and str(out) in err[0] and message in err[0], err
    assert not rendered


def test_a_render_that_cannot_be_written_is_rescued(capsys, tmp_path, monkeypatch):
    """The disk fills up during the render: the image goes to a rescue EXR in the current folder (mean and
    variance), and the one-line error says where."""
    import lightprobe.io.outputs as outputs

    real_write = outputs.write_image
    target = tmp_path / "out" / "render.exr"

    def disk_full(path, *args, **kwargs):
        if Path(path) == target:
            raise outputs.ImageError(f"{path}: cannot write (No space left on device)")
        return real_write(path, *args, **kwargs)

    monkeypatch.setattr(outputs, "write_image", disk_full)
    monkeypatch.chdir(tmp_path)
    path = _scene_file(tmp_path, 'spp = 4\nstrategy = "mis"')
    assert main(["render", str(path), "-o", str(target), "-q"]) == 2
    err = [line for line in capsys.readouterr().err.strip().splitlines() if "error" in line or "Traceback" in line]
    assert len(err) == 1 and "No space left on device" in err[0] and str(target) in err[0], err
    rescued = sorted(tmp_path.glob("lightprobe-rescued-render-*.exr"))
    assert len(rescued) == 1 and rescued[0].name in err[0]
    image = read_image(rescued[0])
    # a furnace (rho L = 0.5 on the sphere), with the variance of the mean in channels 3-5
    z = (image[6, 8, :3] - 0.5) / np.sqrt(image[6, 8, 3:])
    assert image.shape == (12, 16, 6) and np.all(np.abs(z) < 5) and image[6, 8, 3:].min() > 0, image[6, 8]
    meta = json.loads(rescued[0].with_name(rescued[0].name + ".json").read_text())
    assert meta["intended_output"] == str(target) and meta["spp_done"] == 4


def test_compiling_is_announced(capsys, tmp_path, monkeypatch):
    """When the kernels are not in the cache, the render says it is compiling and how long it took."""
    import lightprobe.integrators.wavefront as wavefront

    monkeypatch.setattr(wavefront, "kernels_cached", lambda *scene_and_settings: False)
    assert main(["render", str(_scene_file(tmp_path)), "-o", str(tmp_path / "o.exr"), "--spp", "1", "-q"]) == 0
    err = capsys.readouterr().err
    assert "compiling kernels (once for this kind of scene" in err and "compiled kernels in" in err
    monkeypatch.setattr(wavefront, "kernels_cached", lambda *scene_and_settings: True)
    assert main(["render", str(_scene_file(tmp_path)), "-o", str(tmp_path / "o.exr"), "--spp", "1", "-q"]) == 0
    assert "compiling kernels" not in capsys.readouterr().err


def test_kernels_report_whether_they_are_cached(tmp_path):
    from lightprobe._numba import is_cached, jit
    from lightprobe.integrators.wavefront import kernels_cached

    # the demo's kernels (what kernels_cached() checks by default: the environment's stages in vector lanes, Embree)
    assert main(["render", "--demo", "--width", "24", "-o", str(tmp_path / "d.exr"), "--spp", "1", "-q"]) == 0
    assert kernels_cached()  # the render above compiled (or loaded) them into the cache
    from lightprobe.io.scene_file import load_scene

    scene, _ = load_scene(_scene_file(tmp_path))  # a small constant map: its samples are drawn one slot at a time
    assert main(["render", str(_scene_file(tmp_path)), "-o", str(tmp_path / "o.exr"), "--spp", "1", "-q"]) == 0
    assert kernels_cached(scene)

    @jit
    def never_called(x):
        return x + 1

    assert not is_cached(never_called)


def test_render_many_lights_demo_records_the_light_settings(tmp_path):
    out = tmp_path / "lights.exr"
    args = ["render", "--demo", "many-lights", "--width", "24", "--spp", "2", "-o", str(out), "-q"]
    assert main([*args, "--light-sampler", "bvh", "--lights-per-sample", "3", "--light-strategy", "area"]) == 0
    meta = json.loads((tmp_path / "lights.exr.json").read_text())
    assert meta["light_sampler"] == "bvh" and meta["lights_per_sample"] == 3 and meta["light_strategy"] == "area"
    assert meta["area_lights"] == 4000 and meta["spp_done"] == 2
    image = read_image(out)
    assert np.all(np.isfinite(image)) and image.mean() > 0


def test_scene_file_with_area_lights_and_no_environment(tmp_path):
    path = tmp_path / "lit.toml"
    path.write_text(
        "[camera]\norigin = [0, 2, 4]\ntarget = [0, 0, 0]\nresolution = [12, 8]\n"
        '[materials.grey]\ntype = "lambert"\nalbedo = 0.5\n'
        '[[objects]]\ntype = "ground"\nmaterial = "grey"\n'
        '[[objects]]\ntype = "rectangle"\norigin = [-0.5, 1.5, -0.5]\nedge_u = [1, 0, 0]\nedge_v = [0, 0, 1]\n'
        "emission = [1.0, 0.9, 0.8]\nemission_scale = 5.0\n"
        '[[objects]]\ntype = "sphere"\ncenter = [1, 0.3, 0]\nradius = 0.3\nemission = 2.0\n'
        '[render]\nspp = 2\nlight_sampler = "bvh"\nlights_per_sample = 2\nlight_strategy = "area"\n'
    )
    out = tmp_path / "lit.pfm"
    assert main(["render", str(path), "-o", str(out), "-q"]) == 0
    meta = json.loads((tmp_path / "lit.pfm.json").read_text())
    assert meta["area_lights"] == 2 and meta["light_sampler"] == "bvh" and meta["lights_per_sample"] == 2
    assert read_image(out).mean() > 0


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["render", "--demo", "nowhere"], "unknown demo 'nowhere'"),
        (["render", "--demo", "--light-sampler", "random"], "light_sampler must be one of"),
        (["render", "--demo", "--light-strategy", "magic"], "light_strategy must be one of"),
        (["render", "--demo", "--lights-per-sample", "0"], "lights_per_sample must be >= 1"),
    ],
)
def test_light_option_errors_are_one_line(capsys, tmp_path, args, message):
    assert main([*args, "-o", str(tmp_path / "x.exr"), "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("lightprobe: error:") and message in err[0], err


def test_render_adds_point_and_spot_lights(tmp_path, capsys):
    # a scene file without any light, lit from the command line: a point light over a Lambert ground
    path = tmp_path / "dark.toml"
    path.write_text(
        "[camera]\norigin = [0, 2, 4]\ntarget = [0, 0, 0]\nresolution = [12, 8]\n"
        '[materials.grey]\ntype = "lambert"\n[[objects]]\ntype = "ground"\nmaterial = "grey"\n'
    )
    out = tmp_path / "lamp.pfm"
    args = ["render", str(path), "-o", str(out), "--spp", "2", "-q"]
    assert main([*args, "--light", "point:0,1,0:4", "--light", "spot:1,2,0:0,0,0:5,5,4:25:20"]) == 0
    assert "1 point light + 1 spot light" in capsys.readouterr().err
    meta = json.loads((tmp_path / "lamp.pfm.json").read_text())
    # counted by kind: no surface light, one of each delta light
    assert (meta["area_lights"], meta["point_lights"], meta["spot_lights"], meta["lights"]) == (0, 1, 1, 2)
    assert read_image(out).min() > 0  # the point light reaches every visible point of the ground


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("lamp:0,1,0:4", "expected 'point:X,Y,Z:I'"),
        ("point:0,1:4", "the position must be 3 numbers"),
        ("point:0,1,0:-4", "intensity must be"),
        ("spot:0,1,0:0,1,0:4", "target must differ"),
        ("spot:0,1,0:0,0,0:4:120", "cone_angle"),
        ("spot:0,1,0:0,0,0:4:wide", "an angle must be a number"),
        ("directional:0,-1:3", "the direction must be 3 numbers"),
        ("directional:0,0,0:3", "direction must not be zero"),
        ("directional:0,-1,0:-3", "irradiance must be"),
        ("directional:0,-1,0:3:200", "angle must be"),
        ("directional:0,-1,0:3:0.5:9", "expected 'point:X,Y,Z:I'"),
    ],
)
def test_light_specs_are_checked(capsys, tmp_path, spec, message):
    assert main(["render", "--demo", "--light", spec, "-o", str(tmp_path / "x.exr"), "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("lightprobe: error: --light") and message in err[0], err


def test_a_scene_without_any_light_is_an_error(tmp_path, capsys):
    path = tmp_path / "dark.toml"
    path.write_text(
        "[camera]\norigin = [0, 2, 4]\ntarget = [0, 0, 0]\n"
        '[materials.grey]\ntype = "lambert"\n[[objects]]\ntype = "ground"\nmaterial = "grey"\n'
    )
    assert main(["render", str(path), "-o", str(tmp_path / "x.exr"), "-q"]) == 2
    assert "the scene has no light" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("name", "options", "labels"),
    [
        ("lecture-area-sampling", ["--width", "16"], {"hemisphere-1", "area-16", "solid-angle-16"}),
        ("lecture-many-lights", ["--width", "18", "--lights", "60", "--k", "4"], {"uniform", "power", "bvh"}),
    ],
)
def test_lecture_experiments_write_rows_and_images(capsys, tmp_path, name, options, labels):
    out = tmp_path / name
    args = ["experiment", name, "--spp", "1", "--reference-spp", "8", "--json", "-o", str(out), *options]
    assert main(args) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines() if line.startswith("{")]
    assert labels <= {r["strategy"] for r in rows}
    for r in rows:
        assert r["mse"] > 0 and r["seconds"] > 0 and r["rays"] > 0 and r["mse_ratio_to_best"] >= 1.0
        assert r["efficiency"] == pytest.approx(1 / (r["mse"] * r["seconds"]))
    assert min(r["mse_ratio_to_best"] for r in rows) == 1.0
    assert (out / f"{name}.json").exists() and (out / f"{name}-reference.png").exists()
    assert len(list(out.glob("*.png"))) == len(rows) + 1
    page = (out / "index.html").read_text()
    assert page.count("data:image/png;base64,") == len(rows) + 1 and all(r["strategy"] in page for r in rows)


def test_render_writes_an_object_id_pass_on_request(tmp_path):
    out = tmp_path / "r.exr"
    ids_path = tmp_path / "ids.exr"
    args = ["render", "--demo", "--width", "48", "--spp", "1", "-o", str(out), "-q", "--object-ids", str(ids_path)]
    assert main(args) == 0
    ids = read_image(ids_path)[:, :, 0]
    names = json.loads((tmp_path / "ids.exr.json").read_text())["objects"]
    assert ids.shape == (30, 48) and ids.min() == -1  # the sky
    seen = {int(v) for v in np.unique(ids)} - {-1}
    assert seen and all(0 <= v < len(names) for v in seen) and len(seen) >= 3  # ground, blob, spheres
    assert main(["render", "--demo", "-o", str(out), "--object-ids", str(tmp_path / "ids.png")]) != 0


def test_adaptive_from_the_scene_file_or_the_option(capsys, tmp_path):
    """``adaptive = true`` in [render] (or --adaptive) renders with per-pixel counts; compare refuses it in one line,
    before rendering anything, where it cannot apply: below 4 spp."""
    path = _scene_file(tmp_path, "adaptive = true\nspp = 8")
    assert main(["render", str(path), "-o", str(tmp_path / "a.exr"), "-q"]) == 0
    assert "spp (adaptive, " in capsys.readouterr().err
    meta = json.loads((tmp_path / "a.exr.json").read_text())
    assert meta["adaptive"] is True and meta["spp_done"] == 2
    assert main(["render", str(path), "--no-adaptive", "-o", str(tmp_path / "b.exr"), "-q"]) == 0
    meta = json.loads((tmp_path / "b.exr.json").read_text())
    assert meta["adaptive"] is False and meta["spp_done"] == meta["spp_max"] == 8
    capsys.readouterr()
    # under a time limit the counts are planned to end at it: the line says so, stopped there or not
    assert main(["render", str(path), "--time-limit", "60", "-o", str(tmp_path / "c.exr"), "-q"]) == 0
    assert "(counts planned for the time limit)" in capsys.readouterr().err
    assert main(["compare", str(path), "-o", str(tmp_path / "r.html"), "--spp", "2", "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "adaptive = true" in err[0] and "s.toml" in err[0] and "needs --spp >= 4" in err[0], err
    assert not (tmp_path / "r.html").exists()


def test_every_render_option_with_flags_is_an_option_of_the_render_command():
    """A RenderSettings field that declares command-line flags is on `lightprobe render` (its list is written out
    for the help's order, so a new option could be left off it)."""
    from lightprobe.cli import RENDER_COMMAND_OPTIONS
    from lightprobe.integrators.settings import options

    flagged = {name for name, option in options().items() if option.flags}
    assert flagged == set(RENDER_COMMAND_OPTIONS)


def test_version_and_doctor(capsys):
    """``--version`` prints the version; ``doctor`` names the kernel cache, its size and whether the demo's kernels
    are ready, in one line each."""
    import lightprobe

    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"lightprobe {lightprobe.__version__}"
    assert main(["doctor"]) == 0
    out = capsys.readouterr().out
    rows = dict(line.split(None, 1) if "  " not in line else line.split("  ", 1) for line in out.splitlines())
    assert {"lightprobe", "kernel cache", "cache size", "demo kernels", "cores"} <= {k.strip() for k in rows}
    assert rows["demo kernels"].strip().startswith(("ready", "not compiled yet"))


def test_the_compile_is_shown_stage_by_stage():
    """While a render compiles, each stage of its plan is reported once, in the order Numba starts compiling them,
    with the plan's count; other functions' compiles are not stages."""
    from numba.core import event

    from lightprobe.cli import _stage_compiles
    from lightprobe.demo import demo_scene
    from lightprobe.integrators import pipeline
    from lightprobe.integrators.wavefront import RenderSettings, plan_for

    scene, settings = demo_scene((8, 5)), RenderSettings()
    names = plan_for(scene, settings).stages()
    steps = []
    with _stage_compiles(scene, settings, lambda *step: steps.append(step)):
        for name in ("setup", "setup", "accumulate"):
            body = pipeline.STAGES[pipeline.stage_id(name)].body
            event.start_event("numba:compile", data={"dispatcher": body})
            event.end_event("numba:compile", data={"dispatcher": body})
        event.start_event("numba:compile", data={"dispatcher": pipeline.run_stage})
        event.end_event("numba:compile", data={"dispatcher": pipeline.run_stage})
    assert steps == [(1, len(names), "setup"), (2, len(names), "accumulate")]
