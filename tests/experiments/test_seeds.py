"""The seeds' comparisons as commands: rows, one report per cell, an index, and the claims they are about."""

from __future__ import annotations

import json

from lightprobe.cli import main


def _rows(folder):
    return [json.loads(line) for line in (folder / "rows.json").read_text().splitlines()]


def test_pbrt_envmap_vs_cosine(tmp_path, capsys):
    out = tmp_path / "pbrt"
    args = ["experiment", "pbrt-envmap-vs-cosine", "--maps", "sky-sun,sky", "--width", "32", "--spp", "16"]
    assert main([*args, "--reference-spp", "256", "-o", str(out), "--json"]) == 0
    rows = _rows(out)
    assert {(r["map"], r["strategy"]) for r in rows} == {(m, s) for m in ("sky-sun", "sky") for s in ("cosine", "env")}
    assert (out / "index.html").exists() and all((out / r["report"]).exists() for r in rows)
    printed = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert printed == rows
    mse = {(r["map"], r["strategy"]): r["mse"] for r in rows}
    # pbrt's point: importance sampling the map pays under a spiky map (by orders of magnitude here) and not under
    # a soft one, where the cosine is the larger factor of the integrand
    assert mse[("sky-sun", "cosine")] > 100 * mse[("sky-sun", "env")]
    assert mse[("sky", "cosine")] < 2 * mse[("sky", "env")]


def test_krivanek_mis(tmp_path):
    out = tmp_path / "krivanek"
    args = ["experiment", "krivanek-mis", "--maps", "sky-sun", "--exponents", "1,1000", "--width", "32"]
    assert main([*args, "--spp", "64", "--reference-spp", "2048", "-o", str(out), "--json"]) == 0
    mse = {(r["material"], r["strategy"]): r["mse"] for r in _rows(out)}
    # broad lobe under a spiky map: sampling the map wins by orders of magnitude (at n = 1000 the 2-degree sun is
    # as wide as the lobe, and neither technique dominates: both are rows of the table)
    assert mse[("phong n=1", "env")] < 0.01 * mse[("phong n=1", "brdf")]
    # MIS stays near the better technique; asserted where one image's MSE is a stable measure (at n = 1000 a few
    # pixels where the sun's reflection is hit or missed dominate each technique's MSE at this size)
    best = min(mse[("phong n=1", "brdf")], mse[("phong n=1", "env")])
    assert mse[("phong n=1", "mis-balance")] < 3 * best and mse[("phong n=1", "mis-power")] < 3 * best
    assert {m for m, _ in mse} == {"phong n=1", "phong n=1000"} and len(mse) == 8


def test_cells_as_dask_tasks_give_the_same_rows(tmp_path):
    import pytest

    pytest.importorskip("distributed", reason="Dask distributed is not installed")
    common = ["experiment", "pbrt-envmap-vs-cosine", "--maps", "sky-sun,sky", "--width", "16", "--spp", "4"]
    common += ["--reference-spp", "32"]
    assert main([*common, "-o", str(tmp_path / "here")]) == 0
    assert main([*common, "-o", str(tmp_path / "dask"), "--dask", "--workers", "2"]) == 0
    here, there = _rows(tmp_path / "here"), _rows(tmp_path / "dask")
    assert [(r["map"], r["strategy"]) for r in here] == [(r["map"], r["strategy"]) for r in there]
    assert [r["mse"] for r in here] == [r["mse"] for r in there]  # the same renders, bit for bit
    assert all((tmp_path / "dask" / r["report"]).exists() for r in there)
