"""A render's stages compiled in helper processes beside its own compile (decisions.md 104).

Numba compiles under one lock per process, so a first render compiles its stage bodies one after another, about half
a minute for a plan.  The bodies are independent functions whose arguments have the same types for every scene (the
pass records hold empty arrays where a scene needs nothing: ``pass_state.py``), so another process can compile some of
them into the shared cache while the render compiles the others: the render's own compile then finds them there and
loads them in milliseconds.  Numba writes a function's cache index under a lock (``_numba.py``), so processes can save
into one cache at once.

A helper takes the plan's stages the longest to compile first (the render compiles them from the first); with more
cores, more helpers share them.  Each body is compiled by one process only, whichever claims it first
(:class:`Claims`): the render compiles the bodies it claims, then waits for those a helper claimed and loads them.
Helpers are stopped when the render's warm-up is done, whatever they were compiling: what they saved stays in the
cache, a half-written file never does (Numba writes a temporary file and renames it).

``LIGHTPROBE_COMPILE_HELPERS`` says how many: ``auto`` (one per spare core, what the ``lightprobe`` command sets
unless told otherwise), a number, or unset / ``0``: none, the default of the Python API, whose callers may already be
one of several processes (Dask's workers, the test suite's).  Measured on the 2-core machine, the demo's first
render from an empty cache: 46.7 and 50.6 s with a helper, 59.4 and 54.7 s without, alternating (decisions.md 104);
with the claims, the longest compile first and the prestart, 18.7-19.6 s (decisions.md 129).  A helper's process
is ``compile_helper.py``.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import threading
from pathlib import Path

__all__ = [
    "Claims",
    "Helpers",
    "helpers_wanted",
    "known_record_types",
    "largest_first",
    "prestart",
    "record_types_pickled",
    "save_record_types",
    "take_prestarted",
]

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
        """Wait until the helper that claimed body ``name`` has saved it (or no helper is left: then the render
        compiles it itself)."""
        with self.changed:
            self.changed.wait_for(lambda: name in self.saved or self.running == 0, timeout)


#: seconds each stage body took to compile from an empty cache on the 2-core machine (its own compile and its
#: callees', alone), the bodies not listed about a second: only the order of a helper's work depends on them
COMPILE_SECONDS = {
    "setup": 10.8,
    "setup_textured": 14.0,
    "what_bsdf_rays_see": 12.5,
    "light_samples": 11.8,
    "finish": 3.6,
    "camera": 2.2,
    "camera_tree": 2.2,
}


def largest_first(stages: tuple[str, ...]) -> list[str]:
    """``stages`` in the order a helper takes them: the longest to compile first (the render takes them in the
    plan's order, so the two meet in the fewest seconds: a helper that took them from the last was done 7 s before
    the render had compiled the demo's setup stage, decisions.md 129), ties from the last."""
    return sorted(reversed(stages), key=lambda name: -COMPILE_SECONDS.get(name, 1.0))


#: the stage bodies a prestarted helper compiles before it knows the plan: the setup stage, which every plan but a
#: textured scene's runs, the longest compile of most plans
SPECULATIVE = ("setup",)


class Helpers:
    """The helper processes of one render and their :class:`Claims`: started once, at the render's start where an
    earlier render left the pass records' types (:func:`known_record_types`), else at its warm-up; stopped when the
    warm-up has compiled (or loaded) every stage, or when the render ends."""

    def __init__(self):
        self.processes: list[subprocess.Popen] = []
        self.claims: Claims | None = None
        self.waiting = False  # prestarted: the helpers wait for the plan

    @property
    def started(self) -> bool:
        return self.claims is not None

    def prestart(self, speculative: tuple[str, ...] = SPECULATIVE) -> None:
        """Start the helpers before the command builds its scene: each compiles the stage bodies ``speculative``
        (which nearly every plan runs) for the pass records' types of an empty scene
        (``compile_helper.empty_record_types``), then waits for the render's plan (:meth:`start` sends it).  For
        a first render on this machine: the demo's setup stage, the longest compile of its plan, then starts about
        2 s sooner (decisions.md 129)."""
        if not self.started:
            self._spawn(helpers_wanted(2), ["--first", *speculative])
            self.waiting = bool(self.processes)

    def start(self, stages: tuple[str, ...], signatures: bytes | None) -> None:
        """Helpers that compile ``stages`` (a plan's stage names), the longest to compile first
        (:func:`largest_first`), each body claimed by one process, for bodies called with pass records of the types
        pickled in ``signatures`` (:func:`record_types_pickled`: Numba's types are its cache's keys; None: an empty
        scene's, ``compile_helper.empty_record_types``).  Prestarted helpers are sent the plan; started ones,
        nothing."""
        import pickle

        message = pickle.dumps((largest_first(stages), signatures))
        if self.waiting:  # sent from a thread: a helper reads it only after its first stages
            for helper in self.processes:
                threading.Thread(target=_send, args=(helper, message), daemon=True).start()
            self.waiting = False
            return
        if not self.started:
            self._spawn(helpers_wanted(len(stages)), [], message)

    def _spawn(self, count: int, arguments: list[str], message: bytes | None = None) -> None:
        """``count`` helper processes, run with ``arguments`` and sent ``message`` (or later, by :meth:`start`)."""
        if count == 0:
            return
        import tempfile

        self.claims = claims = Claims(tempfile.mkdtemp(prefix="lightprobe-claims-"))
        for _ in range(count):
            try:
                helper = subprocess.Popen(
                    [sys.executable, "-m", "lightprobe.integrators.compile_helper", claims.folder, *arguments],
                    stdin=subprocess.PIPE,
                    stdout=subprocess.PIPE,
                    stderr=subprocess.DEVNULL,
                    env={**os.environ, ENVIRONMENT: "0"},
                )
                if message is not None:
                    helper.stdin.write(message)
                    helper.stdin.close()
            except OSError:  # no room for another process: the render compiles alone
                break
            self.processes.append(helper)
            with claims.changed:
                claims.running += 1
            threading.Thread(target=claims.listen, args=(helper,), daemon=True).start()

    def claim(self, name: str) -> bool:
        """Whether the render may compile stage body ``name`` now (:meth:`Claims.claim`; always, without helpers)."""
        return self.claims is None or self.claims.claim(name)

    def wait_for(self, name: str) -> None:
        """Before the render loads stage body ``name``, which a helper claimed: :meth:`Claims.wait_for`."""
        if self.claims is not None:
            self.claims.wait_for(name)

    def stop(self) -> None:
        """End the helpers, done or not (what they saved stays in the cache), and remove the claims' folder."""
        for helper in self.processes:
            if helper.poll() is None:
                helper.kill()
        for helper in self.processes:
            try:
                helper.wait(timeout=10)
            except subprocess.TimeoutExpired:  # pragma: no cover - a killed process that does not end
                pass
            try:  # a prestarted helper's, if it was never sent a plan (its output ends with it: the listener's)
                helper.stdin.close()
            except (OSError, ValueError):
                pass
        if self.claims is not None:
            shutil.rmtree(self.claims.folder, ignore_errors=True)
        self.processes, self.claims, self.waiting = [], None, False


def _send(helper: subprocess.Popen, message: bytes) -> None:
    """Write ``message`` to ``helper``'s standard input and close it (nothing if it has ended: the render compiles
    what it did not)."""
    try:
        helper.stdin.write(message)
        helper.stdin.close()
    except (OSError, ValueError):
        pass


_PRESTARTED: list[Helpers] = []


def prestart() -> None:
    """Where helpers are wanted and this machine's kernel cache lacks the stage loop (a first render after an install
    or an upgrade), start them now (:meth:`Helpers.prestart`), before the command builds its scene; the render takes
    them (:func:`take_prestarted`), else they are stopped when the process exits."""
    if _PRESTARTED or helpers_wanted(2) == 0:
        return
    from .._numba import is_cached
    from .pipeline import run_stage

    if is_cached(run_stage):
        return
    helpers = Helpers()
    helpers.prestart()
    if helpers.processes:
        import atexit

        _PRESTARTED.append(helpers)
        atexit.register(helpers.stop)


def take_prestarted() -> Helpers:
    """The helpers :func:`prestart` started, for the render that now begins (once); else new, not yet started."""
    return _PRESTARTED.pop() if _PRESTARTED else Helpers()


def record_types_pickled(records: tuple) -> bytes:
    """The Numba types of a pass's records, pickled (what a helper is sent)."""
    import pickle

    from .pipeline import record_types

    return pickle.dumps(record_types(records))


def _record_types_file() -> Path | None:
    """Where renders keep the pass records' pickled types for the next render's early helpers: in the kernel
    cache, named by the stamp of the render driver's import closure (which builds every record), so an edit that
    could change a record's type names another file; None where kernels are not stamped by their imports."""
    from .. import _numba

    if not _numba.STAMPED_BY_IMPORTS:
        return None
    stamp = _numba._closure_stamps().get(str((Path(__file__).parent / "wavefront.py").resolve()))
    if stamp is None:
        return None
    return Path(os.environ["NUMBA_CACHE_DIR"]) / f"record-types-{stamp[:20]}.pickle"


def save_record_types(signatures: bytes) -> None:
    """Keep ``signatures`` (:func:`record_types_pickled`) for later renders (written once, atomically; a cache that
    cannot be written is no error: the next render starts its helpers at its warm-up)."""
    path = _record_types_file()
    if path is None or path.is_file():
        return
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        temporary = path.with_name(f"{path.name}.{os.getpid()}")
        temporary.write_bytes(signatures)
        os.replace(temporary, path)
    except OSError:
        pass


def known_record_types() -> bytes | None:
    """The pass records' pickled types an earlier render of these sources kept (:func:`save_record_types`), or
    None."""
    path = _record_types_file()
    try:
        return path.read_bytes() if path is not None else None
    except OSError:
        return None
