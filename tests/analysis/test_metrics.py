"""Metrics on hand-computed cases, masks from an object-id pass."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lightprobe.analysis import metrics
from lightprobe.analysis.masks import BACKGROUND, object_id_pass
from lightprobe.bsdfs import Lambert
from lightprobe.emitters.envmap import EnvironmentMap
from lightprobe.emitters.procedural import constant
from lightprobe.errors import ParameterError
from lightprobe.geometry.camera import Camera
from lightprobe.geometry.shapes import Rectangle, Sphere
from lightprobe.scene import Scene

REF = np.ones((2, 2, 3))
IMG = REF + np.array([[0.0, 0.1], [0.2, -0.3]])[:, :, None]  # the same error in every channel


def test_mse_relmse_psnr_by_hand():
    squares = [0.0, 0.01, 0.04, 0.09]
    assert metrics.mse(IMG, REF) == pytest.approx(np.mean(squares))  # 0.035
    assert metrics.relmse(IMG, REF) == pytest.approx(np.mean(squares) / 1.01)
    assert metrics.relmse(IMG, REF, epsilon=0.0) == pytest.approx(0.035)
    assert metrics.psnr(IMG, REF) == pytest.approx(10 * math.log10(1 / 0.035))
    assert metrics.psnr(IMG, REF, peak=2.0) == pytest.approx(10 * math.log10(4 / 0.035))
    assert metrics.psnr(REF, REF) == math.inf
    mask = np.array([[False, True], [False, False]])
    assert metrics.mse(IMG, REF, mask) == pytest.approx(0.01)
    assert metrics.relmse(IMG, REF, mask) == pytest.approx(0.01 / 1.01)


def test_efficiency_and_mean_variance():
    assert metrics.efficiency(0.5, 2.0) == 1.0
    assert metrics.efficiency(0.01, 4.0) == pytest.approx(25.0)
    var = np.zeros((2, 2, 3))
    var[1, 1] = 0.4
    assert metrics.mean_variance(var) == pytest.approx(0.1)
    assert metrics.mean_variance(var, np.array([[False, False], [False, True]])) == pytest.approx(0.4)
    with pytest.raises(ParameterError, match="efficiency needs"):
        metrics.efficiency(0.0, 1.0)


def test_bias_and_its_interval():
    image = REF + 0.1
    var = np.full(REF.shape, 0.12)  # 12 values: se = sqrt(12 x 0.12) / 12 = 0.1
    b = metrics.bias(image, REF, var)
    assert b.estimate == pytest.approx(0.1)
    assert b.standard_error == pytest.approx(0.1)
    assert (b.low, b.high) == pytest.approx((0.1 - 1.959964 * 0.1, 0.1 + 1.959964 * 0.1), rel=1e-5)
    assert not b.significant
    tight = metrics.bias(image, REF, var / 100, confidence=0.99)
    assert tight.significant and tight.low > 0
    both = metrics.bias(image, REF, var, reference_variance=var)
    assert both.standard_error == pytest.approx(0.1 * math.sqrt(2))


def test_flip_is_zero_for_identical_images_and_grows_with_error():
    rng = np.random.default_rng(0)
    ref = rng.random((32, 32, 3)).astype(np.float32)
    assert metrics.flip(ref, ref) == pytest.approx(0.0, abs=1e-6)
    small = metrics.flip(ref * 1.05, ref)
    large = metrics.flip(ref * 2.0, ref)
    assert 0 < small < large
    half = ref.copy()
    half[:, 16:] *= 3.0  # errors on the right half only; FLIP's filters spread them over a few pixels
    left = np.zeros((32, 32), bool)
    left[:, :8] = True
    right = np.zeros((32, 32), bool)
    right[:, 24:] = True
    assert metrics.flip(half, ref, left) < 0.01 < 0.05 < metrics.flip(half, ref, right)


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: metrics.mse(np.ones((2, 3, 3)), REF), "differ in size"),
        (lambda: metrics.mse(IMG, REF, np.zeros((2, 2), bool)), "selects no pixel"),
        (lambda: metrics.mse(IMG, REF, np.zeros((3, 2), bool)), "does not match"),
        (lambda: metrics.relmse(IMG * np.nan, REF), "NaN or infinite"),
        (lambda: metrics.psnr(IMG, REF * 0), "positive peak"),
        (lambda: metrics.bias(IMG, REF, -np.ones(REF.shape)), ">= 0"),
        (lambda: metrics.bias(IMG, REF, REF, confidence=1.5), "confidence"),
    ],
)
def test_bad_input_names_the_problem(call, message):
    with pytest.raises(ParameterError, match=message):
        call()


def test_object_id_pass_and_masks():
    scene = Scene(Camera([0, 0, 4], [0, 0, 0], fov=40, resolution=(24, 16)), EnvironmentMap.from_array(constant(1)))
    scene.add(Rectangle([-10, -1, 10], [20, 0, 0], [0, 0, -20]), Lambert(0.5), name="ground")
    scene.add(Sphere([0, 0, 0], 0.6), Lambert(0.5), name="ball")
    ids, names = object_id_pass(scene)
    assert names == ["ground", "ball"] and ids.shape == (16, 24)
    assert ids[8, 12] == 1  # the ball in the centre
    assert ids[15, 12] == 0  # the ground at the bottom
    assert ids[0, 0] == BACKGROUND  # the sky at the top
    ball = metrics.object_mask(ids, "ball", names)
    assert ball.sum() == (ids == 1).sum() > 0
    with pytest.raises(ParameterError, match="no object named"):
        metrics.object_mask(ids, "table", names)
