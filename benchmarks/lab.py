"""The laboratory's estimator against the render core: what a user technique costs.

Renders the Krivanek exercise's scene (``lightprobe exercise init``; 96x72, 8 BSDF + 8 environment directions per
camera sample) at ``--spp`` samples per pixel with

- ``core``: the render core's MIS (``render``);
- ``lab builtin``: the same techniques, lightprobe's own, through the laboratory (``render_lab``; their njit twins,
  so its compiled estimator);
- ``lab user``: the exercise's reference solutions (``tests/lab/solutions/sampling.py``: Phong lobes, the map's 2D
  distribution, the balance heuristic; NumPy, a batch per call) through its NumPy estimator;
- ``lab njit``: the same solutions written as ``numba.njit`` functions (``examples/njit_sampling.py``) through its
  compiled estimator;
- ``lab njit, NumPy heuristic``: those njit techniques with the NumPy balance heuristic, which sends them through the
  NumPy estimator (each technique a batch at a time through its compiled loop);

after a warm-up render of each (compiling), one JSON line each: seconds, samples_per_s (camera samples),
directions_per_s, relMSE against a 1024-spp core reference, efficiency 1 / (relMSE x seconds), peak_mb, cores.

    python benchmarks/lab.py [--spp 16] [--scale 1]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--scale", type=int, default=1, help="render at SCALE times the scene's 96x72 per axis")
    args = parser.parse_args()

    from lightprobe.analysis import metrics
    from lightprobe.integrators.settings import RenderSettings
    from lightprobe.integrators.wavefront import render
    from lightprobe.io.scene_file import load_scene
    from lightprobe.lab.exercise import init_exercise
    from lightprobe.lab.render import LabStrategy, render_lab
    from lightprobe.lab.techniques import GuardedTechnique, builtin, load_module

    work = Path(tempfile.mkdtemp(prefix="lightprobe-lab-bench-"))
    init_exercise(work)
    if args.scale != 1:
        text = (work / "scene.toml").read_text()
        text = text.replace("resolution = [96, 72]", f"resolution = [{96 * args.scale}, {72 * args.scale}]")
        (work / "scene.toml").write_text(text)
    scene, _ = load_scene(work / "scene.toml")
    solutions = load_module(ROOT / "tests" / "lab" / "solutions" / "sampling.py")
    njit = load_module(ROOT / "examples" / "njit_sampling.py")
    reference = render(scene, RenderSettings(spp=1024 // args.scale**2, seed=99, heuristic="balance"))
    forms = {
        "core": None,
        "lab builtin": LabStrategy((builtin("bsdf"), builtin("light")), "balance"),
        "lab user": LabStrategy(
            (
                GuardedTechnique(solutions.PhongLobes(), "PhongLobes"),
                GuardedTechnique(solutions.EnvironmentMapSampler(), "EnvironmentMapSampler"),
            ),
            solutions.balance_heuristic,
        ),
        "lab njit": LabStrategy(
            (
                GuardedTechnique(njit.PhongLobes(), "PhongLobes"),
                GuardedTechnique(njit.EnvironmentMap(), "EnvironmentMap"),
            ),
            njit.balance_heuristic,
        ),
        "lab njit, NumPy heuristic": LabStrategy(
            (
                GuardedTechnique(njit.PhongLobes(), "PhongLobes"),
                GuardedTechnique(njit.EnvironmentMap(), "EnvironmentMap"),
            ),
            solutions.balance_heuristic,
        ),
    }
    width, height = scene.camera.resolution
    for name, strategy in forms.items():
        settings = RenderSettings(spp=args.spp, seed=1, heuristic="balance")

        def run(s, strategy=strategy):
            return render(scene, s) if strategy is None else render_lab(scene, strategy, s)

        start = time.perf_counter()
        run(RenderSettings(spp=1, seed=2, heuristic="balance"))  # compile
        first = time.perf_counter() - start
        start = time.perf_counter()
        result = run(settings)
        seconds = time.perf_counter() - start
        relmse = metrics.relmse(result.image, reference.image)
        samples = width * height * args.spp
        print(json.dumps({
            "form": name, "spp": args.spp, "seconds": round(seconds, 3), "first_1spp_s": round(first, 2),
            "samples_per_s": round(samples / seconds), "directions_per_s": round(8 * samples / seconds),
            "relmse": relmse, "efficiency": round(1.0 / (relmse * seconds), 1),
            "peak_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1), "cores": os.cpu_count(),
        }), flush=True)  # fmt: skip


if __name__ == "__main__":
    sys.exit(main())
