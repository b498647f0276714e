"""A compile helper's process (``python -m lightprobe.integrators.compile_helper FOLDER [--first NAME ...]``): it
compiles the stage bodies a render's helpers are given (``precompile.Helpers``) into the shared kernel cache, each
one that no other process has claimed in FOLDER (``precompile.Claims``), and reports each saved on its standard
output (decisions.md 104, 129)."""

from __future__ import annotations

import pickle
import sys

from . import pipeline, wavefront
from .accumulation import Accumulator
from .precompile import Claims, record_types_pickled
from .schedule import pass_pixels

__all__ = ["empty_record_types", "main"]


def empty_record_types() -> bytes:
    """The pass records' pickled types for an empty scene (:func:`record_types_pickled`): the same as any scene's
    (``pass_state.py``; a test compares them with the demo's), worked out in about a second without the scene."""
    from ..geometry.camera import Camera
    from ..geometry.raytracer import RayTracer
    from ..scene import Scene

    scene = Scene(Camera((0, 0, 5), (0, 0, 0), fov=40, resolution=(2, 2)))
    arrays = scene.compile()
    plan = wavefront.resolve(scene, wavefront.RenderSettings(spp=1, adaptive=False))
    work = wavefront._Pass(scene, plan, arrays, RayTracer(arrays), 4, 1)
    work.make_buffers()
    return record_types_pickled(work.records(Accumulator(4), pass_pixels(0, 1), 1, 0))


def main(folder: str, arguments: list[str]) -> None:
    """Compile stage bodies that no other process has claimed in ``folder``, reporting each one saved (``saved
    NAME``) on standard output: those the pickled (names, record types) on standard input lists, in its order; with
    ``--first NAME ...`` (a prestarted helper), first those, for an empty scene's record types, then the list."""
    claims = Claims(folder)

    def compile_bodies(names, record_types):
        for name in names:
            if not claims.claim(name):
                continue
            stage = pipeline.STAGES[pipeline.stage_id(name)]
            pipeline.compiled(stage.body, pipeline.body_signature(record_types, stage.parameters))
            print("saved", name, flush=True)

    empty = None
    if arguments[:1] == ["--first"]:
        empty = pickle.loads(empty_record_types())
        compile_bodies(arguments[1:], empty)
    message = sys.stdin.buffer.read()
    if not message:  # the render ended, or needed nothing more
        return
    names, signatures = pickle.loads(message)
    if signatures is not None:
        compile_bodies(names, pickle.loads(signatures))
    else:  # the render did not have its records' types yet: an empty scene's are the same
        compile_bodies(names, empty if empty is not None else pickle.loads(empty_record_types()))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2:])
