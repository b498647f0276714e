"""A render's stages compiled in helper processes beside its own compile (decisions.md 104).

Numba compiles under one lock per process, so a first render compiles its stage bodies one after another, about half
a minute for a plan.  The bodies are independent functions whose arguments have the same types for every scene (the
pass records hold empty arrays where a scene needs nothing: ``pass_state.py``), so another process can compile some of
them into the shared cache while the render compiles the others: the render's own compile then finds them there and
loads them in milliseconds.  Numba writes a function's cache index under a lock (``_numba.py``), so processes can save
into one cache at once.

A helper takes the plan's stages from the last (the render compiles them from the first); with more cores, more
helpers share them.  Each body is compiled by one process only, whichever claims it first (:class:`Claims`): the
render waits for a body a helper claimed, then loads it.  Helpers are stopped when the render's warm-up is done,
whatever they were compiling: what they saved stays in the cache, a half-written file never does (Numba writes a
temporary file and renames it).

``LIGHTPROBE_COMPILE_HELPERS`` says how many: ``auto`` (one per spare core, what the ``lightprobe`` command sets
unless told otherwise), a number, or unset / ``0``: none, the default of the Python API, whose callers may already be
one of several processes (Dask's workers, the test suite's).  Measured on the 2-core machine, the demo's first
render from an empty cache: 46.7 and 50.6 s with a helper, 59.4 and 54.7 s without, alternating (decisions.md 104).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import threading

__all__ = ["Claims", "helpers_wanted", "start", "stop"]

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


class Claims:
    """Which process compiles which stage body of a first render: a file per body in a folder that the render and
    its helpers share, created with ``O_EXCL`` by whichever process comes to the body first (so no body is compiled
    twice: where a render and its helper met, both compiled the body between them, the area-light scene's BSDF-ray
    stage 11 s each, decisions.md 129).  The render waits for a body a helper claimed (the helper reports each body
    it has saved on its standard output) and then loads it from the cache."""

    def __init__(self, folder: str):
        self.folder = folder
        self.saved: set[str] = set()
        self.running = 0  # helpers still reporting
        self.changed = threading.Condition()

    def claim(self, name: str) -> bool:
        """Whether this process may compile body ``name`` (no other process has claimed it)."""
        try:
            os.close(os.open(os.path.join(self.folder, name), os.O_CREAT | os.O_EXCL | os.O_WRONLY))
        except FileExistsError:
            return False
        return True

    def listen(self, helper: subprocess.Popen) -> None:
        """Read ``helper``'s reports (a line ``saved NAME`` per body) until it exits."""
        for line in helper.stdout:
            word, _, name = line.decode(errors="replace").strip().partition(" ")
            if word == "saved":
                with self.changed:
                    self.saved.add(name)
                    self.changed.notify_all()
        with self.changed:
            self.running -= 1
            self.changed.notify_all()

    def wait_for(self, name: str, timeout: float = 600.0) -> None:
        """Before the render compiles body ``name``: claim it, or wait until the helper that claimed it has saved
        it (or no helper is left: then the render compiles it itself)."""
        if self.claim(name):
            return
        with self.changed:
            self.changed.wait_for(lambda: name in self.saved or self.running == 0, timeout)


def start(stages: tuple[str, ...], records: tuple) -> tuple[list[subprocess.Popen], Claims | None]:
    """Helpers that compile ``stages`` (a plan's stage names, in its order) from the last, each body claimed by one
    process (:class:`Claims`), for bodies called with the pass ``records`` (their types are sent, pickled: Numba's
    types are its cache's keys); and the claims, which the render consults before compiling a body."""
    count = helpers_wanted(len(stages))
    if count == 0:
        return [], None
    import pickle
    import tempfile

    from numba import typeof

    signatures = pickle.dumps(tuple(typeof(x) for x in records))
    claims = Claims(tempfile.mkdtemp(prefix="lightprobe-claims-"))
    helpers = []
    for _ in range(count):
        try:
            helper = subprocess.Popen(
                [sys.executable, "-m", "lightprobe.integrators.precompile", claims.folder, *reversed(stages)],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=subprocess.DEVNULL,
                env={**os.environ, ENVIRONMENT: "0"},
            )
            helper.stdin.write(signatures)
            helper.stdin.close()
        except OSError:  # no room for another process: the render compiles alone
            break
        helpers.append(helper)
        with claims.changed:
            claims.running += 1
        threading.Thread(target=claims.listen, args=(helper,), daemon=True).start()
    return helpers, claims


def stop(helpers: list[subprocess.Popen], claims: Claims | None = None) -> None:
    """End the helpers, done or not (what they saved stays in the cache), and remove the claims' folder."""
    for helper in helpers:
        if helper.poll() is None:
            helper.kill()
    for helper in helpers:
        try:
            helper.wait(timeout=10)
        except subprocess.TimeoutExpired:  # pragma: no cover - a killed process that does not end
            pass
    if claims is not None:
        shutil.rmtree(claims.folder, ignore_errors=True)


def main(folder: str, names: list[str]) -> None:
    """Compile the stage bodies ``names``, in order, that no other process has claimed in ``folder``, for the pass
    records' types pickled on standard input; report each one saved (``saved NAME``) on standard output."""
    import pickle

    from . import pipeline

    record_types = pickle.loads(sys.stdin.buffer.read())
    claims = Claims(folder)
    for name in names:
        if not claims.claim(name):
            continue
        stage = pipeline.STAGES[pipeline.stage_id(name)]
        pipeline.compiled(stage.body, pipeline.body_signature(record_types, stage.parameters))
        print("saved", name, flush=True)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2:])
