"""The Krivanek exercise, packaged: ``lightprobe exercise init DIR`` and ``lightprobe exercise check DIR``.

``init`` copies ``template/`` (``sampling.py``: skeletons with the maths to fill in; ``scene.toml``; ``README.md``)
into a directory. ``check`` grades it step by step, stopping at the first step that is wrong:

1. ``UniformHemisphere``, 2. ``CosineHemisphere``, 3. ``PhongLobes``, 4. ``EnvironmentMapSampler``: each through
   ``lightprobe check`` (:func:`lightprobe.lab.check.check_technique`), its first failing check reported with the
   hint it carries ("the pdf is missing the sin theta of the lat-long Jacobian");
5. ``balance_heuristic`` against n_f p_f / (n_f p_f + n_g p_g) on chosen and random inputs (unequal counts, zero
   pdfs);
6. a render of ``scene.toml`` with the student's Phong and environment techniques under MIS weighted by their
   heuristic (the laboratory's estimator, ``lab/render.py``) against lightprobe's own render at 8x the samples: z =
   (mine - lightprobe's) / sqrt(var_mine + var_lightprobe) over 8 x 8-pixel blocks
   (``analysis.metrics.block_z_test``), pooled and as the share of |z| > 4, from fixed seeds.
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from ...analysis.metrics import block_z_test
from ...errors import LightprobeError
from ...sampling.mis import balance_heuristic
from ..techniques import GuardedTechnique, TechniqueError, load_module

__all__ = ["FILES", "STEPS", "Grade", "Step", "grade", "init_exercise"]

FILES = ("sampling.py", "scene.toml", "README.md")
#: (step, the name in sampling.py)
STEPS = (
    (1, "UniformHemisphere"),
    (2, "CosineHemisphere"),
    (3, "PhongLobes"),
    (4, "EnvironmentMapSampler"),
    (5, "balance_heuristic"),
    (6, "render"),
)
#: the render step: samples per pixel of the student's image and of lightprobe's, and the verdict's bounds
RENDER_SPP, REFERENCE_SPP = 16, 128
#: blocks of BLOCK x BLOCK pixels; the pooled z over them within +-POOLED_Z_LIMIT, at most OUTLIER_SHARE_LIMIT of
#: them with |z| > 4
BLOCK = 8
POOLED_Z_LIMIT, OUTLIER_SHARE_LIMIT = 4.0, 0.05


@dataclass
class Step:
    number: int
    name: str
    passed: bool | None  # None: not run (an earlier step failed)
    message: str


@dataclass
class Grade:
    directory: Path
    steps: list[Step] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return len(self.steps) == len(STEPS) and all(s.passed for s in self.steps)

    def text(self) -> str:
        lines = [f"the Krivanek exercise in {self.directory}"]
        for s in self.steps:
            mark = {True: "ok  ", False: "FAIL", None: "    "}[s.passed]
            lines.append(f"  {mark} step {s.number} ({s.name}): {s.message}")
        failed = next((s for s in self.steps if s.passed is False), None)
        lines.append("all six steps pass" if self.passed else f"step {failed.number} ({failed.name}) is wrong: fix it "
                     "and run `lightprobe exercise check` again" if failed else "incomplete")  # fmt: skip
        return "\n".join(lines)


def init_exercise(directory: str | Path, *, force: bool = False) -> list[Path]:
    """Write the exercise's files into ``directory`` (made if needed); existing files are kept unless ``force``."""
    target = Path(directory)
    if target.exists() and not target.is_dir():
        raise LightprobeError(f"{target}: exists and is not a directory")
    existing = [target / f for f in FILES if (target / f).exists()]
    if existing and not force:
        raise LightprobeError(f"{existing[0]}: already exists (use --force to overwrite the exercise's files)")
    target.mkdir(parents=True, exist_ok=True)
    template = resources.files(__package__) / "template"
    written = []
    for name in FILES:
        with resources.as_file(template / name) as source:
            shutil.copyfile(source, target / name)
        written.append(target / name)
    return written


def grade(directory: str | Path, *, samples: int = 100_000, progress=None) -> Grade:
    """Grade an exercise directory; see the module docstring."""
    root = Path(directory)
    if not (root / "sampling.py").is_file():
        raise LightprobeError(f"{root}: no sampling.py here (make one with `lightprobe exercise init {root}`)")
    module = load_module(root / "sampling.py", what="exercise file")
    result = Grade(root)

    def say(text: str) -> None:
        if progress is not None:
            progress(text)

    techniques = {}
    for number, name in STEPS[:4]:
        say(f"step {number}: checking {name} ...")
        step = _technique_step(module, number, name, samples)
        result.steps.append(step[0])
        techniques[name] = step[1]
        if not step[0].passed:
            return _rest_not_run(result)
    say("step 5: testing balance_heuristic ...")
    result.steps.append(_heuristic_step(module))
    if not result.steps[-1].passed:
        return _rest_not_run(result)
    say(f"step 6: rendering scene.toml ({RENDER_SPP} spp with your techniques, {REFERENCE_SPP} with lightprobe's) ...")
    result.steps.append(_render_step(root, techniques, module.balance_heuristic))
    return result


def _rest_not_run(result: Grade) -> Grade:
    for number, name in STEPS[len(result.steps) :]:
        result.steps.append(Step(number, name, None, "not run (an earlier step is wrong)"))
    return result


def _technique_step(module, number: int, name: str, samples: int) -> tuple[Step, GuardedTechnique | None]:
    from ..check import check_technique

    obj = getattr(module, name, None)
    if obj is None:
        return Step(number, name, False, f"sampling.py has no {name} (the exercise's files name it)"), None
    try:
        tech = GuardedTechnique(obj() if isinstance(obj, type) else obj, f"sampling.py:{name}")
        report = check_technique(tech, samples=samples)
    except TechniqueError as exc:
        return Step(number, name, False, _plain(str(exc))), None
    failure = report.first_failure
    if failure is None:
        checks = sorted({i.name for i in report.items})
        return Step(number, name, True, f"{len(report.items)} checks passed ({', '.join(checks)})"), tech
    return Step(number, name, False, f"{failure.name} ({failure.context}): {_plain(failure.message)}"), None


def _plain(message: str) -> str:
    """A skeleton's NotImplementedError as 'not written yet'."""
    if "raised NotImplementedError" in message:
        what = message.split(" raised NotImplementedError")[0].split(":")[-1]
        return f"{what} is not written yet (it raises NotImplementedError; fill in its TODO)"
    return message


def _heuristic_step(module) -> Step:
    fn = getattr(module, "balance_heuristic", None)
    name = "balance_heuristic"
    if fn is None:
        return Step(5, name, False, "sampling.py has no balance_heuristic")
    rng = np.random.default_rng(5)
    p_f = np.concatenate([[0.0, 0.0, 1.0, 0.3, 2.0], rng.random(200) * 10.0])
    p_g = np.concatenate([[0.0, 1.0, 0.0, 0.6, 2.0], rng.random(200) * 10.0])
    for n_f, n_g in ((1, 1), (4, 1), (1, 3)):
        expected = balance_heuristic(p_f, p_g, n_f=n_f, n_g=n_g)
        try:
            got = np.asarray(fn(n_f, p_f.copy(), n_g, p_g.copy()), dtype=np.float64)
        except NotImplementedError:
            return Step(5, name, False, "balance_heuristic is not written yet (it raises NotImplementedError)")
        except (Exception, SystemExit) as exc:  # a sys.exit() in the student's code must not end lightprobe
            return Step(5, name, False, f"balance_heuristic({n_f}, p_f, {n_g}, p_g) raised {type(exc).__name__}: {exc}")
        if got.shape != p_f.shape:
            return Step(5, name, False, f"balance_heuristic returned shape {got.shape}, expected {p_f.shape}")
        bad = ~np.isclose(got, expected, rtol=1e-9, atol=1e-12) | ~np.isfinite(got)
        if bad.any():
            i = int(np.argmax(bad))
            return Step(5, name, False, f"balance_heuristic({n_f}, {p_f[i]:.4g}, {n_g}, {p_g[i]:.4g}) returned "
                        f"{got[i]:.6g}, expected {expected[i]:.6g} (n_f p_f / (n_f p_f + n_g p_g), 0 where both pdfs "
                        "are 0)")  # fmt: skip
    return Step(5, name, True, "equal to n_f p_f / (n_f p_f + n_g p_g) on 615 inputs (zero pdfs, unequal counts)")


def _render_step(root: Path, techniques: dict, heuristic) -> Step:
    from ...integrators.settings import RenderSettings
    from ...integrators.wavefront import render
    from ...io.scene_file import load_scene
    from ..render import LabRenderError, LabStrategy, render_lab

    name = "render"
    scene, _ = load_scene(root / "scene.toml")
    strategy = LabStrategy((techniques["PhongLobes"], techniques["EnvironmentMapSampler"]), heuristic)
    try:
        mine = render_lab(scene, strategy, RenderSettings(spp=RENDER_SPP, seed=11))
    except LabRenderError as exc:
        return Step(6, name, False, str(exc))
    theirs = render(scene, RenderSettings(spp=REFERENCE_SPP, seed=12, heuristic="balance"))
    verdict = block_z_test(mine.image, mine.variance, theirs.image, theirs.variance, block=BLOCK)
    text = (
        f"{verdict['blocks']} blocks of {BLOCK}x{BLOCK} pixels: pooled z {verdict['pooled_z']:+.2f} (limit "
        f"{POOLED_Z_LIMIT:g}), |z| > 4 in {verdict['outliers']:.1%} (limit {OUTLIER_SHARE_LIMIT:.0%}); "
        f"image means {verdict['image_mean']:.5f} "
        f"(yours) and {verdict['reference_mean']:.5f} (lightprobe's)"
    )
    if abs(verdict["pooled_z"]) > POOLED_Z_LIMIT or verdict["outliers"] > OUTLIER_SHARE_LIMIT:
        side = "brighter" if verdict["pooled_z"] > 0 else "darker"
        return Step(6, name, False, f"your image is {side} than lightprobe's: {text}; with every technique passing "
                    "its checks, look at how the render combines them: the heuristic's counts n_f and n_g")  # fmt: skip
    return Step(6, name, True, f"your image matches lightprobe's: {text}")
