"""The user guide's promise for bad input, checked command by command: every command of `lightprobe --help` given
a damaged file (a reference checkpoint cut short, overwritten or empty; a technique file that raises, exits, ends the
process or does not parse; a glTF file whose indices name nothing; a corrupt PNG as a texture or a map; a scene file
with a bad key; an exercise folder that is a file) exits with status 2 and one line, `lightprobe: error: ...`,
naming the file or the key; no traceback and no library's own error line anywhere; and no file of the user's
deleted or changed. Each command stops at the damaged file, before rendering: the tests are quick and need no
render core."""

from __future__ import annotations

import base64
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from lightprobe.cli import main

SCENE = (
    "[camera]\norigin = [0, 0, 4]\ntarget = [0, 0, 0]\nresolution = [16, 12]\n"
    "[environment]\nconstant = [1.0, 1.0, 1.0]\n"
    '[materials.white]\ntype = "lambert"\nalbedo = 0.5\n'
    '[[objects]]\ntype = "sphere"\ncenter = [0, 0, 0]\nradius = 1\nmaterial = "white"\n'
)
TECHNIQUE = (
    "import numpy as np\n\n\nclass Cosine:\n    kind = 'bsdf'\n\n    def sample(self, u, ctx):\n"
    "        r, phi, z = np.sqrt(u[:, 0]), 2 * np.pi * u[:, 1], np.sqrt(1 - u[:, 0])\n"
    "        return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1), z / np.pi\n\n"
    "    def pdf(self, wi, ctx):\n        return np.maximum(wi[:, 2], 0) / np.pi\n"
)
#: a technique file's ways of going wrong when imported
TECHNIQUE_ENDINGS = {
    "raises": "raise RuntimeError('half written')\n",
    "sys.exit": "import sys\nsys.exit(0)\n",
    "os._exit": "import os\nos._exit(0)\n",
    "syntax error": "def broken(:\n",
}


def _gltf_with_a_bad_index() -> str:
    """One triangle whose POSITION accessor names buffer view 9 (the file has one)."""
    blob = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32).tobytes()
    doc = {
        "asset": {"version": "2.0"},
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "accessors": [{"bufferView": 9, "componentType": 5126, "count": 3, "type": "VEC3"}],
        "bufferViews": [{"buffer": 0, "byteLength": len(blob)}],
        "buffers": [{"byteLength": len(blob), "uri": "data:application/octet-stream;base64,"
                     + base64.b64encode(blob).decode()}],
    }  # fmt: skip
    return json.dumps(doc)


def _damaged_folder(root: Path) -> Path:
    """Every damaged input of the cases below, beside good ones, in ``root``."""
    from lightprobe.images import write_png
    from lightprobe.lab.exercise import init_exercise

    (root / "scene.toml").write_text(SCENE)
    (root / "bad_key.toml").write_text(SCENE.replace("albedo = 0.5", "albedo = 0.5\nalbdo = 0.5"))
    (root / "bad.gltf").write_text(_gltf_with_a_bad_index())
    (root / "gltf.toml").write_text(SCENE + '[[objects]]\ntype = "gltf"\nfile = "bad.gltf"\n')
    png = write_png(root / "good.png", np.random.default_rng(7).random((16, 16, 3))).read_bytes()
    (root / "bad.png").write_bytes(png[: len(png) // 2])
    (root / "texture.toml").write_text(SCENE.replace("albedo = 0.5", 'albedo = 0.5\nbase_color_texture = "bad.png"'))
    for name, ending in TECHNIQUE_ENDINGS.items():
        (root / f"{_slug(name)}.py").write_text(TECHNIQUE + ending)
        exercise = root / f"exercise_{_slug(name)}"
        init_exercise(exercise)
        (exercise / "sampling.py").write_text(TECHNIQUE + ending)
    (root / "light.py").write_text(TECHNIQUE.replace("Cosine", "Light").replace("'bsdf'", "'light'"))
    (root / "a_file").write_text("not a folder")
    for damage in ("truncated", "garbage", "empty"):
        (root / damage).mkdir()
        (root / damage / "scene.toml").write_text(SCENE)
    return root


def _checkpoints(root: Path) -> None:
    """Damaged checkpoints of ``root/{truncated,garbage,empty}/ref.exr``, made from one in the format of
    analysis/reference.py (16 x 12 pixels at 2 spp; not rendered, so that this file needs no render core)."""
    import io

    from lightprobe.integrators.accumulation import Accumulator

    acc = Accumulator(16 * 12)
    acc.count[:] = 2
    buffer = io.BytesIO()
    np.savez(buffer, identity=np.array(json.dumps({"settings": {}, "counts": "resolved"})), **acc.to_arrays())
    data = buffer.getvalue()
    (root / "truncated" / "ref.exr.checkpoint.npz").write_bytes(data[: len(data) // 3])
    (root / "garbage" / "ref.exr.checkpoint.npz").write_bytes(data[:2000] + b"\xab" * 400 + data[2400:])
    (root / "empty" / "ref.exr.checkpoint.npz").write_bytes(b"")


def _slug(name: str) -> str:
    return name.replace(".", "_").replace(" ", "_")


#: (what, the command line in the damaged folder, what its error must name)
CASES = [
    *[(f"reference, {damage} checkpoint", f"reference {damage}/scene.toml -o {damage}/ref.exr",
       f"{damage}/ref.exr.checkpoint.npz: damaged checkpoint") for damage in ("truncated", "garbage", "empty")],
    *[case for name in TECHNIQUE_ENDINGS for case in (
        (f"check, technique that {name}", f"check {_slug(name)}.py:Cosine -o c.html", f"{_slug(name)}.py"),
        (f"render, technique that {name}", f"render scene.toml --techniques {_slug(name)}.py:Cosine -o r.exr -q",
         f"{_slug(name)}.py"),
        (f"compare, technique that {name}", f"compare scene.toml --strategies mis,{_slug(name)}.py:Cosine -o r.html "
         "-q", f"{_slug(name)}.py"),
        (f"exercise check, sampling.py that {name}", f"exercise check exercise_{_slug(name)}", "sampling.py"),
    )],
    *[(f"{command}, glTF with a bad index", f"{command} gltf.toml -o r.{out} -q",
       "bad.gltf: accessors[0].bufferView: bufferView 9 does not exist")
      for command, out in (("render", "exr"), ("reference", "exr"), ("compare", "html"))],
    *[(f"{command}, corrupt PNG texture", f"{command} texture.toml -o r.{out} -q", "bad.png: cannot read image")
      for command, out in (("render", "exr"), ("reference", "exr"), ("compare", "html"))],
    *[(f"{command}, scene file with a bad key", f"{command} bad_key.toml -o r.{out} -q", "albdo")
      for command, out in (("render", "exr"), ("reference", "exr"), ("compare", "html"))],
    ("envmap info, corrupt PNG map", "envmap info bad.png", "bad.png: cannot read image"),
    ("envmap convert, corrupt PNG map", "envmap convert bad.png out.exr --to angular", "bad.png: cannot read image"),
    ("envmap pdf, corrupt PNG map", "envmap pdf bad.png -o pdf.png", "bad.png: cannot read image"),
    ("check, corrupt PNG map", "check light.py:Light --envmap bad.png -o c.html", "bad.png: cannot read image"),
    ("experiment shading-point, corrupt PNG map", "experiment shading-point --maps bad.png --samples 1000",
     "bad.png: cannot read image"),
    *[(f"experiment {name}, corrupt PNG map", f"experiment {name} --maps bad.png --spp 1 --reference-spp 1 --width 8 "
       "-o out", "bad.png: cannot read image") for name in ("krivanek-mis", "pbrt-envmap-vs-cosine")],
    ("exercise init, a file as the folder", "exercise init a_file", "a_file: exists and is not a directory"),
]  # fmt: skip


@pytest.fixture(scope="module")
def damaged(tmp_path_factory):
    root = _damaged_folder(tmp_path_factory.mktemp("damaged"))
    _checkpoints(root)
    return root


def _files(root: Path) -> dict[Path, bytes]:
    return {p: p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def _run(args: list[str], capfd) -> tuple[int, str, str]:
    """The command as a user runs it: in a process of its own when a file may end the process (os._exit would end
    the test's), else through main() with the process's stdout and stderr captured (libpng writes to the latter's
    file descriptor, not through Python)."""
    if any("os__exit" in a for a in args):
        out = subprocess.run([sys.executable, "-m", "lightprobe", *args], capture_output=True, text=True, timeout=300)
        return out.returncode, out.stdout, out.stderr
    capfd.readouterr()
    try:
        status = main(args)
    except BaseException as exc:  # what escapes main() is what the test is about
        import traceback

        status, escaped = 99, "Traceback (escaped main()):\n" + "".join(traceback.format_exception(exc))
    else:
        escaped = ""
    out, err = capfd.readouterr()
    return status, out, err + escaped


@pytest.mark.parametrize(("command", "names"), [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_a_damaged_input_is_one_line_and_loses_nothing(damaged, capfd, monkeypatch, command, names):
    monkeypatch.chdir(damaged)
    before = _files(damaged)
    status, out, err = _run(command.split(), capfd)
    errors = [line for line in err.splitlines() if line.startswith("lightprobe: error:")]
    assert status == 2 and len(errors) == 1, (status, out, err)
    assert names in errors[0], errors[0]
    assert "Traceback" not in out + err, out + err
    others = [line for line in err.splitlines() if line not in errors]
    assert not [line for line in others if "error" in line.lower()], err  # a library's own error line (libpng)
    after = _files(damaged)
    assert [p for p in before if p not in after] == [], "files deleted"
    assert [p for p in before if after.get(p, before[p]) != before[p]] == [], "files changed"


#: commands that read no file of the user's (their inputs are numbers and names)
READ_NO_FILES = {"doctor", "experiment lecture-area-sampling", "experiment lecture-many-lights"}


def test_every_command_that_reads_a_file_has_a_case():
    """The cases cover the commands of `lightprobe --help`: a new command that reads files gets its damaged ones."""
    import typer.main

    from lightprobe.cli import app

    def leaves(command, prefix=""):
        subcommands = getattr(command, "commands", None)
        if not subcommands:
            return [prefix.strip()]
        return [leaf for name, sub in subcommands.items() for leaf in leaves(sub, f"{prefix} {name}")]

    every = set(leaves(typer.main.get_command(app)))
    covered = {" ".join(case[1].split()[: 2 if case[1].split()[0] in ("envmap", "experiment", "exercise") else 1])
               for case in CASES}  # fmt: skip
    assert every - READ_NO_FILES == covered, (every - READ_NO_FILES) ^ covered
