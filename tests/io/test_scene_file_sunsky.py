"""``[environment] type = "sunsky"`` in scene files and ``render --sunsky``: the Hosek-Wilkie sky becomes the
scene's environment map and the sun a light of kind ``sun``, with the parameters given; every mistake one line
naming the file and the table."""

from __future__ import annotations

import json

import numpy as np
import pytest

from lightprobe.cli import main
from lightprobe.emitters.hosek_wilkie import sun_position
from lightprobe.emitters.procedural import sun_direction
from lightprobe.emitters.sunsky import SunSky
from lightprobe.errors import SceneError
from lightprobe.io.scene_file import load_scene

HEAD = (
    "[camera]\norigin = [0, 2, 4]\ntarget = [0, 0, 0]\nresolution = [12, 8]\n"
    '[materials.grey]\ntype = "lambert"\n[[objects]]\ntype = "ground"\nmaterial = "grey"\n'
)


def _scene(tmp_path, environment: str):
    path = tmp_path / "s.toml"
    path.write_text(HEAD + "[environment]\n" + environment)
    return path


def test_a_sunsky_table_gives_its_parameters_to_the_sky_and_the_sun(tmp_path):
    path = _scene(
        tmp_path,
        'type = "sunsky"\nturbidity = 4.5\nalbedo = [0.1, 0.2, 0.3]\nsun_elevation = 30\nsun_azimuth = 120\n'
        "sun_scale = 2.0\nsky_scale = 0.5\nsun_aperture = 1.0\nwidth = 64\nlimb_darkening = false\n",
    )
    scene, _ = load_scene(path)
    same = SunSky(turbidity=4.5, albedo=[0.1, 0.2, 0.3], sun_elevation=30, sun_azimuth=120, sun_scale=2.0,
                  sky_scale=0.5, sun_aperture=1.0, width=64, limb_darkening=False)  # fmt: skip
    assert scene.environment.resolution == (64, 33)
    np.testing.assert_allclose(scene.environment.kernel.image, same.sky_image(), rtol=1e-6)
    (sun,) = scene.lights
    assert sun.kind == "sun" and sun.turbidity == 4.5 and sun.aperture == 1.0 and sun.scale == 2.0
    assert sun.limb_darkening is False and SunSky(width=8).sun().limb_darkening is True
    np.testing.assert_allclose(sun.radiance, same.sun().radiance, rtol=1e-15)
    np.testing.assert_allclose(sun.sun_direction, sun_direction(30, 120), atol=1e-12)
    assert "1 sun light" in scene.summary()


def test_a_sunsky_at_a_date_time_and_place(tmp_path):
    scene, _ = load_scene(
        _scene(tmp_path, 'type = "sunsky"\nyear = 2024\nmonth = 1\nday = 3\nhour = 9.25\nlatitude = -33.9\n'
                         "longitude = 18.4\ntimezone = 2.0\nwidth = 32\n")
    )  # fmt: skip
    when = {"year": 2024, "month": 1, "day": 3, "hour": 9.25, "latitude": -33.9, "longitude": 18.4, "timezone": 2.0}
    np.testing.assert_allclose(scene.lights[0].sun_direction, sun_position(**when), atol=1e-15)


def test_a_sunsky_with_a_sun_direction_and_no_sky(tmp_path):
    scene, _ = load_scene(_scene(tmp_path, 'type = "sunsky"\nsun_direction = [1, 1, 0]\nsky_scale = 0\n'))
    assert scene.environment is None
    np.testing.assert_allclose(scene.lights[0].sun_direction, np.array([1, 1, 0]) / np.sqrt(2), atol=1e-12)


@pytest.mark.parametrize(
    ("environment", "message"),
    [
        ('type = "sunsky"\nturbidity = 12\n', "[environment]: sunsky: turbidity must be a number from 1 to 10"),
        ('type = "sunsky"\nturbidity = "clear"\n', "[environment]: turbidity must be a finite number"),
        ('type = "sunsky"\nsun_elevation = -10\n', "below the horizon"),
        ('type = "sunsky"\nsun_direction = [0, -1, 0.2]\n', "below the horizon"),
        ('type = "sunsky"\nsun_direction = [0, 1]\n', "sun_direction must be 3 finite numbers"),
        ('type = "sunsky"\nalbedo = 2\n', "albedo must be a number or"),
        ('type = "sunsky"\nsun_scale = 0\nsky_scale = 0\n', "nothing would emit"),
        ('type = "sunsky"\nsun_aperture = 120\n', "sun_aperture must be"),
        ('type = "sunsky"\nwidth = 4\n', "width must be >= 8"),
        ('type = "sunsky"\nfile = "sky.exr"\n', "unknown key(s) file"),
        ('type = "sky"\nconstant = 1\n', "type must be 'sunsky'"),
        ('type = "sunsky"\nmonth = 7.5\n', "[environment]: month must be an integer"),
        ('type = "sunsky"\nlimb_darkening = "yes"\n', "limb_darkening must be true or false"),
        ('type = "sunsky"\nhour = 12\nsun_elevation = 30\n', "not both"),
        ('type = "sunsky"\nhour = 23\n', "the sun is below the horizon at 2010-07-10 23:00:00"),
    ],
)
def test_sunsky_mistakes_are_one_line(tmp_path, environment, message):
    path = _scene(tmp_path, environment)
    with pytest.raises(SceneError) as info:
        load_scene(path)
    text = str(info.value)
    assert "\n" not in text and text.startswith(f"{path}: [environment]") and message in text, text


def test_render_sunsky_lights_a_scene_without_lights(tmp_path, capsys):
    """The CLI flag as a user would type it: a dark scene lit by the sun and sky, the sidecar counting the sun."""
    path = tmp_path / "dark.toml"
    path.write_text(HEAD)
    out = tmp_path / "sun.pfm"
    assert main(["render", str(path), "-o", str(out), "--spp", "2", "-q", "--sunsky", "40:30:2.5"]) == 0
    assert "1 sun light" in capsys.readouterr().err
    meta = json.loads((tmp_path / "sun.pfm.json").read_text())
    assert (meta["sun_lights"], meta["environment"], meta["area_lights"], meta["lights"]) == (1, True, 0, 2)
    from lightprobe.images import read_image

    image = read_image(out)
    assert np.all(np.isfinite(image)) and image.min() > 0


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ("high", "expected ELEVATION[:AZIMUTH[:TURBIDITY]]"),
        ("40:30:2:1", "expected ELEVATION[:AZIMUTH[:TURBIDITY]]"),
        ("-5", "below the horizon"),
        ("40:0:20", "turbidity must be a number from 1 to 10"),
    ],
)
def test_sunsky_specs_are_checked(capsys, tmp_path, spec, message):
    assert main(["render", "--demo", "--sunsky", spec, "-o", str(tmp_path / "x.exr"), "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("lightprobe: error: --sunsky") and message in err[0], err
