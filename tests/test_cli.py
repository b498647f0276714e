"""The command line on tiny inputs: every command runs, user errors are one line and exit status 2."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from lightprobe.cli import main
from lightprobe.emitters.procedural import sky_with_sun
from lightprobe.io.images import read_image, write_image


@pytest.fixture
def sky(tmp_path):
    return write_image(tmp_path / "sky.exr", sky_with_sun(64, 32, sun_diameter_deg=6.0))


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
    time.sleep(2.0)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    assert "interrupted" in err and out.exists()
    meta = json.loads((tmp_path / "partial.exr.json").read_text())
    assert meta["interrupted"] is True and meta["spp_done"] < 1000000
