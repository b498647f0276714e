"""The code's style is checked with the suite: ruff's lint rules and its formatter (pyproject.toml's [tool.ruff]),
over the package, the tests and the benchmarks.  A docstring line past 120 characters once landed with the suite
green, because nothing ran ruff; now the suite does (ruff is one of the ``test`` extras)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
TREES = ("src", "tests", "benchmarks")


def _ruff() -> list[str]:
    """The command that runs ruff: the executable beside this Python (the venv's), else one on PATH."""
    beside = Path(sys.executable).with_name("ruff")
    if beside.exists():
        return [str(beside)]
    found = shutil.which("ruff")
    if found is None:
        pytest.fail("ruff is not installed: pip install -e '.[test]' installs it")
    return [found]


@pytest.mark.parametrize("check", [["check"], ["format", "--check"]], ids=["lint", "format"])
def test_ruff_finds_nothing(check):
    out = subprocess.run([*_ruff(), *check, *TREES], cwd=ROOT, capture_output=True, text=True)
    assert out.returncode == 0, f"ruff {' '.join(check)}:\n{out.stdout[-3000:]}{out.stderr[-1000:]}"
