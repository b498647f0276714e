#!/usr/bin/env python3
"""How long a new user waits for a first image: the README's first command from an empty kernel cache, then a
scene of each further kind, then the same after an edit to one module.

    python benchmarks/first_image.py              # every step (about 3 minutes on 2 cores)
    python benchmarks/first_image.py --steps demo,again

Each step is a separate ``lightprobe render`` process, timed from its start to its exit (the image written), in a
copy of the package's sources (so that the edit step cannot touch the repository) with its own empty Numba cache
(``XDG_CACHE_HOME``): the machine as it is after ``pip install`` (Python's own bytecode compiled, no kernel
compiled). The steps, in order, each reading what the steps before it compiled:

- ``demo``: the README's first command's render, ``lightprobe render --demo -o demo.png`` (issue 60: at most 20 s on
  2 cores);
- ``again``: the same command once more (every kernel loaded from the cache);
- ``area``: ``--demo many-lights`` (area lights: the light-sample stage, the selector, the BSDF rays' nearest hits;
  at most 10 s more);
- ``gltf``: ``examples/gltf_spheres.toml`` (a glTF asset's metallic-roughness material and a spot light);
- ``textured``: ``examples/textured_bunny.toml`` (image textures; needs ``../shared/data`` and the asset from
  ``examples/make_textured_asset.py``: skipped without them);
- ``edit``: a comment added to ``integrators/outlines.py``, then the demo again: only the kernels that import it
  recompile (the setup stage, the stage loop, the outline kernels);
- ``leaf``: a comment added to ``emitters/procedural.py`` (no kernel imports it), then the demo: nothing recompiles.

Printed per step: wall seconds, CPU seconds of the process and its children (the compile helpers), the
"compiled kernels in N s" the command reports, and the machine's cores. Timings on a loaded machine are not
comparable: run it alone.
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STEPS = ("demo", "again", "area", "gltf", "textured", "edit", "leaf")


def _cpu_children() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _run(args: list[str], env: dict, cwd: Path) -> tuple[float, float, str, int]:
    cpu = _cpu_children()
    start = time.perf_counter()
    done = subprocess.run(args, env=env, cwd=cwd, capture_output=True, text=True)
    return time.perf_counter() - start, _cpu_children() - cpu, done.stdout + done.stderr, done.returncode


def _append_comment(path: Path) -> None:
    with path.open("a") as f:
        f.write("\n# an edit (benchmarks/first_image.py)\n")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", default=",".join(STEPS), help=f"comma-separated, of {', '.join(STEPS)}")
    parser.add_argument("--keep", action="store_true", help="keep the temporary folder (printed)")
    args = parser.parse_args()
    steps = [s for s in args.steps.split(",") if s]
    unknown = [s for s in steps if s not in STEPS]
    if unknown:
        parser.error(f"unknown steps {unknown}; the steps are {', '.join(STEPS)}")

    work = Path(tempfile.mkdtemp(prefix="lightprobe-first-image-"))
    src = work / "src"
    shutil.copytree(ROOT / "src", src, ignore=shutil.ignore_patterns("__pycache__", "*.nbi", "*.nbc"))
    examples = ROOT / "examples"  # read only
    env = dict(os.environ, PYTHONPATH=str(src), XDG_CACHE_HOME=str(work / "cache"))
    env.pop("NUMBA_CACHE_DIR", None)
    command = [sys.executable, "-m", "lightprobe"]
    # Python's bytecode compiled before the clock starts, as pip does at install
    subprocess.run([sys.executable, "-m", "compileall", "-q", str(src)], check=True)
    print(f"cores: {os.cpu_count()}; python {sys.version.split()[0]}; sources copied to {src}")
    print(f"{'step':9s} {'wall s':>7s} {'CPU s':>7s} {'compile s':>9s}  command")
    data = ROOT.parent / "shared" / "data"
    failed = 0
    for step in steps:
        out = work / f"{step}.png"
        if step in ("demo", "again", "edit", "leaf"):
            if step == "edit":
                _append_comment(src / "lightprobe" / "integrators" / "outlines.py")
            if step == "leaf":
                _append_comment(src / "lightprobe" / "emitters" / "procedural.py")
            cmd = [*command, "render", "--demo", "-o", str(out)]
        elif step == "area":
            cmd = [*command, "render", "--demo", "many-lights", "-o", str(out)]
        elif step == "gltf":
            cmd = [*command, "render", str(examples / "gltf_spheres.toml"), "--camera", "Front", "-o", str(out)]
        else:
            asset = examples / "assets" / "textured_bunny.glb"
            if not data.is_dir() or not asset.is_file():
                print(f"{step:9s} skipped: needs ../shared/data and examples/make_textured_asset.py's asset")
                continue
            cmd = [*command, "render", str(examples / "textured_bunny.toml"), "-o", str(out)]
        wall, cpu, text, code = _run(cmd, env, ROOT)
        compiled = re.search(r"compiled kernels in ([0-9.]+) s", text)
        shown = " ".join(c if not c.startswith(str(work)) else c.replace(str(work), "TMP") for c in cmd[3:])
        if code != 0:
            failed += 1
            print(f"{step:9s} failed ({code}): {text.strip().splitlines()[-1] if text.strip() else ''}")
            continue
        print(f"{step:9s} {wall:7.1f} {cpu:7.1f} {compiled.group(1) if compiled else '-':>9s}  lightprobe {shown}",
              flush=True)  # fmt: skip
    if args.keep:
        print(f"kept {work}")
    else:
        shutil.rmtree(work, ignore_errors=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
