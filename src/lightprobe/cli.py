"""The ``lightprobe`` command.

User errors (a missing file, a bad parameter) print one line, ``lightprobe: error: ...``, and exit with status 2;
warnings print one line each.  Run ``lightprobe --help`` or ``lightprobe COMMAND --help`` for the options.
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
import time
import warnings
from pathlib import Path
from typing import Annotated

import typer

from .errors import LightprobeError

# Help texts are plain text: they give defaults in brackets ("Random seed [0]."), which Rich markup would take for
# tags and drop ("Random seed .").
PLAIN_HELP = None

app = typer.Typer(
    rich_markup_mode=PLAIN_HELP,
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    help="Monte Carlo image-based lighting with verified importance sampling.",
)
experiment_app = typer.Typer(
    rich_markup_mode=PLAIN_HELP, no_args_is_help=True, help="Reproduce the seed documents' measurements."
)
envmap_app = typer.Typer(
    rich_markup_mode=PLAIN_HELP, no_args_is_help=True, help="Inspect and convert environment maps."
)
exercise_app = typer.Typer(
    rich_markup_mode=PLAIN_HELP, no_args_is_help=True, help="The Krivanek exercise: write the sampling, get it graded."
)


def _print_version(value: bool) -> None:
    if value:
        from . import __version__

        typer.echo(f"lightprobe {__version__}")
        raise typer.Exit(0)


@app.callback()
def _options(
    version: Annotated[
        bool,
        typer.Option("--version", callback=_print_version, is_eager=True, help="Print lightprobe's version and exit."),
    ] = False,
) -> None:
    """Monte Carlo image-based lighting with verified importance sampling."""


app.add_typer(experiment_app, name="experiment")
app.add_typer(envmap_app, name="envmap")
app.add_typer(exercise_app, name="exercise")

# options shared by the experiment commands (one declaration, one help text)
SeedOption = Annotated[int, typer.Option(help="Random seed.")]
JsonOption = Annotated[bool, typer.Option("--json", help="Print JSON rows instead of a table.")]
CellSppOption = Annotated[int, typer.Option(help="Samples per pixel of each strategy.")]
CellReferenceSppOption = Annotated[int, typer.Option(help="Samples per pixel of each cell's MIS reference.")]
CellWidthOption = Annotated[int, typer.Option(help="Image width (height 3/4 of it).")]
CellDaskOption = Annotated[bool, typer.Option("--dask", help="Run the cells as tasks on a Dask LocalCluster.")]
CellSchedulerOption = Annotated[str | None, typer.Option(help="Run the cells on this Dask scheduler.")]
WorkersOption = Annotated[int, typer.Option(help="Worker processes of the --dask LocalCluster.")]


def _check_sizes(spp: int, reference_spp: int, width: int) -> None:
    if spp < 1 or reference_spp < 1 or width < 4:
        raise LightprobeError("--spp and --reference-spp must be >= 1 and --width >= 4")


def _dask_backend(dask: bool, scheduler: str | None) -> str | None:
    """Where Dask work goes: a scheduler's address, "local" for a LocalCluster of our own, or None (in-process)."""
    return scheduler or ("local" if dask else None)


def _split(text: str) -> list[str]:
    return [t.strip() for t in text.split(",") if t.strip()]


_OPTION_TYPES = {"integer": int, "number": float, "string": str, "true or false": bool}


def render_options(*names: str):
    """Give a command the options of :class:`~lightprobe.integrators.settings.RenderSettings` fields ``names``,
    each from its one declaration (flags, type, help with its default), as ``None`` when not given; the command
    receives them as a dict, ``render_options`` (field name -> value)."""
    import functools
    import inspect

    from .integrators.settings import RenderSettings, options

    declared = options()
    defaults = RenderSettings()

    def parameter(name: str) -> inspect.Parameter:
        o = declared[name]
        default = o.auto if o.auto is not None else getattr(defaults, name)
        shown = str(default).lower() if isinstance(default, bool) else default
        annotation = Annotated[
            _OPTION_TYPES[o.kind] | None, typer.Option(*o.flags, help=f"{o.help} [{shown}].", show_default=False)
        ]
        return inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=None, annotation=annotation)

    def decorate(command):
        import typing

        signature = inspect.signature(command)
        hints = typing.get_type_hints(command, include_extras=True)  # this module's annotations are strings
        own = [
            p.replace(annotation=hints.get(p.name, p.annotation))
            for p in signature.parameters.values()
            if p.name != "render_options"
        ]

        @functools.wraps(command)
        def wrapper(**kwargs):
            chosen = {name: kwargs.pop(name) for name in names}
            return command(**kwargs, render_options=chosen)

        wrapper.__signature__ = signature.replace(parameters=[*own, *(parameter(n) for n in names)])
        return wrapper

    return decorate


#: the options of `lightprobe render`, as RenderSettings declares them
RENDER_COMMAND_OPTIONS = (
    "spp",
    "strategy",
    "heuristic",
    "n_bsdf",
    "n_env",
    "seed",
    "sampler",
    "env_candidates",
    "mis_compensation",
    "light_sampler",
    "lights_per_sample",
    "light_strategy",
    "time_limit",
    "adaptive",
    "outline_control_variate",
    "threads",
)


LIGHT_SPECS = "'point:X,Y,Z:I', 'spot:X,Y,Z:TX,TY,TZ:I[:ANGLE[:START]]' or 'directional:DX,DY,DZ:E[:ANGLE]'"


def _parse_light(spec: str):
    """A PointLight, SpotLight or DirectionalLight from ``--light``'s :data:`LIGHT_SPECS`."""
    from .emitters.directional import DirectionalLight
    from .emitters.punctual import PointLight, SpotLight

    fields = spec.split(":")

    def numbers(text, count, what):
        try:
            values = [float(x) for x in text.split(",")]
        except ValueError:
            values = []
        if len(values) not in count:
            wanted = {(3,): "3 numbers", (1,): "a number", (1, 3): "a number or 3 numbers"}[count]
            raise LightprobeError(f"--light {spec!r}: {what} must be {wanted}")
        return values if len(values) > 1 else values[0]

    kind = fields[0]
    try:
        if kind == "point" and len(fields) == 3:
            return PointLight(numbers(fields[1], (3,), "the position"), numbers(fields[2], (1, 3), "the intensity"))
        if kind == "directional" and 3 <= len(fields) <= 4:
            return DirectionalLight(
                numbers(fields[1], (3,), "the direction"),
                numbers(fields[2], (1, 3), "the irradiance"),
                angle=numbers(fields[3], (1,), "an angle") if len(fields) == 4 else 0.0,
            )
        if kind == "spot" and 4 <= len(fields) <= 6:
            angles = [numbers(f, (1,), "an angle") for f in fields[4:]]
            return SpotLight(
                numbers(fields[1], (3,), "the position"),
                numbers(fields[2], (3,), "the target"),
                numbers(fields[3], (1, 3), "the intensity"),
                cone_angle=angles[0] if angles else 30.0,
                falloff_start=angles[1] if len(angles) > 1 else None,
            )
    except LightprobeError as exc:
        message = str(exc)
        raise LightprobeError(message if message.startswith("--light") else f"--light {spec!r}: {message}") from None
    raise LightprobeError(f"--light {spec!r}: expected {LIGHT_SPECS}")


SUNSKY_SPEC = "ELEVATION[:AZIMUTH[:TURBIDITY]]"


def _parse_sunsky(spec: str):
    """A :class:`~lightprobe.emitters.sunsky.SunSky` from ``--sunsky``'s :data:`SUNSKY_SPEC` (degrees; azimuth 0
    and turbidity 3 when left out)."""
    from .emitters.sunsky import SunSky

    fields = spec.split(":")
    try:
        values = [float(x) for x in fields]
    except ValueError:
        values = []
    if not 1 <= len(values) <= 3:
        raise LightprobeError(f"--sunsky {spec!r}: expected {SUNSKY_SPEC}, numbers (degrees; turbidity 1-10)")
    names = ("sun_elevation", "sun_azimuth", "turbidity")
    try:
        return SunSky(**dict(zip(names, values, strict=False)))
    except LightprobeError as exc:
        raise LightprobeError(f"--sunsky {spec!r}: {exc}") from None


@app.command("render")
@render_options(*RENDER_COMMAND_OPTIONS)
def render_command(
    scene_file: Annotated[Path | None, typer.Argument(metavar="SCENE", help="Scene file (TOML).")] = None,
    output: Annotated[Path, typer.Option("--output", "-o", help=".exr, .hdr, .pfm or .png.")] = Path("render.exr"),
    demo: Annotated[
        bool,
        typer.Option(
            "--demo", help="Render a built-in scene (no files needed): the default one, or `--demo many-lights`."
        ),
    ] = False,
    light: Annotated[
        list[str] | None,
        typer.Option(
            "--light",
            metavar="SPEC",
            help="Add a point light 'point:X,Y,Z:I', a spot light 'spot:X,Y,Z:TX,TY,TZ:I[:ANGLE[:START]]' aimed "
            "at (TX, TY, TZ) (I a number or R,G,B in W/sr; angles in degrees, ANGLE 30, START ANGLE - 5) or a "
            "directional light 'directional:DX,DY,DZ:E[:ANGLE]' shining along (DX, DY, DZ) with irradiance E "
            "(W/m^2) from a disc ANGLE degrees wide (0: a delta light, the default); repeatable.",
        ),
    ] = None,
    sunsky: Annotated[
        str | None,
        typer.Option(
            "--sunsky",
            metavar=SUNSKY_SPEC,
            help="Light the scene by the Hosek-Wilkie sun and sky (Mitsuba 3's sunsky with complex_sun), the sun "
            "ELEVATION degrees up at lat-long AZIMUTH (0: toward -Z, 90: toward +X; default 0) and TURBIDITY 1-10 "
            "(default 3); it replaces the scene's environment (and a sunsky's sun).  Scene files: [environment] "
            'type = "sunsky".',
        ),
    ] = None,
    width: Annotated[int | None, typer.Option(help="Override the image width (height keeps the aspect).")] = None,
    variance: Annotated[bool, typer.Option(help="Add variance.R/G/B channels to an EXR.")] = False,
    exposure: Annotated[float, typer.Option(help="PNG exposure in stops.")] = 0.0,
    png: Annotated[Path | None, typer.Option(help="Also write a tone-mapped PNG preview here.")] = None,
    object_ids: Annotated[
        Path | None,
        typer.Option(help="Also write an object-id pass here (.exr, channel object_id; -1 = background)."),
    ] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar.")] = False,
    camera: Annotated[
        str | None,
        typer.Option(help="Render from this camera of the scene's glTF objects (keeps the resolution)."),
    ] = None,
    techniques: Annotated[
        str | None,
        typer.Option(
            help="Render with your own sampling techniques (lightprobe.lab): FILE.py[:NAME] alone, or "
            "mis:FILE.py[:NAME][+FILE.py[:NAME]] under MIS with lightprobe's technique of the other kind "
            "(scenes lit by an environment map alone); or your light selector, sel:FILE.py[:NAME] (select(ctx, "
            "u), pmf(ctx, light); scenes of two lights or more), or lightprobe's: sel:uniform, sel:power, sel:bvh."
        ),
    ] = None,
    render_options: dict | None = None,
) -> None:
    """Render a scene (or a built-in demo) with direct illumination from its environment map and lights.  A
    rendering option left out takes the scene file's [render] value, else the default shown."""
    from .integrators.wavefront import render
    from .io.outputs import check_output, write_render

    if not demo and scene_file is None:
        raise LightprobeError("give a SCENE file or --demo [NAME]")
    lamps = [_parse_light(spec) for spec in light or []]
    sky = _parse_sunsky(sunsky) if sunsky is not None else None
    check_output(output, variance=variance, png=png)
    if object_ids is not None and object_ids.suffix.lower() != ".exr":
        raise LightprobeError(f"{object_ids}: the object-id pass is written as .exr")
    if techniques is None:  # a first render on this machine: its compile helpers start while the scene is built
        from .integrators import precompile

        precompile.prestart()
    if demo:
        from .demo import DEMOS

        name = "default" if scene_file is None else str(scene_file)
        if name not in DEMOS:
            raise LightprobeError(f"unknown demo {name!r}; the demos are {', '.join(DEMOS)}")
        scene, defaults = DEMOS[name](), {}
    else:
        from .io.scene_file import load_scene

        scene, defaults = load_scene(scene_file, require_light=not lamps and sky is None)
    for lamp in lamps:
        scene.add_light(lamp)
    if sky is not None:
        scene.lights = [x for x in scene.lights if x.kind != "sun"]
        scene.environment = sky.environment()
        if (sun := sky.sun()) is not None:
            scene.add_light(sun)
    if camera is not None:
        if camera not in scene.cameras:
            known = ", ".join(scene.cameras) or "none (no glTF object has one)"
            raise LightprobeError(f"--camera {camera!r}: no such camera; the scene's glTF cameras: {known}")
        scene.camera = scene.cameras[camera].camera(camera, scene.camera.resolution)
    if width is not None:
        if width < 1:
            raise LightprobeError(f"--width must be >= 1, got {width}")
        w, h = scene.camera.resolution
        scene.camera = scene.camera.with_resolution(width, max(1, round(h * width / w)))
    chosen = render_options
    settings = _render_settings(defaults, chosen)
    check_output(output, variance=variance, png=png, resolution=scene.camera.resolution)
    typer.echo(scene.summary(), err=True)
    if techniques is not None:
        from .lab.render import LabRenderError

        render = _lab_renderer(scene, settings, techniques)
        try:
            result = _render_with_progress(
                scene, settings, render, quiet=quiet, core=False, lab_compiles=render.compiles
            )
        except LabRenderError as exc:  # a technique failed mid-render: keep the passes done before it
            if exc.result is None:
                raise
            files = write_render(output, exc.result, variance=variance, exposure=exposure, png=png)
            kept = int(exc.result.counts.min())
            raise LightprobeError(f"{exc}; {files[0]} holds the {kept} spp rendered before it") from None
    else:
        result = _render_with_progress(scene, settings, render, quiet=quiet)
    stats = result.stats
    if not result.counts.any():
        if stats["stopped_by_time_limit"]:  # a user technique's call can outlast the limit in the first pass
            raise LightprobeError(
                f"the time limit ({settings.time_limit:g} s) ran out before the first pass was finished; {output} was "
                "not written"
            )
        raise LightprobeError(f"interrupted before the first sample was taken; {output} was not written")
    files = write_render(output, result, variance=variance, exposure=exposure, png=png)
    if object_ids is not None:
        files += _write_object_ids(object_ids, scene)
    note = ""
    if stats["interrupted"]:
        note = " (interrupted: the image holds the samples accumulated so far)"
    elif stats["adaptive"] and settings.time_limit is not None:
        note = " (counts planned for the time limit)"  # it ends at the limit by design, stopped there or not
    elif stats["stopped_by_time_limit"]:
        note = " (stopped by the time limit)"
    typer.echo(
        f"wrote {', '.join(str(f) for f in files)}: {stats['spp_done']}"
        + (f"-{stats['spp_max']}" if stats["spp_max"] != stats["spp_done"] else "")
        + " spp"
        + (f" (adaptive, {result.counts.mean():.1f} on average)" if stats["adaptive"] else "")
        + (f", {stats['lights_per_sample']} light picks (a probe's choice)" if "picks_probe" in stats else "")
        + f" in {stats['seconds']:.2f} s, {stats['samples_per_s'] / 1e6:.2f} M samples/s, "
        f"{stats['rays_per_s'] / 1e6:.2f} M rays/s{note}",
        err=True,
    )
    if stats["nonfinite_samples"]:
        warnings.warn(f"{stats['nonfinite_samples']} samples were NaN or infinite and counted as 0", stacklevel=1)


@app.command("doctor")
def doctor_command() -> None:
    """What this machine gives lightprobe: versions, cores, the vector kernels, and the compiled-kernel cache (where
    it is, its size, and whether the demo's kernels are ready or its first render will compile them)."""
    import platform

    import numba
    import numpy

    from . import __version__, _numba
    from .geometry.embree import packets_native
    from .integrators.stages import environment_lanes
    from .integrators.wavefront import kernels_cached

    cache = Path(os.environ["NUMBA_CACHE_DIR"])
    files = [p for p in cache.rglob("*") if p.is_file()] if cache.is_dir() else []
    size = sum(p.stat().st_size for p in files)
    rows = [
        ("lightprobe", __version__),
        ("python", f"{platform.python_version()} ({sys.executable})"),
        ("numpy / numba", f"{numpy.__version__} / {numba.__version__}"),
        ("cores", f"{os.cpu_count()} (numba threads {numba.config.NUMBA_NUM_THREADS})"),
        ("vector kernels", "yes" if environment_lanes.compiles() else "no (scalar stages: slower, same images)"),
        ("embree 8-ray packets", "yes" if packets_native() else "no (one shadow ray per call)"),
        ("kernel cache", str(cache)),
        ("cache size", f"{size / 2**20:.1f} MiB in {sum(p.suffix == '.nbc' for p in files)} compiled functions"),
        ("cache rule", "per module and its imports" if _numba.STAMPED_BY_IMPORTS else "one per version of all sources"),
        (
            "demo kernels",
            "ready" if kernels_cached() else "not compiled yet: its first render compiles them (~20 s, 2 cores)",
        ),
    ]
    width = max(len(name) for name, _ in rows)
    for name, value in rows:
        typer.echo(f"{name:<{width}}  {value}")


@app.command("reference")
@render_options("strategy", "seed", "sampler", "time_limit", "threads")
def reference_command(
    scene_file: Annotated[Path, typer.Argument(metavar="SCENE", help="Scene file (TOML).")],
    output: Annotated[Path, typer.Option("--output", "-o", help=".exr (mean and variance).")] = Path("reference.exr"),
    spp: Annotated[int, typer.Option(help="Total samples per pixel of the reference.")] = 1024,
    chunk: Annotated[int, typer.Option(help="Samples per pixel between checkpoints.")] = 16,
    dask: Annotated[bool, typer.Option("--dask", help="Render the chunks on a Dask LocalCluster.")] = False,
    scheduler: Annotated[
        str | None, typer.Option(help="Render the chunks on this Dask scheduler (tcp://host:8786).")
    ] = None,
    workers: WorkersOption = 2,
    quiet: Annotated[
        bool, typer.Option("--quiet", "-q", help="No line per checkpoint (errors and the result only).")
    ] = False,
    render_options: dict | None = None,
) -> None:
    """Render a high-sample reference in checkpointed chunks.  Run the same command again to resume after Ctrl-C,
    a crash or a time limit (bit for bit the same image as an uninterrupted run), or with a larger --spp to extend.
    A rendering option left out takes the scene file's [render] value, else the default shown."""
    from .analysis.reference import checkpoint_path, file_id, render_reference
    from .io.outputs import check_output, write_render
    from .io.scene_file import load_scene

    if output.suffix.lower() != ".exr":
        raise LightprobeError(f"{output}: a reference is written as .exr (mean and variance)")
    check_output(output, variance=True)
    scene, defaults = load_scene(scene_file)
    # a reference is resumable and mergeable by sample range, which per-pixel counts are not
    settings = _render_settings(defaults, {**render_options, "spp": spp, "adaptive": False})
    check_output(output, variance=True, resolution=scene.camera.resolution)
    if not quiet:
        typer.echo(scene.summary(), err=True)
    start = time.perf_counter()

    def chunk_done(done: int, total: int) -> None:
        if not quiet:
            _echo_err(f"{done}/{total} spp, checkpoint written ({time.perf_counter() - start:.1f} s)")

    if workers < 1:
        raise LightprobeError(f"--workers must be >= 1, got {workers}")
    backend = _dask_backend(dask, scheduler)
    result = render_reference(
        scene,
        settings,
        output,
        chunk=chunk,
        scene_id=file_id(scene_file),
        on_chunk=chunk_done,
        dask=backend,
        workers=workers,
    )
    stats = result.stats
    spp_done = int(result.counts.min())
    files = write_render(output, result, variance=True)
    state = "complete" if spp_done >= spp else f"stopped at {spp_done}/{spp} spp; run again to resume"
    _echo_err(
        f"wrote {', '.join(str(f) for f in files)}: {spp_done} spp ({state}; resumed from {stats['resumed_from_spp']}),"
        f" checkpoint {checkpoint_path(output)}"
    )


@app.command("compare")
def compare_command(
    scene_file: Annotated[Path | None, typer.Argument(metavar="SCENE", help="Scene file (TOML).")] = None,
    demo: Annotated[bool, typer.Option("--demo", help="Compare on the built-in demo scene.")] = False,
    strategies: Annotated[
        str,
        typer.Option(
            help="Comma-separated: env, brdf, mis-balance, mis-power, ..., each with /key=value overrides; your "
            "techniques as FILE.py[:NAME] or mis:FILE.py[:NAME][+FILE.py[:NAME]]; lab:mis, lab:brdf, lab:env; "
            "a light selector rendered by the laboratory: sel:FILE.py[:NAME], sel:uniform, sel:power, sel:bvh."
        ),
    ] = "env,brdf,mis-balance,mis-power",
    equal: Annotated[str, typer.Option(help="spp (equal samples) or time (equal seconds).")] = "spp",
    spp: Annotated[int, typer.Option(help="Samples per pixel of each strategy (--equal spp).")] = 64,
    seconds: Annotated[float, typer.Option(help="Seconds of rendering per strategy (--equal time).")] = 10.0,
    reference: Annotated[
        Path | None, typer.Option(help="Reference EXR (e.g. from `lightprobe reference`); else one is rendered.")
    ] = None,
    reference_spp: Annotated[int, typer.Option(help="Samples per pixel of the rendered reference.")] = 1024,
    output: Annotated[Path, typer.Option("--output", "-o", help="The HTML report.")] = Path("report.html"),
    width: Annotated[int | None, typer.Option(help="Override the image width (height keeps the aspect).")] = None,
    seed: Annotated[int, typer.Option(help="Random seed of the strategies.")] = 0,
    as_json: Annotated[bool, typer.Option("--json", help="Also print one JSON line per strategy.")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar.")] = False,
    selector: Annotated[
        list[str] | None,
        typer.Option(
            help="Your light selector, FILE.py[:NAME] (select(ctx, u) -> (light, pmf), pmf(ctx, light)), measured "
            "in the light-choice section against lightprobe's and the oracle; repeat for several."
        ),
    ] = None,
    light_choice_points: Annotated[
        int,
        typer.Option(
            help="Shading points of the light-choice section (the oracle and the split of the variance; scenes "
            "with two or more lights); 0: no section."
        ),
    ] = 512,
) -> None:
    """Render each strategy at equal samples or equal time, measure it against a reference, and write a
    self-contained HTML report (images with synchronised zoom and crops, error maps, convergence, efficiency; on a
    scene with several lights, each light selector against the oracle and where each strategy's variance comes
    from)."""
    import shlex

    from .analysis.report import write_report
    from .experiments.compare import compare
    from .images import read_image
    from .integrators.settings import RenderSettings
    from .integrators.wavefront import render

    if output.suffix.lower() not in (".html", ".htm"):
        raise LightprobeError(f"{output}: the report is an .html file")
    if equal not in ("spp", "time"):
        raise LightprobeError(f"--equal must be spp or time, got {equal!r}")
    if demo or scene_file is None:
        if not demo:
            raise LightprobeError("give a SCENE file or --demo")
        from .demo import DEMOS

        scene, defaults, name = DEMOS["default"](), {}, "demo"
    else:
        from .io.scene_file import load_scene

        scene, defaults = load_scene(scene_file)
        name = str(scene_file)
    if width is not None:
        if width < 1:
            raise LightprobeError(f"--width must be >= 1, got {width}")
        w, h = scene.camera.resolution
        scene.camera = scene.camera.with_resolution(width, max(1, round(h * width / w)))
    adaptive = bool(defaults.get("adaptive"))
    if adaptive and equal == "spp" and spp < 4:
        raise LightprobeError(f"{name}: [render] adaptive = true needs --spp >= 4 (a pilot first), got {spp}")
    base = _render_settings(defaults, {"seed": seed, "spp": 4 if adaptive else 1})
    from .experiments.compare import parse_strategy

    tokens = [t for t in strategies.split(",") if t.strip()]
    for token in tokens:  # a bad token is an error before the reference is rendered, not after
        parse_strategy(token, base, equal, spp)
    if light_choice_points < 0:
        raise LightprobeError(f"--light-choice-points must be >= 0, got {light_choice_points}")
    from .experiments.light_choice import check_selectors
    from .lab.selectors import load_selector

    user_selectors = [load_selector(spec) for spec in selector or []]
    if user_selectors and light_choice_points == 0:
        raise LightprobeError("--selector is measured in the light-choice section: give --light-choice-points > 0")
    check_selectors(scene, user_selectors)  # a selector that breaks its contract fails before anything renders
    w, h = scene.camera.resolution
    if reference is not None:
        ref = read_image(reference)
        if ref.shape[:2] != (h, w):
            raise LightprobeError(f"{reference}: {ref.shape[1]}x{ref.shape[0]} does not match the scene's {w}x{h}")
        ref_image, ref_var = ref[:, :, :3], (ref[:, :, 3:6] if ref.shape[2] >= 6 else None)
    else:
        if reference_spp < 1:
            raise LightprobeError(f"--reference-spp must be >= 1, got {reference_spp}")
        _echo_err(f"rendering the reference: {reference_spp} spp, MIS (use --reference to bring your own) ...")
        ref_settings = RenderSettings(  # uniform, as `lightprobe reference` renders one
            **{**_settings_dict(base), "spp": reference_spp, "seed": seed + 1_000_003, "adaptive": False}
        )
        ref_result = render(scene, ref_settings)
        ref_image, ref_var = ref_result.image, ref_result.variance
    from .analysis.masks import object_id_pass

    ids, names = object_id_pass(scene)
    masks = {f"{i}: {n}": ids == i for i, n in enumerate(names)}
    runs = _compare_with_progress(
        lambda progress: compare(
            scene,
            tokens,
            ref_image,
            ref_var,
            base=base,
            equal=equal,
            spp=spp,
            seconds=seconds,
            progress=progress,
            masks=masks,
        ),
        tokens,
        quiet=quiet,
    )
    command = "lightprobe " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    settings = {
        "scene": name,
        "resolution": [w, h],
        "equal": equal,
        "spp": spp if equal == "spp" else None,
        "seconds": seconds if equal == "time" else None,
        "reference": str(reference) if reference else f"rendered, {reference_spp} spp",
        "strategies": {r.label: _strategy_settings(r.settings) for r in runs},
    }
    budget = f"{spp} spp each" if equal == "spp" else f"{seconds:g} s each"
    choice, choice_error = None, None
    if light_choice_points:
        from .experiments.compare import light_choice
        from .experiments.light_choice import LightChoice

        if not quiet and len(scene.light_table().kind) >= 2:
            _echo_err("measuring the light choice: every light at each of the shading points, by brute force ...")
        try:
            choice = light_choice(scene, runs, ref_image, user_selectors=user_selectors, points=light_choice_points)
        except Exception as exc:  # a user selector failed at a point the first check did not see (or worse): the
            choice_error = exc  # report keeps every strategy's renders, says why, and the command ends with the error
            choice = LightChoice(points=0, lights=0, per_light=0, bsdf_samples=0, skipped=str(exc))
    write_report(
        output,
        title=f"lightprobe compare: {name}, {budget}",
        runs=runs,
        reference=ref_image,
        command=command,
        settings=settings,
        notes=f"{w}x{h}, equal {equal}: {budget}. Reference: {settings['reference']}."
        + "".join(f" Strategy {r.label} stopped early at {r.spp:g} spp: {r.error}" for r in runs if r.error),
        light_choice=choice,
    )
    for r in runs:
        m = r.metrics
        row = {
            "strategy": r.label,
            "spp": round(r.spp, 3),
            "seconds": r.seconds,
            "mse": m["mse"],
            "relmse": m["relmse"],
            "psnr": m["psnr"],
            "flip": m["flip"],
            "efficiency": m["efficiency"],
            "relative_efficiency": m["relative_efficiency"],
        }
        if as_json:
            typer.echo(json.dumps(row))
    _echo_err(f"wrote {output}")
    failed = [r for r in runs if r.error]
    if failed:  # the report keeps what every strategy rendered; the failure is still an error
        raise LightprobeError(f"strategy {failed[0].label!r} stopped at {failed[0].spp:g} spp: {failed[0].error}")
    if choice_error is not None:
        raise choice_error


@app.command("check")
def check_command(
    technique: Annotated[str, typer.Argument(metavar="FILE.py[:NAME]", help="The technique to check.")],
    samples: Annotated[int, typer.Option(help="Samples per context [200000].")] = 200_000,
    seed: SeedOption = 0,
    material: Annotated[
        str | None,
        typer.Option(
            help="Material of a BSDF technique's contexts, TYPE:key=value,... as in a scene file "
            "[phong:rho_d=0.3,rho_s=0.6,exponent=20]."
        ),
    ] = None,
    envmap: Annotated[
        Path | None, typer.Option(help="Map of a light technique's context [a 64x32 sky with a 12-degree sun].")
    ] = None,
    output: Annotated[Path, typer.Option("--output", "-o", help="The HTML page; the PNG goes beside it.")] = Path(
        "check.html"
    ),
    time_limit: Annotated[float, typer.Option(help="Seconds one call of the technique may take [60].")] = 60.0,
    as_json: Annotated[bool, typer.Option("--json", help="Print the checks as JSON.")] = False,
) -> None:
    """Check a sampling technique written in Python against its own pdf: it runs and returns finite, unit
    directions; nothing below the surface (hemisphere techniques); sample()'s pdf equals pdf(); the pdf integrates
    to 1; a chi-square test of the samples. A light selector (select(ctx, u), pmf(ctx, light)) is checked on a scene
    of every kind of light: pmfs summing to 1, indices in range, select's pmf = pmf(), a chi-square test of its picks.
    Exit status 0 when every check passes, 1 when one fails."""
    from .lab.check import check_technique, figure_png, write_html
    from .lab.techniques import TechniqueError, load_technique

    if output.suffix.lower() not in (".html", ".htm"):
        raise LightprobeError(f"{output}: the page is an .html file")
    try:
        tech = load_technique(technique, time_limit=time_limit)
    except TechniqueError as exc:  # not a technique: a light selector?
        if "is not a technique" not in str(exc) and "(techniques found: none)" not in str(exc):
            raise
        _check_selector(technique, exc, seed=seed, time_limit=time_limit, as_json=as_json)
        return
    report = check_technique(
        tech, samples=samples, seed=seed, material=_material_option(material), environment=_envmap_option(envmap)
    )
    png = output.with_suffix(".png")
    picture = figure_png(report)
    write_html(report, output, picture)
    png.write_bytes(picture)
    typer.echo(json.dumps(report.as_dict()) if as_json else report.text())
    _echo_err(f"wrote {output} and {png}")
    if not report.passed:
        raise typer.Exit(1)


def _check_selector(spec: str, not_a_technique: Exception, *, seed: int, time_limit: float, as_json: bool) -> None:
    """``lightprobe check`` of a light selector: its checks on the test scene, printed; exit status 1 if one fails."""
    from .experiments.light_choice import SELECTOR_CHECKS, check_selector
    from .lab.selectors import load_selector
    from .lab.techniques import TechniqueError

    try:
        selector = load_selector(spec, time_limit=time_limit)
    except TechniqueError as exc:
        if "is not a selector" in str(exc) or "(selectors found: none)" in str(exc):
            raise not_a_technique from None  # neither: the technique's message, as before selectors
        raise
    try:
        passed, failure = check_selector(selector, seed=seed), None
    except TechniqueError as exc:
        passed, failure = [], str(exc)
    if as_json:
        typer.echo(json.dumps({"selector": selector.label, "passed": failure is None, "checks": list(SELECTOR_CHECKS),
                               "failure": failure}))  # fmt: skip
    elif failure is None:
        typer.echo(f"{selector.label}: every check passed on a scene of every kind of light")
        for line in passed:
            typer.echo(f"  passed: {line}")
    else:
        typer.echo(f"{selector.label}: FAILED: {failure}")
    if failure is not None:
        raise typer.Exit(1)


@exercise_app.command("init")
def exercise_init_command(
    directory: Annotated[Path, typer.Argument(metavar="DIR", help="Where to write the exercise.")],
    force: Annotated[bool, typer.Option("--force", help="Overwrite the exercise's files if they exist.")] = False,
) -> None:
    """Write the Krivanek exercise into DIR: sampling.py (the techniques to write, with their maths), scene.toml
    and README.md."""
    from .lab.exercise import init_exercise

    for path in init_exercise(directory, force=force):
        typer.echo(f"wrote {path}")
    typer.echo(f"next: fill in step 1 of {directory / 'sampling.py'}, then `lightprobe exercise check {directory}`")


@exercise_app.command("check")
def exercise_check_command(
    directory: Annotated[Path, typer.Argument(metavar="DIR", help="The exercise's directory.")] = Path("."),
    samples: Annotated[int, typer.Option(help="Samples per context of each technique's check [100000].")] = 100_000,
) -> None:
    """Grade the exercise in DIR step by step: each technique checked against its own pdf, the balance heuristic
    against its formula, then a render with your techniques z-tested against lightprobe's. Exit status 0 when all
    six steps pass, 1 otherwise."""
    from .lab.exercise import grade

    result = grade(directory, samples=samples, progress=_echo_err)
    typer.echo(result.text())
    if not result.passed:
        raise typer.Exit(1)


def _material_option(text: str | None):
    """A BSDF from TYPE:key=value,... (scene-file keys), or None."""
    if text is None:
        return None
    from .experiments.compare import _value
    from .io.scene_file import material_from_table

    kind, _, rest = text.partition(":")
    table = {"type": kind.strip()}
    for item in filter(None, (p.strip() for p in rest.split(","))):
        key, sep, value = item.partition("=")
        if not sep:
            raise LightprobeError(f"--material: {item!r} is not key=value")
        table[key.strip()] = _value(value)
    return material_from_table(table, "--material")


def _envmap_option(path: Path | None):
    if path is None:
        return None
    from .emitters.envmap import EnvironmentMap

    return EnvironmentMap.load(path)


def _settings_dict(settings) -> dict:
    import dataclasses

    return dataclasses.asdict(settings)


def _strategy_settings(settings) -> dict:
    """A strategy's settings without the fields the comparison sets per round (spp, sample range, time)."""
    rest = _settings_dict(settings)
    for key in ("spp", "first_sample", "time_limit", "pass_samples", "threads"):
        rest.pop(key)
    return rest


def _compare_with_progress(run, tokens: list[str], *, quiet: bool):
    """Run ``run(progress)`` with a progress bar over the strategies (one line per strategy when not a terminal)."""
    if quiet or not sys.stderr.isatty():
        seen = set()

        def log(label, fraction):
            if label not in seen:
                seen.add(label)
                _echo_err(f"rendering {label} ...")

        return run(log)
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    with Progress(
        TextColumn("{task.description}"), BarColumn(), TimeElapsedColumn(), transient=True, console=_stderr_console()
    ) as bar:
        task = bar.add_task("comparing", total=len(tokens))
        order = {t.strip(): i for i, t in enumerate(tokens)}

        def update(label, fraction):
            bar.update(task, completed=order.get(label, 0) + min(fraction, 1.0), description=label)

        return run(update)


def _write_object_ids(path: Path, scene) -> list[Path]:
    """The object-id pass (index in the scene's objects, -1 where the environment is seen) and its names."""
    import numpy as np

    from .analysis.masks import object_id_pass
    from .images import write_image

    ids, names = object_id_pass(scene)
    written = [write_image(path, ids.astype(np.float32)[:, :, None], channel_names=["object_id"])]
    meta = path.with_name(path.name + ".json")
    meta.write_text(json.dumps({"objects": names, "background": -1}, indent=2) + "\n")
    return [*written, meta]


def _render_settings(defaults: dict, chosen: dict):
    """Settings from a scene file's ``[render]`` table, overridden by the options given (None: not given), checked
    (a :class:`~lightprobe.errors.LightprobeError` naming the setting if one is of the wrong type or range)."""
    from .integrators.settings import RenderSettings, settings_from_table

    settings = settings_from_table(defaults)
    settings.update({k: v for k, v in chosen.items() if v is not None})
    settings.setdefault("spp", 16)
    settings = RenderSettings(**settings)
    settings.validate()
    return settings


def _lab_renderer(scene, settings, token: str):
    """``render(scene, settings, progress=...)`` with the user techniques of a ``--techniques`` token."""
    from .lab.render import parse_lab_token, render_lab

    strategy, overrides = parse_lab_token(token)
    if overrides:
        raise LightprobeError(f"--techniques {token!r}: give settings as options (--seed, --heuristic ...)")

    def run(scene, settings, progress=None):
        return render_lab(scene, strategy, settings, progress=progress)

    # a user's njit techniques get their loops compiled on every run (lightprobe's own have cached loops): announced
    # like the core's compile
    run.compiles = any(t.technique is not t.user for t in strategy.techniques)
    return run


def _render_with_progress(scene, settings, render, *, quiet: bool, core: bool = True, lab_compiles: bool = False):
    """Render with a progress bar (unless ``quiet``).  The first run compiles the kernels for about half a minute
    before the first pass: that is announced (a spinner with the elapsed time on a terminal, one line elsewhere,
    and the time it took), since a silent half minute looks like a hang.  ``core``: ``render`` is the render
    core's (whose kernels' cache can be looked up); ``lab_compiles``: a laboratory render whose njit techniques'
    loops are compiled on every run (a few seconds)."""
    from .integrators.wavefront import kernels_cached

    compiling = not kernels_cached(scene, settings) if core else lab_compiles
    what, when = ("kernels", "once for this kind of scene") if core else ("the techniques' loops", "on every run")
    started = time.perf_counter()
    interactive = not quiet and sys.stderr.isatty()
    if compiling and not interactive:
        later = "later runs load them from the cache" if core else "Numba cannot cache functions passed to others"
        _echo_err(f"lightprobe: compiling {what} ({when}; {later}) ...")

    def compiled(echo) -> None:
        nonlocal compiling
        if compiling:
            compiling = False
            echo(f"lightprobe: compiled {what} in {time.perf_counter() - started:.0f} s ({when})")

    if not interactive:  # no bar to draw: --quiet, or stderr is a file or a pipe
        result = render(scene, settings, progress=lambda stats: compiled(_echo_err))
        compiled(_echo_err)
        return result
    from rich.progress import BarColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    w, h = scene.camera.resolution
    total = settings.spp * w * h
    columns = (
        SpinnerColumn(),
        TextColumn("[progress.description]{task.description}"),
        BarColumn(),
        TextColumn("{task.fields[spp]} spp"),
        TextColumn("pass {task.fields[passes]}"),
        TextColumn("{task.fields[rate]}"),
        TimeElapsedColumn(),
        TextColumn("ETA"),
        TimeRemainingColumn(),
    )
    with Progress(*columns, transient=True, console=_stderr_console()) as bar, contextlib.ExitStack() as steps:
        compile_task = None
        if compiling:
            compile_task = bar.add_task(f"compiling {what} ({when})", total=None, spp="-", passes="-", rate="")
            if core:

                def step(done: int, count: int, stage: str) -> None:
                    description = f"compiling {what} ({when}): stage {done} of {count}, {stage}"
                    bar.update(compile_task, description=description)

                steps.enter_context(_stage_compiles(scene, settings, step))
        task = bar.add_task("rendering", total=total, spp=0, passes=0, rate="", visible=not compiling)

        def update(stats):
            if compile_task is not None and compiling:
                bar.remove_task(compile_task)
                bar.reset(task, visible=True)
            compiled(bar.console.print)
            rate = stats["camera_rays"] / max(stats["seconds"], 1e-9)
            done = stats["camera_rays"]
            if settings.time_limit is not None:  # the limit may end it first (an adaptive render plans for it)
                done = max(done, min(1.0, stats["seconds"] / settings.time_limit) * total)
            bar.update(
                task,
                completed=done,
                spp=stats["spp_done"],
                passes=stats["passes"],
                rate=f"{rate / 1e6:.2f} M samples/s",
            )

        result = render(scene, settings, progress=update)
    compiled(_echo_err)
    return result


@contextlib.contextmanager
def _stage_compiles(scene, settings, step):
    """Within: ``step(done, count, stage)`` as Numba starts compiling each stage of the render's plan (the compile
    as a step with its progress, not a silent minute)."""
    from numba.core import event

    from .integrators import pipeline
    from .integrators.wavefront import plan_for

    names = plan_for(scene, settings).stages()
    bodies = {pipeline.STAGES[pipeline.stage_id(name)].body.py_func: name for name in names}
    seen: set[str] = set()

    class Listener(event.Listener):
        def on_start(self, ev):
            func = getattr(ev.data.get("dispatcher"), "py_func", None)
            if func in bodies and bodies[func] not in seen:
                seen.add(bodies[func])
                step(len(seen), len(names), bodies[func])

        def on_end(self, ev):
            pass

    with event.install_listener("numba:compile", Listener()):
        yield


def _echo_err(text: str) -> None:
    print(text, file=sys.stderr)


def _stderr_console():
    from rich.console import Console

    return Console(stderr=True)


@experiment_app.command("shading-point")
def experiment_shading_point(
    maps: Annotated[
        str,
        typer.Option(help="Comma-separated: constant, a named map (overcast, sunrise, studio, ...) or a file."),
    ] = "constant,overcast,sunrise,studio",
    exponents: Annotated[str, typer.Option(help="Comma-separated Phong exponents.")] = "1,10,100,1000,10000",
    samples: Annotated[int, typer.Option(help="Directions per estimator.")] = 200_000,
    seed: SeedOption = 1,
    output: Annotated[Path | None, typer.Option("--output", "-o", help="Also write the table (Markdown).")] = None,
) -> None:
    """Variance of every estimator at one shading point, at equal numbers of directions (the seed's MIS claim)."""
    from .experiments.shading_point import run, to_markdown

    try:
        values = [float(x) for x in _split(exponents)]
    except ValueError:
        raise LightprobeError(f"--exponents must be comma-separated numbers, got {exponents!r}") from None
    rows = run(_split(maps), values, n=samples, seed=seed)
    table = to_markdown(rows)
    header = (
        f"Relative variance per direction (luminance variance / mean^2), {samples} directions per estimator, "
        f"seed {seed}; normal +Y, viewer at 45 deg elevation toward +Z; Phong rho_d = 0, rho_s = 1; "
        f"Lambert albedo 0.8. MIS = 1 BRDF + 1 env sample per group. Bold: lowest."
    )
    typer.echo(header)
    typer.echo(table)
    if output is not None:
        output.write_text(header + "\n\n" + table + "\n")


def _lecture_experiment(name: str, run, as_json: bool, output: Path, options: dict) -> None:
    from .experiments.lecture import to_json_lines, to_markdown

    rows = run(out_dir=output, **options)
    if as_json:
        typer.echo(to_json_lines(rows))
    else:
        typer.echo(to_markdown(rows))
    (output / f"{name}.json").write_text(to_json_lines(rows) + "\n")
    from dataclasses import asdict

    from .analysis.report import write_gallery

    report = write_gallery(
        output / "index.html",
        title=f"lightprobe experiment {name}",
        rows=[asdict(r) for r in rows],
        images=sorted(output.glob(f"{name}-*.png")),
        notes=f"Options: {options}.",
    )
    typer.echo(f"wrote the images, {output / (name + '.json')} and {report}", err=True)


def _seed_experiment(name: str, rows, as_json: bool, output: Path, summary: str = "") -> None:
    from dataclasses import asdict

    if as_json:
        for r in rows:
            typer.echo(json.dumps(asdict(r)))
    else:
        typer.echo("| map | material | strategy | spp | seconds | MSE | relMSE | efficiency |")
        typer.echo("|---|---|---|---|---|---|---|---|")
        for r in rows:
            typer.echo(
                f"| {r.map} | {r.material} | {r.strategy} | {r.spp:g} | {r.seconds:.3f} | {r.mse:.3g} | "
                f"{r.relmse:.3g} | {r.efficiency:.3g} |"
            )
    if summary:
        typer.echo(summary, err=True)
    _echo_err(f"wrote {output / 'index.html'}, a report per cell and {output / 'rows.json'}")


def _floats(text: str, option: str) -> list[float]:
    try:
        values = [float(v) for v in _split(text)]
    except ValueError:
        raise LightprobeError(f"{option} must be comma-separated numbers, got {text!r}") from None
    if not values:
        raise LightprobeError(f"{option} is empty")
    return values


@experiment_app.command("krivanek-mis")
def experiment_krivanek_mis(
    maps: Annotated[str, typer.Option(help="Comma-separated map names or files [sky-sun,sky without data].")] = (
        "sunrise,studio,overcast,city"
    ),
    exponents: Annotated[str, typer.Option(help="Comma-separated Phong exponents.")] = "1,10,100,1000",
    spp: CellSppOption = 64,
    reference_spp: CellReferenceSppOption = 1024,
    width: CellWidthOption = 96,
    seed: SeedOption = 1,
    as_json: JsonOption = False,
    output: Annotated[Path, typer.Option("--output", "-o", help="Folder for the reports.")] = Path("krivanek-mis"),
    dask: CellDaskOption = False,
    scheduler: CellSchedulerOption = None,
    workers: WorkersOption = 2,
) -> None:
    """BRDF vs environment sampling vs MIS on a rendered Phong sphere, per map and exponent (the seed's claim)."""
    from .experiments.seeds import krivanek_mis

    _check_sizes(spp, reference_spp, width)
    rows = krivanek_mis(
        _maps_or_procedural(maps),
        _floats(exponents, "--exponents"),
        output,
        spp=spp,
        reference_spp=reference_spp,
        width=width,
        seed=seed,
        progress=_echo_err,
        dask=_dask_backend(dask, scheduler),
        workers=workers,
    )
    _seed_experiment("krivanek-mis", rows, as_json, output)


@experiment_app.command("pbrt-envmap-vs-cosine")
def experiment_pbrt_envmap_vs_cosine(
    maps: Annotated[str, typer.Option(help="Comma-separated map names or files [sky-sun,sky without data].")] = (
        "sunrise,overcast,sky-sun,sky"
    ),
    spp: CellSppOption = 64,
    reference_spp: CellReferenceSppOption = 1024,
    width: CellWidthOption = 96,
    seed: SeedOption = 1,
    as_json: JsonOption = False,
    output: Annotated[Path, typer.Option("--output", "-o", help="Folder for the reports.")] = Path(
        "pbrt-envmap-vs-cosine"
    ),
    dask: CellDaskOption = False,
    scheduler: CellSchedulerOption = None,
    workers: WorkersOption = 2,
) -> None:
    """Cosine-weighted vs environment importance sampling of a diffuse scene under spiky and soft maps (pbrt)."""
    from .experiments.seeds import pbrt_envmap_vs_cosine, reduction_factors

    _check_sizes(spp, reference_spp, width)
    rows = pbrt_envmap_vs_cosine(
        _maps_or_procedural(maps),
        output,
        spp=spp,
        reference_spp=reference_spp,
        width=width,
        seed=seed,
        progress=_echo_err,
        dask=_dask_backend(dask, scheduler),
        workers=workers,
    )
    factors = ", ".join(f"{m} {f:.3g}x" for m, f in reduction_factors(rows).items())
    _seed_experiment(
        "pbrt-envmap-vs-cosine", rows, as_json, output, f"variance reduction (MSE cosine / env): {factors}"
    )


def _maps_or_procedural(text: str) -> list[str]:
    """The maps asked for; real ones are replaced by the procedural pair when ../shared/data is absent."""
    from .data import NAMED_ENVMAPS, data_dir

    names = _split(text)
    if not names:
        raise LightprobeError("--maps is empty")
    root = data_dir()
    missing = [n for n in names if n in NAMED_ENVMAPS and (root is None or not (root / "envmaps").exists())]
    if missing:
        _echo_err(f"maps not found ({', '.join(missing)}; ../shared/data absent): using sky-sun and sky instead")
        names = [n for n in names if n not in missing] or ["sky-sun", "sky"]
    return list(dict.fromkeys(names))


@experiment_app.command("lecture-area-sampling")
def experiment_lecture_area_sampling(
    spp: Annotated[int, typer.Option(help="Camera samples per pixel.")] = 4,
    reference_spp: Annotated[int, typer.Option(help="Samples per pixel of the MIS reference.")] = 1024,
    width: Annotated[int, typer.Option(help="Image width (height 3/4 of it).")] = 320,
    seed: SeedOption = 1,
    as_json: JsonOption = False,
    output: Annotated[Path, typer.Option("--output", "-o", help="Folder for the images.")] = Path(
        "lecture-area-sampling"
    ),
) -> None:
    """Hemisphere vs area vs solid-angle sampling of a rectangular light, 1 and 16 shadow rays (the lecture)."""
    from .experiments.lecture import area_sampling

    _check_sizes(spp, reference_spp, width)
    options = {"spp": spp, "reference_spp": reference_spp, "seed": seed, "resolution": (width, max(1, width * 3 // 4))}
    _lecture_experiment("lecture-area-sampling", area_sampling, as_json, output, options)


@experiment_app.command("lecture-many-lights")
def experiment_lecture_many_lights(
    lights: Annotated[int, typer.Option(help="Number of emissive triangles.")] = 4000,
    k: Annotated[int, typer.Option("--k", help="Lights picked per camera sample (N = 1 sample each).")] = 16,
    spp: Annotated[int, typer.Option(help="Camera samples per pixel.")] = 1,
    reference_spp: Annotated[int, typer.Option(help="Samples per pixel of the MIS reference.")] = 256,
    width: Annotated[int, typer.Option(help="Image width (height 2/3 of it).")] = 320,
    seed: SeedOption = 1,
    as_json: JsonOption = False,
    output: Annotated[Path, typer.Option("--output", "-o", help="Folder for the images.")] = Path(
        "lecture-many-lights"
    ),
) -> None:
    """Uniform vs power vs BVH light selection on the many-light demo, K = 16, N = 1 (the lecture's 12.4x)."""
    from .experiments.lecture import many_lights

    if lights < 2 or k < 1 or k > 64 or spp < 1 or reference_spp < 1 or width < 4:
        raise LightprobeError("--lights >= 2, 1 <= --k <= 64, --spp, --reference-spp >= 1 and --width >= 4")
    options = {
        "n_lights": lights,
        "k": k,
        "spp": spp,
        "reference_spp": reference_spp,
        "seed": seed,
        "resolution": (width, max(1, width * 2 // 3)),
    }
    _lecture_experiment("lecture-many-lights", many_lights, as_json, output, options)


@envmap_app.command("info")
def envmap_info(
    file: Annotated[Path, typer.Argument(help="Environment map (.exr, .hdr, .pfm).")],
    mapping: Annotated[str, typer.Option(help="latlong or angular.")] = "latlong",
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
) -> None:
    """Resolution, luminance statistics, dynamic range and how spiky the map is."""
    from .emitters.envmap import EnvironmentMap

    stats = EnvironmentMap.load(file, mapping=mapping).stats()
    if as_json:
        typer.echo(json.dumps(stats))
        return
    typer.echo(f"{stats['source']}: {stats['width']}x{stats['height']} lat-long (input {stats['mapping']})")
    typer.echo(
        f"  luminance min {stats['min_luminance']:.4g}, max {stats['max_luminance']:.4g}, "
        f"mean {stats['mean_luminance']:.4g} (solid-angle weighted), median {stats['median_luminance']:.4g}"
    )
    typer.echo(f"  dynamic range {stats['dynamic_range_stops']:.1f} stops (max / 1st percentile)")
    typer.echo(f"  brightest 0.1% of texels hold {100 * stats['top_0.1%_energy_fraction']:.1f}% of the energy")
    typer.echo(f"  integral of luminance over the sphere {stats['integral']:.4g}")


@envmap_app.command("convert")
def envmap_convert(
    source: Annotated[Path, typer.Argument(help="Input map.")],
    output: Annotated[Path, typer.Argument(help="Output file (.exr, .hdr, .pfm).")],
    to: Annotated[str, typer.Option("--to", help="Target mapping: latlong or angular.")],
    mapping: Annotated[str | None, typer.Option(help="Input mapping (default: the other one).")] = None,
    size: Annotated[int | None, typer.Option(help="Angular map size (default: the lat-long width).")] = None,
) -> None:
    """Convert between lat-long and Debevec's angular light-probe mapping."""
    from .emitters.envmap import EnvironmentMap
    from .images import write_image

    if to not in ("latlong", "angular"):
        raise LightprobeError(f"--to must be latlong or angular, got {to!r}")
    src_mapping = mapping or ("angular" if to == "latlong" else "latlong")
    env = EnvironmentMap.load(source, mapping=src_mapping)
    write_image(output, env.to_array(mapping=to, size=size))
    typer.echo(f"wrote {output} ({to})")


@envmap_app.command("pdf")
def envmap_pdf(
    file: Annotated[Path, typer.Argument(help="Environment map.")],
    output: Annotated[Path, typer.Option("--output", "-o", help="PNG to write.")] = Path("envmap_pdf.png"),
    pdf: Annotated[str | None, typer.Option(help="bilinear, exact or pbrt [bilinear for bilinear lookups].")] = None,
    compensated: Annotated[bool, typer.Option(help="Show the MIS-compensated PDF.")] = False,
    mapping: Annotated[str, typer.Option(help="latlong or angular.")] = "latlong",
) -> None:
    """Picture of the sampling PDF (log scale) beside the map."""
    from .analysis.plots import plot_envmap_pdf
    from .emitters.envmap import EnvironmentMap

    env = EnvironmentMap.load(file, mapping=mapping, pdf=pdf)
    plot_envmap_pdf(env, output, compensated=compensated)
    typer.echo(f"wrote {output}")


def _format_warning(message, category, filename, lineno, line=None) -> str:
    return f"lightprobe: warning: {message}\n"


def main(argv: list[str] | None = None) -> int:
    """Entry point: runs the Typer app, turning user errors into one line and exit status 2."""
    warnings.formatwarning = _format_warning
    # a first render compiles some of its stages in a helper process per spare core (integrators/precompile.py)
    os.environ.setdefault("LIGHTPROBE_COMPILE_HELPERS", "auto")
    try:
        # outside standalone mode Typer turns Ctrl-C into a returned 130 (and typer.Exit into its code) instead of
        # raising: a Ctrl-C while a scene loads came back as a silent success before this was read
        status = app(args=argv, standalone_mode=False)
        if status == 130:
            raise KeyboardInterrupt
    except LightprobeError as exc:
        print(f"lightprobe: error: {exc}", file=sys.stderr)
        return 2
    except (typer.Abort, KeyboardInterrupt):
        print("lightprobe: interrupted", file=sys.stderr)
        return 130
    except typer.Exit as exc:
        return exc.exit_code
    except Exception as exc:
        # usage errors (missing argument, bad option): click's exceptions, which typer may vendor
        if hasattr(exc, "show") and isinstance(getattr(exc, "exit_code", None), int):
            exc.show()
            return exc.exit_code
        raise
    return status if type(status) is int else 0  # a command returns None; Typer returns an exit code


if __name__ == "__main__":
    sys.exit(main())
