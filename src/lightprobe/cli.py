"""The ``lightprobe`` command.

User errors (a missing file, a bad parameter) print one line, ``lightprobe: error: ...``, and exit with status 2;
warnings print one line each.  Run ``lightprobe --help`` or ``lightprobe COMMAND --help`` for the options.
"""

from __future__ import annotations

import json
import sys
import warnings
from pathlib import Path
from typing import Annotated

import typer

from .errors import LightprobeError

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    help="Monte Carlo image-based lighting with verified importance sampling.",
)
experiment_app = typer.Typer(no_args_is_help=True, help="Reproduce the measurements behind the README's claims.")
envmap_app = typer.Typer(no_args_is_help=True, help="Inspect and convert environment maps.")
app.add_typer(experiment_app, name="experiment")
app.add_typer(envmap_app, name="envmap")


def _split(text: str) -> list[str]:
    return [t.strip() for t in text.split(",") if t.strip()]


@experiment_app.command("shading-point")
def experiment_shading_point(
    maps: Annotated[
        str,
        typer.Option(help="Comma-separated: constant, a named map (overcast, sunrise, studio, ...) or a file."),
    ] = "constant,overcast,sunrise,studio",
    exponents: Annotated[str, typer.Option(help="Comma-separated Phong exponents.")] = "1,10,100,1000,10000",
    samples: Annotated[int, typer.Option(help="Directions per estimator.")] = 200_000,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 1,
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
    from .io.images import write_image

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
    pdf: Annotated[str, typer.Option(help="exact or pbrt.")] = "exact",
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
    try:
        app(args=argv, standalone_mode=False)
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
    return 0


if __name__ == "__main__":
    sys.exit(main())
