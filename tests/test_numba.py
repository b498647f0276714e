"""The Numba configuration every kernel shares (``lightprobe._numba``): the inliner's one-pass copy."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numba import njit
from numba.core import inline_closurecall
from numba.core.compiler import run_frontend

from lightprobe import _numba


def _branchy(x, n):  # several blocks (a loop, branches), several variables
    total = 0.0
    for i in range(n):
        if x > i:
            total += x - i
        else:
            total -= 0.5 * i
    return total if total > 0 else -total


def test_the_inliner_copies_a_function_in_one_pass_on_this_numba():
    # Installed on the Numba the project pins: without it the render core compiles about a fifth slower
    # (decisions.md 92).  A Numba whose inliner copies some other way fails here, so that the loss is seen.
    assert _numba.INLINE_COPY_IN_ONE_PASS, "lightprobe._numba could not install the inliner's one-pass copy"
    assert inline_closurecall.copy is not __import__("copy")


def test_a_functions_blocks_copied_after_its_copy_share_one_new_scope():
    function_ir = run_frontend(_branchy)
    assert len(function_ir.blocks) >= 4
    scope = next(iter(function_ir.blocks.values())).scope
    assert all(block.scope is scope for block in function_ir.blocks.values())

    function_ir.copy()  # what the inliner's copy_ir does first, then one deepcopy per block
    copies = {label: inline_closurecall.copy.deepcopy(block) for label, block in function_ir.blocks.items()}
    new_scopes = {id(block.scope) for block in copies.values()}
    assert len(new_scopes) == 1 and id(scope) not in new_scopes  # one copied scope, not the original's
    for label, block in copies.items():  # a deep copy: same statements, none of the original objects
        original = function_ir.blocks[label]
        assert [str(s) for s in block.body] == [str(s) for s in original.body]
        assert all(a is not b for a, b in zip(block.body, original.body, strict=True))

    # a block copied again outside such a copy gets its own scope, as copy.deepcopy gives it
    again = inline_closurecall.copy.deepcopy(next(iter(function_ir.blocks.values())))
    assert again.scope is not scope and id(again.scope) not in new_scopes
    assert inline_closurecall.copy.copy is __import__("copy").copy  # the rest of the module is the real one


@njit(inline="always")
def _inner(x, n):
    return _branchy_jit(x, n) + _branchy_jit(-x, n)


_branchy_jit = njit(inline="always")(_branchy)


@njit(inline="always")
def _middle(x, n):
    a = _inner(x, n)
    if a > 3.0:
        return a + _inner(x + 1.0, n)
    return a - _inner(x - 1.0, n)


@njit
def _outer(xs, n):
    out = np.empty_like(xs)
    for i in range(xs.size):
        out[i] = _middle(xs[i], n) + _branchy_jit(xs[i], n)
    return out


def test_nested_inlined_helpers_compute_what_python_computes():
    # helpers inlined into helpers at several sites: each site renames and rewires its own copy of the callee
    def inner(x, n):
        return _branchy(x, n) + _branchy(-x, n)

    def middle(x, n):
        a = inner(x, n)
        return a + inner(x + 1.0, n) if a > 3.0 else a - inner(x - 1.0, n)

    xs = np.linspace(-7.0, 9.0, 41)
    expected = np.array([middle(x, 6) + _branchy(x, 6) for x in xs])
    np.testing.assert_array_equal(_outer(xs, 6), expected)


# --- the cache: kernels stamped by their modules' import closure (decisions.md 104) ---------------------------------
def _package(root, files: dict[str, str]):
    package = root / "pkg"
    for name, text in files.items():
        path = package / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return package


def test_an_edit_changes_the_stamps_of_the_modules_that_reach_it_and_no_others(tmp_path):
    """a imports b (relative, from a subpackage), b imports c, d imports nothing of the package, e imports c only
    inside a function (never in a jitted one's reach): an edit to c changes a's, b's and c's stamps, not d's or e's;
    an edit to a changes a's alone."""
    package = _package(
        tmp_path,
        {
            "__init__.py": "",
            "a.py": "from .sub.b import g\nimport numpy\n",
            "sub/__init__.py": "",
            "sub/b.py": "from .. import c\ntry:\n    from ..c import h\nexcept ImportError:\n    pass\n",
            "c.py": "X = 1\n",
            "d.py": "import math\n",
            "e.py": "def later():\n    from . import c\n",
        },
    )
    before = _numba.import_closure_stamps(package)
    (package / "c.py").write_text("X = 2\n")
    after = _numba.import_closure_stamps(package)
    changed = {Path(p).relative_to(package).as_posix() for p in before if before[p] != after[p]}
    assert changed == {"a.py", "sub/b.py", "c.py"}
    (package / "a.py").write_text("from .sub.b import g\nimport numpy  # edited\n")
    again = _numba.import_closure_stamps(package)
    assert {Path(p).relative_to(package).as_posix() for p in after if after[p] != again[p]} == {"a.py"}


def test_the_package_kernels_carry_their_import_closure_stamp():
    """On this Numba the rules are installed: a cached kernel of the package (the stage loop) is stamped with its
    module's closure stamp, not with its own file's hash, and the index is written under a lock."""
    from numba.core import caching

    from lightprobe.integrators import pipeline

    assert _numba.STAMPED_BY_IMPORTS
    stamp = pipeline.run_stage._cache._cache_file._source_stamp
    assert stamp == _numba._closure_stamps()[str(Path(pipeline.__file__).resolve())]
    assert getattr(caching.IndexDataCacheFile.save, "_lightprobe", False)


def test_a_cache_index_naming_a_module_that_is_gone_is_a_miss(tmp_path):
    """An index pickles its versions' signatures, which name their types' modules; after an upgrade that moved one,
    Numba's loader raised ModuleNotFoundError from the kernel's first call.  The installed loader reads it as an
    empty index (the kernel is compiled again and the index rewritten), and still reads a good one."""
    import pickle
    import sys
    import types

    from numba.core import caching

    gone = types.ModuleType("lightprobe_module_that_moved")

    class Moved:
        pass

    Moved.__module__ = gone.__name__
    Moved.__qualname__ = "Moved"
    gone.Moved = Moved
    sys.modules[gone.__name__] = gone
    try:
        payload = pickle.dumps(("stamp", {"signature": Moved()}))
    finally:
        del sys.modules[gone.__name__]
    index = caching.IndexDataCacheFile.__new__(caching.IndexDataCacheFile)
    index._index_path = str(tmp_path / "f.nbi")
    index._version = "v"
    index._source_stamp = "stamp"
    for data, expected in ((payload, {}), (pickle.dumps(("stamp", {"k": 1})), {"k": 1})):
        with open(index._index_path, "wb") as f:
            pickle.dump("v", f)
            f.write(data)
        assert getattr(caching.IndexDataCacheFile._load_index, "_lightprobe", False)
        assert index._load_index() == expected
