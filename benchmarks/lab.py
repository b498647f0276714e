"""The laboratory's estimator against the render core: what a user technique costs.

Renders the Krivanek exercise's scene (``lightprobe exercise init``; 96x72, 4 BSDF + 4 environment directions per
camera sample) at ``--spp`` samples per pixel with

- ``core``: the render core's MIS (``render``);
- ``lab builtin``: the same techniques, lightprobe's own, through the laboratory's NumPy estimator (``render_lab``);
- ``lab user``: the exercise's reference solutions (``tests/lab/solutions/sampling.py``: Phong lobes, the map's 2D
  distribution, the balance heuristic) through it;

after a warm-up render of each (compiling), one JSON line each: seconds, samples_per_s (camera samples),
directions_per_s, relMSE against a 1024-spp core reference, efficiency 1 / (relMSE x seconds), peak_mb, cores.

    python benchmarks/lab.py [--spp 16]
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
    scene, _ = load_scene(work / "scene.toml")
    solutions = load_module(ROOT / "tests" / "lab" / "solutions" / "sampling.py")
    reference = render(scene, RenderSettings(spp=1024, seed=99, heuristic="balance"))
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
    }
    width, height = scene.camera.resolution
    for name, strategy in forms.items():
        settings = RenderSettings(spp=args.spp, seed=1, heuristic="balance")

        def run(s, strategy=strategy):
            return render(scene, s) if strategy is None else render_lab(scene, strategy, s)

        run(RenderSettings(spp=1, seed=2, heuristic="balance"))  # compile
        start = time.perf_counter()
        result = run(settings)
        seconds = time.perf_counter() - start
        relmse = metrics.relmse(result.image, reference.image)
        samples = width * height * args.spp
        print(json.dumps({
            "form": name, "spp": args.spp, "seconds": round(seconds, 3),
            "samples_per_s": round(samples / seconds), "directions_per_s": round(8 * samples / seconds),
            "relmse": relmse, "efficiency": round(1.0 / (relmse * seconds), 1),
            "peak_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1), "cores": os.cpu_count(),
        }), flush=True)  # fmt: skip


if __name__ == "__main__":
    sys.exit(main())
