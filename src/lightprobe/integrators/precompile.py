"""A render's stages compiled in helper processes beside its own compile (decisions.md 104).

Numba compiles under one lock per process, so a first render compiles its stage bodies one after another, about half
a minute for a plan.  The bodies are independent functions whose arguments have the same types for every scene (the
pass records hold empty arrays where a scene needs nothing: ``pass_state.py``), so another process can compile some of
them into the shared cache while the render compiles the others: the render's own compile then finds them there and
loads them in milliseconds.  Numba writes a function's cache index under a lock (``_numba.py``), so processes can save
into one cache at once.

A helper takes the plan's stages from the last (the render compiles them from the first); with more cores, more
helpers share them.  Helpers are stopped when the render's warm-up is done, whatever they were compiling: what they
saved stays in the cache, a half-written file never does (Numba writes a temporary file and renames it).

``LIGHTPROBE_COMPILE_HELPERS`` says how many: ``auto`` (one per spare core, what the ``lightprobe`` command sets
unless told otherwise), a number, or unset / ``0``: none, the default of the Python API, whose callers may already be
one of several processes (Dask's workers, the test suite's).  Measured on the 2-core machine, the demo's first
render from an empty cache: 46.7 and 50.6 s with a helper, 59.4 and 54.7 s without, alternating (decisions.md 104).
"""

from __future__ import annotations

import os
import subprocess
import sys

__all__ = ["helpers_wanted", "start", "stop"]

ENVIRONMENT = "LIGHTPROBE_COMPILE_HELPERS"


def helpers_wanted(stages: int) -> int:
    """How many helper processes compile beside the render (``LIGHTPROBE_COMPILE_HELPERS``): ``auto``, one per spare
    core and at most one per two stages; a number; none when unset or not understood."""
    given = os.environ.get(ENVIRONMENT, "0").strip().lower()
    if given == "auto":
        return max(0, min((os.cpu_count() or 1) - 1, stages // 2))
    try:
        return max(0, min(int(given), stages))
    except ValueError:
        return 0


def start(stages: tuple[str, ...], records: tuple) -> list[subprocess.Popen]:
    """Helpers that compile ``stages`` (a plan's stage names, in its order) from the last, dealt among them, for
    bodies called with the pass ``records`` (their types are sent, pickled: Numba's types are its cache's keys)."""
    count = helpers_wanted(len(stages))
    if count == 0:
        return []
    import pickle

    from numba import typeof

    signatures = pickle.dumps(tuple(typeof(x) for x in records))
    backwards = list(reversed(stages))
    helpers = []
    for i in range(count):
        try:
            helper = subprocess.Popen(
                [sys.executable, "-m", "lightprobe.integrators.precompile", *backwards[i::count]],
                stdin=subprocess.PIPE,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
                env={**os.environ, ENVIRONMENT: "0"},
            )
            helper.stdin.write(signatures)
            helper.stdin.close()
        except OSError:  # no room for another process: the render compiles alone
            break
        helpers.append(helper)
    return helpers


def stop(helpers: list[subprocess.Popen]) -> None:
    """End the helpers, done or not (what they saved stays in the cache)."""
    for helper in helpers:
        if helper.poll() is None:
            helper.kill()
    for helper in helpers:
        try:
            helper.wait(timeout=10)
        except subprocess.TimeoutExpired:  # pragma: no cover - a killed process that does not end
            pass


def main(names: list[str]) -> None:
    """Compile the stage bodies ``names``, in order, for the pass records' types pickled on standard input."""
    import pickle

    from . import pipeline

    record_types = pickle.loads(sys.stdin.buffer.read())
    for name in names:
        stage = pipeline.STAGES[pipeline.stage_id(name)]
        pipeline.compiled(stage.body, pipeline.body_signature(record_types, stage.parameters))


if __name__ == "__main__":
    main(sys.argv[1:])
