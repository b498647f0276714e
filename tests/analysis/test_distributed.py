"""Sample ranges on a Dask LocalCluster merge to the single-process render."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

pytest.importorskip("distributed", reason="Dask distributed is not installed (pip install -e '.[test]')")

from lightprobe.analysis.distributed import render_on_dask, sample_ranges
from lightprobe.errors import LightprobeError
from lightprobe.integrators.wavefront import RenderSettings, render


def test_adaptive_counts_are_refused_for_sample_ranges():
    from ..integrators.test_wavefront import small_scene

    with pytest.raises(LightprobeError, match="cannot take adaptive counts"):
        render_on_dask(small_scene((4, 3)), RenderSettings(spp=16, adaptive=True), chunk=4)


def test_sample_ranges_cover_exactly():
    assert sample_ranges(10, 4) == [(0, 4), (4, 4), (8, 2)]
    assert sample_ranges(5, 8, first=3) == [(3, 5)]
    with pytest.raises(LightprobeError, match="must be >= 1"):
        sample_ranges(0, 4)


def test_a_local_cluster_reference_equals_the_single_process_render():
    from ..integrators.test_wavefront import small_scene

    scene = small_scene((16, 12))
    # 16 spp, adaptive left automatic: a plain render would take adaptive counts, the ranges take uniform ones
    settings = RenderSettings(spp=16, seed=2)
    whole = render(scene, dataclasses.replace(settings, adaptive=False))
    merged = render_on_dask(scene, settings, chunk=5, workers=2)  # 4 ranges on 2 worker processes
    assert merged.stats["ranges"] == 4
    np.testing.assert_array_equal(merged.counts, whole.counts)
    np.testing.assert_allclose(merged.accumulator.mean, whole.accumulator.mean, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(merged.accumulator.m2, whole.accumulator.m2, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(merged.image, whole.image, rtol=1e-6, atol=1e-9)


def test_an_unreachable_scheduler_is_one_clear_error():
    from ..integrators.test_wavefront import small_scene

    with pytest.raises(LightprobeError, match=r"cannot reach the Dask scheduler at tcp://127\.0\.0\.1:9"):
        render_on_dask(small_scene((4, 4)), RenderSettings(spp=2), scheduler="tcp://127.0.0.1:9", connect_timeout=2)


def test_reference_command_on_a_local_cluster_resumes_a_checkpoint(tmp_path):
    """Half the reference in one process, the rest on Dask: the merged image equals one uninterrupted render."""
    from lightprobe.cli import main
    from lightprobe.images import read_image
    from lightprobe.io.scene_file import load_scene

    from .test_reference import SCENE

    scene_file = tmp_path / "scene.toml"
    scene_file.write_text(SCENE)
    out = tmp_path / "ref.exr"
    args = ["reference", str(scene_file), "-o", str(out), "--chunk", "2", "--seed", "4"]
    assert main([*args, "--spp", "4"]) == 0
    assert main([*args, "--spp", "10", "--dask", "--workers", "2"]) == 0
    scene, _ = load_scene(scene_file)
    whole = render(scene, RenderSettings(spp=10, seed=4, adaptive=False))
    image = read_image(out)
    np.testing.assert_allclose(image[:, :, :3], whole.image, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(image[:, :, 3:6], whole.variance, rtol=1e-4, atol=1e-12)


def test_a_lost_worker_loses_only_its_task():
    """SIGKILL one worker process while it renders a range: Dask re-runs that range, the merge is unchanged."""
    import os
    import signal
    import time

    from distributed import Client, LocalCluster

    from lightprobe.analysis.distributed import _render_range
    from lightprobe.integrators.wavefront import Accumulator

    from ..integrators.test_wavefront import small_scene

    scene = small_scene((32, 24))
    settings = RenderSettings(spp=48, seed=6, threads=1)
    whole = render(scene, dataclasses.replace(settings, adaptive=False))
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        with Client(cluster) as client:
            pids = client.run(os.getpid)
            futures = [client.submit(_render_range, scene, settings, a, n) for a, n in sample_ranges(48, 8)]
            deadline = time.time() + 120
            victim = None
            while victim is None and time.time() < deadline:
                busy = [address for address, keys in client.processing().items() if keys]
                victim = busy[0] if busy else None
                time.sleep(0.02)
            assert victim is not None
            os.kill(pids[victim], signal.SIGKILL)
            parts = client.gather(futures)
    acc = None
    for arrays, _ in parts:
        part = Accumulator.from_arrays(arrays)
        acc = part if acc is None else acc.merged(part)
    np.testing.assert_array_equal(acc.count, whole.accumulator.count)
    np.testing.assert_allclose(acc.mean, whole.accumulator.mean, rtol=1e-12, atol=1e-15)
