"""Numba configuration shared by every compiled kernel.

All kernels are compiled with ``cache=True`` so that a second process loads machine code from disk instead of
recompiling.  Numba invalidates a cached function only when *its own* source file changes, not when a function it
calls (and inlines) changes in another file; a stale kernel would then silently run old code.  So a kernel of this
package is stamped with a hash of its module and of every module of the package that it imports, transitively (the
top-level imports: a jitted function can only call what its module imports): an edit recompiles the kernels whose
modules reach the edited one, and no others (decisions.md 104; before, any edit started a fresh cache for all).
The cache lives in ``$XDG_CACHE_HOME/lightprobe/numba/kernels`` (or ``~/.cache/...``); set ``NUMBA_CACHE_DIR`` to
choose the location yourself.

Scalar kernels (one sample, returning tuples) are ``njit`` functions without reference counting (``jit``; the few
that allocate arrays, ``jit_alloc``, keep it); batch kernels loop over samples and are the only ones marked
``parallel``.  The renderer's stages are plain functions over a claimed range of a pass
(``jit_body``: compiled without reference counting) that one parallel loop calls (``integrators/pipeline.py``).
"""

from __future__ import annotations

import hashlib
import os
import shutil
import tempfile
from pathlib import Path

# Numba's default OpenMP layer busy-waits between parallel regions, which slows down Embree work that runs
# between our kernels, such as building a mesh scene (measured in ../shared/notes/raytracing-measurements.md).
# The workqueue layer has no such spinning; it is also always available (TBB/OpenMP may not be).  (The kernels'
# Embree calls pick a scratch row by numba.get_thread_id(), which every layer provides.)
os.environ.setdefault("NUMBA_THREADING_LAYER", "workqueue")


PACKAGE = Path(__file__).resolve().parent


def _source_fingerprint() -> str:
    """A fingerprint of every source file of the package (path, size, modification time): cheap, for naming the
    file that keeps the modules' stamps."""
    h = hashlib.sha256()
    for path in sorted(PACKAGE.rglob("*.py")):
        st = path.stat()
        h.update(f"{path.relative_to(PACKAGE)}:{st.st_size}:{st.st_mtime_ns}".encode())
    return h.hexdigest()[:16]


def _cache_root() -> Path:
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "lightprobe" / "numba"


def _cache_dir(stamped: bool) -> str:
    """The kernels' cache: one folder whose kernels carry their import closure's stamp (``stamped``); else, on a
    Numba whose cache this module cannot stamp, a folder per fingerprint of all sources (any edit starts afresh),
    older ones removed."""
    root = _cache_root()
    target = root / ("kernels" if stamped else _source_fingerprint())
    try:
        target.mkdir(parents=True, exist_ok=True)
        (target / ".writable").touch()
        for old in root.iterdir():  # a fingerprint's folder of older sources can never be used again
            if old.is_dir() and old != target and len(old.name) == 16 and set(old.name) <= set("0123456789abcdef"):
                shutil.rmtree(old, ignore_errors=True)
        return str(target)
    except OSError:
        return str(Path(tempfile.gettempdir()) / f"lightprobe-numba-{target.name}")


def _module_imports(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The package's modules that module ``name`` imports at its top level (also under a top-level ``if`` or
    ``try``): what its jitted functions can reach."""
    import ast

    tree = ast.parse(path.read_bytes())
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    found = set()
    nodes = [n for top in tree.body for n in (ast.walk(top) if isinstance(top, ast.If | ast.Try) else [top])]
    for node in nodes:
        if isinstance(node, ast.ImportFrom):
            if node.level:  # relative: from the package, one level up per dot after the first
                anchor = package[: len(package) - node.level + 1]
                target = ".".join([*anchor, node.module] if node.module else anchor)
            else:
                target = node.module or ""
            for alias in node.names:
                for candidate in (f"{target}.{alias.name}", target):
                    if candidate in modules:
                        found.add(candidate)
                        break
        elif isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names if alias.name in modules)
    return found


def import_closure_stamps(package: Path) -> dict[str, str]:
    """Per source file of ``package``, a hash of its contents and of the contents of every module of the package it
    imports, transitively (top-level imports, :func:`_module_imports`)."""
    modules = {}
    for path in sorted(package.rglob("*.py")):
        parts = list(path.relative_to(package.parent).with_suffix("").parts)
        modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    content = {name: hashlib.sha256(path.read_bytes()).hexdigest() for name, path in modules.items()}
    graph = {name: _module_imports(name, path, modules) for name, path in modules.items()}
    stamps = {}
    for name, path in modules.items():
        reached, todo = {name}, [name]
        while todo:
            for other in graph[todo.pop()] - reached:
                reached.add(other)
                todo.append(other)
        h = hashlib.sha256()
        for other in sorted(reached):
            h.update(f"{other}:{content[other]};".encode())
        stamps[str(path)] = h.hexdigest()
    return stamps


def _closure_stamps() -> dict[str, str]:
    """This package's :func:`import_closure_stamps`, kept beside the cache under the sources' fingerprint, so that
    only a changed package parses its modules again (about half a second)."""
    import json

    record = Path(os.environ["NUMBA_CACHE_DIR"]) / f"stamps-{_source_fingerprint()}.json"
    try:
        return json.loads(record.read_text())
    except (OSError, ValueError):
        pass
    stamps = import_closure_stamps(PACKAGE)
    try:
        for old in record.parent.glob("stamps-*.json"):
            old.unlink(missing_ok=True)
        tmp = record.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(json.dumps(stamps))
        os.replace(tmp, record)
    except OSError:
        pass
    return stamps


from numba import config as _config  # noqa: E402
from numba import njit, prange  # noqa: E402


def _install_cache_rules() -> bool:
    """The package's kernels stamped by their import closure (the module docstring); and Numba's index of a
    function's cached versions updated under a file lock, so that processes compiling into one cache at once
    (pytest-xdist's workers) cannot give two versions the same data file."""
    import pickle
    import threading

    from numba.core import caching

    try:
        import fcntl
    except ImportError:  # not a POSIX system: no lock (one process compiling at a time is then the user's care)
        fcntl = None

    impl = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl", None)
    if impl is None or not hasattr(caching, "UserProvidedCacheLocator") or not hasattr(caching, "IndexDataCacheFile"):
        return False
    stamps: dict[str, str] = {}
    lock = threading.Lock()

    class PackageLocator(caching.UserProvidedCacheLocator):
        def get_source_stamp(self):
            with lock:
                if not stamps:
                    stamps.update(_closure_stamps())
            return stamps.get(str(Path(self._py_file).resolve())) or super().get_source_stamp()

        @classmethod
        def from_function(cls, py_func, py_file):
            if not Path(py_file).resolve().is_relative_to(PACKAGE):
                return None
            return super().from_function(py_func, py_file)

    if not any(getattr(c, "_lightprobe", False) for c in impl._locator_classes):
        PackageLocator._lightprobe = True
        impl._locator_classes.insert(0, PackageLocator)

    load_index = caching.IndexDataCacheFile._load_index
    if not getattr(load_index, "_lightprobe", False):

        def tolerant_load_index(self):
            # an index pickles its versions' signatures, which name the types' modules: after an upgrade that moved
            # one (geometry/scene.py's SceneArrays, decisions.md 107) Numba's own loader raised ModuleNotFoundError
            # from every kernel taking it; an index that cannot be read is a miss, and the next save rewrites it
            try:
                return load_index(self)
            except (ImportError, AttributeError, EOFError, TypeError, ValueError, pickle.UnpicklingError):
                return {}

        tolerant_load_index._lightprobe = True
        caching.IndexDataCacheFile._load_index = tolerant_load_index

    save = caching.IndexDataCacheFile.save
    if fcntl is None or getattr(save, "_lightprobe", False):
        return True

    def locked_save(self, key, data):
        with open(self._index_path + ".lock", "a") as guard:
            fcntl.flock(guard, fcntl.LOCK_EX)
            try:
                save(self, key, data)
            finally:
                fcntl.flock(guard, fcntl.LOCK_UN)

    locked_save._lightprobe = True
    caching.IndexDataCacheFile.save = locked_save
    return True


STAMPED_BY_IMPORTS = _install_cache_rules()
if "NUMBA_CACHE_DIR" not in os.environ:
    os.environ["NUMBA_CACHE_DIR"] = _cache_dir(STAMPED_BY_IMPORTS)
_config.CACHE_DIR = os.environ["NUMBA_CACHE_DIR"]  # Numba read its configuration when imported, before this


def _copy_inlined_functions_in_one_pass() -> bool:
    """Make Numba's IR-level inliner copy a callee's blocks with one shared memo (returns whether it was installed).

    Every ``inline="always"`` call site makes Numba copy the callee's IR twice (``InlineWorker.inline_ir``'s
    ``copy_ir``), one ``copy.deepcopy`` per block, each with a fresh memo: so each block's copy also copies the
    function's whole variable scope (every variable of the function), and a copy costs blocks x variables.  The
    render core's stages inline helpers that inline helpers (a BSDF's sample inside the BSDF dispatch inside the
    direction sampler), so that product was about a fifth of its cold compile (Numba issue 8989 reports the same).
    Here, the blocks of one ``FunctionIR.copy()`` (which ``copy_ir`` calls first) are deep-copied with one memo, as a
    single ``deepcopy`` of the function would: they share one copied scope, as the original blocks share one.  The
    machine code is the same instruction for instruction (all 142 functions of a demo render compared), the compile
    is 18-20 % shorter (decisions.md 92).  Installed only on a Numba whose inliner uses the ``copy`` module as
    assumed; anywhere else nothing changes."""
    import copy
    import threading

    try:
        from numba.core import inline_closurecall, ir
    except ImportError:  # pragma: no cover - a Numba without this module inlines some other way
        return False
    if getattr(inline_closurecall, "copy", None) is not copy or not hasattr(ir.FunctionIR, "copy"):
        return False
    if getattr(ir.FunctionIR.copy, "_lightprobe", False):
        return True

    session = threading.local()  # the blocks of the function being copied, and their shared memo
    function_copy = ir.FunctionIR.copy

    def copy_function(self):
        session.blocks = {id(block): block for block in self.blocks.values()}
        session.memo = {}
        return function_copy(self)

    class _CopyModule:  # the inliner's view of the copy module
        def __getattr__(self, name):
            return getattr(copy, name)

        @staticmethod
        def deepcopy(x, memo=None):
            blocks = getattr(session, "blocks", None)
            if memo is None and blocks and isinstance(x, ir.Block) and blocks.get(id(x)) is x:
                memo = session.memo
                del blocks[id(x)]  # each block once: a later copy of it starts afresh
                if not blocks:
                    session.memo = None  # the function's copy is done: keep nothing alive
                return copy.deepcopy(x, memo)
            return copy.deepcopy(x, memo)

    copy_function._lightprobe = True
    ir.FunctionIR.copy = copy_function
    inline_closurecall.copy = _CopyModule()
    return True


INLINE_COPY_IN_ONE_PASS = _copy_inlined_functions_in_one_pass()

__all__ = [
    "FASTMATH",
    "cached_signatures",
    "is_cached",
    "jit",
    "jit_alloc",
    "jit_body",
    "jit_inline",
    "jit_parallel",
    "prange",
]

# Fast-math flags that keep IEEE semantics for NaN and infinities: contraction into FMA, reciprocal approximations
# and approximate library functions.  'nnan'/'ninf' are left out on purpose: the renderer tests isfinite() to keep
# NaN and Inf out of images.
FASTMATH = {"contract", "arcp", "afn"}


def jit(func):
    """Compile a scalar or serial kernel (cached on disk), without Numba's reference counting (as ``jit_body``).

    A kernel that allocates nothing needs no counts: its callers own every array it reads.  With counting on, each
    array a helper takes from a record or passes on (the environment's kernel record holds about 25) is an atomic
    increment on entry and a decrement on exit, and both render threads make them on the same counters: a constant
    environment map's sample took 775 ns with counting, 285 ns without, one thread (decisions.md 88).  A kernel
    that allocates is compiled by :func:`jit_alloc`."""
    return njit(cache=True, nogil=True, error_model="numpy", fastmath=FASTMATH, _nrt=False)(func)


def jit_alloc(func):
    """Compile a serial kernel that allocates arrays (the builds of trees and tables): reference counting on."""
    return njit(cache=True, nogil=True, error_model="numpy", fastmath=FASTMATH)(func)


def jit_body(func):
    """Compile a stage body: the work of one claimed chunk of a pass, called by the pipeline's parallel loop.

    Without Numba's reference counting (``_nrt=False``): a body reads its arrays through the pass records, and each
    field it takes from a record would otherwise be an atomic increment and decrement of that array's count, which
    both threads make on the same counters; such a body ran 2x slower than the same code inlined into the parallel
    loop (decisions.md 73, 77).  A body allocates nothing and returns nothing.  Compiled as a plain function, not
    inside the parallel loop, it skips Numba's parfor passes: the area-light path compiled in 124 s instead of 225 s
    (decisions.md 77).  The loop calls it through the address of its C entry (Numba's cfunc wrapper), so it has
    that entry and no Python one (decisions.md 129)."""
    return njit(
        cache=True,
        nogil=True,
        error_model="numpy",
        fastmath=FASTMATH,
        _nrt=False,
        no_cpython_wrapper=True,
    )(func)


def jit_inline(func):
    """Compile a helper that Numba inlines into its callers at the IR level: for helpers that take many arrays,
    where a real call costs more than the work (measured: the shading-frame helper as a call made the peer
    scene's setup stage 1.9x slower, decisions.md 20)."""
    return njit(cache=True, nogil=True, error_model="numpy", fastmath=FASTMATH, inline="always")(func)


def jit_parallel(func):
    """Compile a batch kernel that splits its ``prange`` loop over all cores (cached on disk)."""
    return njit(cache=True, nogil=True, parallel=True, error_model="numpy", fastmath=FASTMATH)(func)


def cached_signatures(kernel) -> list[tuple]:
    """The argument types of every compiled version of ``kernel`` in the on-disk cache (Numba's index file, an
    internal detail: an empty list when it cannot be read)."""
    try:
        index = kernel._cache._cache_file._load_index()
        return [key[0] for key in index]
    except Exception:  # any failure to read Numba's internals means "not known to be cached"
        return []


def is_cached(*kernels) -> bool:
    """Whether every one of ``kernels`` (compiled functions) has machine code in the on-disk cache, current for its
    sources, i.e. whether calling them will load rather than compile.  Reads Numba's index file, an internal detail:
    when it cannot be read, says False (the cost is a needless notice)."""
    return all(cached_signatures(k) for k in kernels)
