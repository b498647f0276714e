"""The README's commands run, so that it stays true.

Every `lightprobe ...` command of README.md runs through `lightprobe.cli.main`, in-process, at a tiny size: the
commands of its shell code blocks (with or without `.venv/bin/`, and the parts of an `&&` chain), in order, one test
per block, and the commands of its inline code spans, one test each. Each runs in a temporary working directory, so
every output (`-o X`, `--png X`, a report's default name) lands there; the README's files (a code block whose first
line is `# NAME.toml` or `# NAME.py`, such as scene.toml and my_sampling.py) are written there first, as the README
tells its reader to; paths under `examples/` are the repository's, paths under `../shared/data` the shared data's.
SMALL puts `--spp 1`, `--width 16` and the like in place of (or beside) a command's own options, so that each takes
seconds. A command that reads `../shared/data` is skipped when the data is absent; a block whose commands all need it
is skipped. A command must exit 0 (EXPECTED_STATUS lists the exceptions: `exercise check` on the exercise as
`exercise init` writes it fails its step 1), so a renamed command or option fails here (exit status 2).

Not run: the first block's install (`python3 -m venv`, `pip install`) and its test command (`python -m pytest`);
test_the_first_block_is_install_demo_and_the_suite checks that block word for word and that .ci/run runs the same
test command.

Also: every relative link of README.md and docs/user_guide.md names a file that exists (and, with `#anchor`, a
heading of it), and the user guide's full scene-file example is io/scene_file.py's docstring, word for word.
"""

from __future__ import annotations

import re
import shlex
import textwrap
from pathlib import Path

import pytest

from lightprobe.cli import main
from lightprobe.data import data_dir

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
USER_GUIDE = ROOT / "docs" / "user_guide.md"
DATA = data_dir()

INSTALL_AND_DEMO = (
    "python3 -m venv .venv && .venv/bin/pip install -e '.[test]' && .venv/bin/lightprobe render --demo -o demo.png"
)
TEST_COMMAND = ".venv/bin/python -m pytest"

#: Options put in place of a command's own (or added), by the command's words before its arguments: a tiny render.
SMALL = {
    ("render",): {"--spp": "1", "--width": "16"},
    ("compare",): {"--spp": "1", "--width": "16", "--reference-spp": "2", "--seconds": "0.5"},
    ("reference",): {"--spp": "2", "--chunk": "1"},
    ("check",): {"--samples": "20000"},
    ("exercise", "check"): {"--samples": "2000"},
}
#: Flags added where the command has them: no progress bars.
QUIET = {("render",), ("compare",), ("reference",)}
#: Exit statuses other than 0, and what the output must then say.
EXPECTED_STATUS = {("exercise", "check"): (1, "step 1 (UniformHemisphere)")}
SUBCOMMANDS = {"envmap", "exercise", "experiment"}


def code_blocks(text: str) -> list[tuple[str, str]]:
    """(language, body) of every fenced code block."""
    return re.findall(r"^```(\w*)\n(.*?)^```", text, re.S | re.M)


def file_blocks(text: str) -> dict[str, str]:
    """The README's files: code blocks whose first line is `# NAME.toml` or `# NAME.py` (and what follows)."""
    files = {}
    for _, body in code_blocks(text):
        m = re.match(r"# ([\w.-]+\.(?:toml|py))\b", body)
        if m:
            files[m.group(1)] = body
    return files


def commands_of(line: str) -> list[list[str]]:
    """The lightprobe commands of one shell line: its `&&` parts that run lightprobe, as argument lists (without
    the program), comments dropped."""
    words = shlex.split(line, comments=True)
    parts, current = [], []
    for word in [*words, "&&"]:
        if word == "&&":
            parts.append(current)
            current = []
        else:
            current.append(word)
    return [p[1:] for p in parts if p and (p[0] == "lightprobe" or p[0].endswith("/lightprobe"))]


def shell_blocks(text: str) -> list[list[list[str]]]:
    """The commands of every shell code block (a block without a language), one list per block."""
    blocks = []
    for language, body in code_blocks(text):
        if language:
            continue
        commands = [c for line in body.splitlines() for c in commands_of(line)]
        if commands:
            blocks.append(commands)
    return blocks


def inline_commands(text: str) -> list[list[str]]:
    """The commands of the inline code spans that start with `lightprobe `."""
    prose = re.sub(r"^```.*?^```", "", text, flags=re.S | re.M)
    return [shlex.split(span)[1:] for span in re.findall(r"`(lightprobe [^`]+)`", prose)]


def command_key(args: list[str]) -> tuple[str, ...]:
    return tuple(args[:2]) if args and args[0] in SUBCOMMANDS else tuple(args[:1])


def small(args: list[str]) -> list[str]:
    """The command at a tiny size: SMALL's options replace the command's own or are added; QUIET adds -q."""
    key = command_key(args)
    if "--help" in args:
        return list(args)
    options = dict(SMALL.get(key, {}))
    out = []
    i = 0
    while i < len(args):
        if args[i] in options:
            out += [args[i], options.pop(args[i])]
            i += 2
            continue
        out.append(args[i])
        i += 1
    for option, value in options.items():
        out += [option, value]
    if key in QUIET and "-q" not in out:
        out.append("-q")
    return out


def localised(args: list[str]) -> list[str] | None:
    """Paths under examples/ made the repository's and under ../shared/data the shared data's; None when the
    command needs the shared data and it is absent (a scene file of the examples may name it too)."""
    out = []
    for arg in args:
        if arg.startswith("../shared/data/"):
            if DATA is None:
                return None
            arg = str(DATA / arg.removeprefix("../shared/data/"))
        elif arg.startswith("examples/"):
            path = ROOT / arg
            if path.suffix == ".toml":
                for rel in re.findall(r'file = "([^"]+)"', path.read_text()):
                    if not (path.parent / rel).exists():
                        return None
            arg = str(path)
        out.append(arg)
    return out


def run(args: list[str], capsys) -> str | None:
    """Run one README command at a tiny size; its output, or None when it needs data that is absent."""
    local = localised(small(args))
    if local is None:
        return None
    status = main(local)
    output = capsys.readouterr()
    text = output.out + output.err
    expected, says = EXPECTED_STATUS.get(command_key(args), (0, ""))
    assert status == expected, f"`lightprobe {shlex.join(args)}` exited {status}, not {expected}:\n{text}"
    assert says in text, f"`lightprobe {shlex.join(args)}` did not say {says!r}:\n{text}"
    return text


def write_files(folder: Path) -> None:
    for name, body in file_blocks(README.read_text()).items():
        (folder / name).write_text(body)


BLOCKS = shell_blocks(README.read_text())
INLINE = inline_commands(README.read_text())


def test_the_readme_has_commands_to_run():
    """The extraction finds what the README shows: the demo, its scene file, compare, the exercise, a technique."""
    everything = [shlex.join(c) for block in BLOCKS for c in block] + [shlex.join(c) for c in INLINE]
    for expected in ("render --demo -o demo.png", "render scene.toml", "compare", "exercise init", "check my_"):
        assert any(c.startswith(expected) for c in everything), (expected, everything)
    assert {"scene.toml", "my_sampling.py"} <= set(file_blocks(README.read_text()))


@pytest.mark.parametrize("block", BLOCKS, ids=lambda b: shlex.join(b[0])[:60])
def test_readme_block_runs(block, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    write_files(tmp_path)
    ran = [args for args in block if run(args, capsys) is not None]
    if not ran:
        pytest.skip("every command of this block needs ../shared/data, which is absent")


@pytest.mark.parametrize("args", INLINE, ids=lambda a: shlex.join(a)[:60])
def test_readme_inline_command_runs(args, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    write_files(tmp_path)
    if run(args, capsys) is None:
        pytest.skip("needs ../shared/data, which is absent")


def test_the_first_block_is_install_demo_and_the_suite():
    """The project's rule: the README's first code block installs and renders the demo, then runs the suite, and
    .ci/run runs the same test command."""
    _, first = code_blocks(README.read_text())[0]
    assert first.splitlines() == [INSTALL_AND_DEMO, TEST_COMMAND]
    assert TEST_COMMAND in (ROOT / ".ci" / "run").read_text().splitlines()


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces as hyphens."""
    text = re.sub(r"[`*_]|\[([^\]]*)\]\([^)]*\)", r"\1", heading.strip().lower())
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def anchors(path: Path) -> set[str]:
    prose = re.sub(r"^```.*?^```", "", path.read_text(), flags=re.S | re.M)
    seen: dict[str, int] = {}
    out = set()
    for heading in re.findall(r"^#{1,6} (.+)$", prose, re.M):
        base = slug(heading)
        n = seen.get(base, 0)
        seen[base] = n + 1
        out.add(base if n == 0 else f"{base}-{n}")
    return out


@pytest.mark.parametrize("document", [README, USER_GUIDE], ids=lambda p: p.name)
def test_relative_links_point_to_files_and_headings(document):
    prose = re.sub(r"^```.*?^```", "", document.read_text(), flags=re.S | re.M)
    links = re.findall(r"\]\(([^)\s]+)\)", prose)
    assert links
    broken = []
    for link in links:
        if re.match(r"[a-z]+:", link):
            continue
        target, _, anchor = link.partition("#")
        path = (document.parent / target).resolve() if target else document
        if not path.exists():
            broken.append(f"{link}: no such file")
        elif anchor and path.suffix == ".md" and anchor not in anchors(path):
            broken.append(f"{link}: no heading #{anchor} in {path.name}")
    assert not broken, broken


def test_the_user_guides_scene_file_is_the_formats_docstring():
    """The user guide's "every key" example is the one io/scene_file.py documents (and its tests load)."""
    import lightprobe.io.scene_file as scene_file

    doc = scene_file.__doc__
    start = doc.index("::\n\n") + 3
    documented = textwrap.dedent(doc[start : doc.index("\nEvery mistake is")]).strip("\n")
    guide = USER_GUIDE.read_text()
    section = guide[guide.index("### Every key") :]
    shown = re.search(r"```toml\n(.*?)\n```", section, re.S).group(1)
    assert shown == documented
