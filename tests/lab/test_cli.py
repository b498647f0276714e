"""The laboratory's commands as a user runs them: `check`, `exercise init/check`, and `compare` with a user
strategy (exit statuses, files written, one-line errors)."""

import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from lightprobe.cli import main

HERE = Path(__file__).parent
SOLUTIONS = HERE / "solutions" / "sampling.py"
TECHNIQUES = HERE / "user_techniques.py"


def test_check_passes_and_writes_page_and_picture(tmp_path, capsys):
    out = tmp_path / "phong.html"
    args = ["check", f"{SOLUTIONS}:PhongLobes", "--samples", "50000", "-o", str(out), "--json"]
    assert main(args) == 0
    row = json.loads(capsys.readouterr().out)
    assert row["passed"] and row["technique"] == "sampling.py:PhongLobes"
    assert out.read_text().count("<tr class='ok'>") == len(row["checks"])
    assert (tmp_path / "phong.png").read_bytes()[:4] == b"\x89PNG"


def test_check_failure_is_exit_1_with_the_verdict(tmp_path, capsys):
    out = tmp_path / "c.html"
    assert main(["check", f"{TECHNIQUES}:CosineUnnormalised", "--samples", "20000", "-o", str(out)]) == 1
    text = capsys.readouterr().out
    assert "FAIL" in text and "verdict: FAILED (integrates to 1" in text


def test_check_options_and_user_errors(tmp_path, capsys):
    out = str(tmp_path / "c.html")
    assert main(["check", f"{TECHNIQUES}:Cosine", "--samples", "20000", "-o", out,
                 "--material", "phong:rho_d=0.1,rho_s=0.8,exponent=200"]) == 0  # fmt: skip
    for args, message in [
        (["check", str(tmp_path / "none.py"), "-o", out], "none.py: no such technique file"),
        (["check", f"{TECHNIQUES}:Nope", "-o", out], "no technique named 'Nope'"),
        (["check", f"{TECHNIQUES}:Cosine", "-o", str(tmp_path / "c.txt")], "c.txt: the page is an .html file"),
        (["check", f"{TECHNIQUES}:Cosine", "--material", "phong:shiny=3", "-o", out], "--material: unknown key"),
        (["check", f"{TECHNIQUES}:Cosine", "--samples", "10", "-o", out], "samples must be >= 1000"),
    ]:
        capsys.readouterr()
        assert main(args) == 2, args
        err = capsys.readouterr().err.strip()
        assert err.startswith("lightprobe: error:") and message in err and "\n" not in err, err


def test_exercise_commands(tmp_path, capsys):
    target = tmp_path / "ex"
    assert main(["exercise", "init", str(target)]) == 0
    assert (target / "sampling.py").exists() and (target / "README.md").exists()
    assert main(["exercise", "init", str(target)]) == 2
    assert "already exists" in capsys.readouterr().err
    assert main(["exercise", "check", str(target), "--samples", "20000"]) == 1
    assert "step 1 (UniformHemisphere) is wrong" in capsys.readouterr().out
    shutil.copyfile(SOLUTIONS, target / "sampling.py")
    assert main(["exercise", "check", str(target), "--samples", "50000"]) == 0
    assert "all six steps pass" in capsys.readouterr().out


def test_compare_with_user_strategies_writes_the_report(tmp_path, capsys):
    target = tmp_path / "ex"
    main(["exercise", "init", str(target)])
    capsys.readouterr()
    report = tmp_path / "r.html"
    strategies = f"mis,mis:{SOLUTIONS}:PhongLobes,{SOLUTIONS}:EnvironmentMapSampler"
    args = ["compare", str(target / "scene.toml"), "--strategies", strategies, "--spp", "2", "--reference-spp", "8",
            "--width", "32", "-o", str(report), "--json", "-q"]  # fmt: skip
    assert main(args) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [r["strategy"] for r in rows][1:] == [f"mis:{SOLUTIONS}:PhongLobes", f"{SOLUTIONS}:EnvironmentMapSampler"]
    assert "EnvironmentMapSampler" in report.read_text()
    # a technique that fails mid-render: the report keeps what it rendered, the command says so and exits 2
    args[3] = f"mis,{TECHNIQUES}:FailsLater"
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "ran out of luck" in err and report.exists() and "stopped early" in report.read_text()
    # one count, said once: the first round's sample is what the strategy kept (it said "0 ... kept" here)
    assert "stopped at 1 spp" in err and "(during sample 1; 1 sample(s) per pixel kept)" in err, err
    args[3] = f"mis:{SOLUTIONS}:PhongLobes/bogus=1"
    assert main(args) == 2
    assert "'bogus=1' is not key=value with a key among" in capsys.readouterr().err


def test_render_with_user_techniques(tmp_path, capsys):
    target = tmp_path / "ex"
    main(["exercise", "init", str(target)])
    out = tmp_path / "mine.exr"
    token = f"mis:{SOLUTIONS}:PhongLobes+{SOLUTIONS}:EnvironmentMapSampler"
    args = ["render", str(target / "scene.toml"), "--techniques", token, "--spp", "2", "--width", "24", "-o", str(out)]
    assert main([*args, "-q"]) == 0
    sidecar = json.loads((tmp_path / "mine.exr.json").read_text())
    assert sidecar["strategy"].startswith("mis:sampling.py:PhongLobes+") and sidecar["spp_done"] == 2
    # a technique that fails on the second pass: the first pass is written, the command says so and exits 2
    capsys.readouterr()
    args[3] = f"{TECHNIQUES}:FailsLater"
    args[9] = str(tmp_path / "kept.exr")
    assert main([*args, "--spp", "8", "-q"]) == 2
    err = capsys.readouterr().err
    assert "ran out of luck" in err and "holds the 1 spp rendered before it" in err
    assert (tmp_path / "kept.exr").exists()


def test_render_with_njit_techniques_announces_their_compile(tmp_path, capsys):
    """njit techniques' loops are compiled on every run (a few seconds): said before it starts, like the core's."""
    target = tmp_path / "ex"
    main(["exercise", "init", str(target)])
    example = HERE.parents[1] / "examples" / "njit_sampling.py"
    capsys.readouterr()
    out = tmp_path / "njit.exr"
    token = f"mis:{example}:PhongLobes+{example}:EnvironmentMap"
    args = ["render", str(target / "scene.toml"), "--techniques", token, "--spp", "2", "--width", "24", "-o", str(out)]
    assert main([*args, "-q"]) == 0
    err = capsys.readouterr().err
    assert "compiling the techniques' loops (on every run" in err and "compiled the techniques' loops in" in err
    sidecar = json.loads((tmp_path / "njit.exr.json").read_text())
    assert sidecar["estimator"] == "lightprobe.lab (user techniques, compiled)" and sidecar["spp_done"] == 2
    # a NumPy technique with lightprobe's own (the NumPy estimator), or lightprobe's own alone (cached loops):
    # nothing compiled per run, nothing announced
    for token in [f"mis:{SOLUTIONS}:PhongLobes", "lab:mis"]:
        args[3] = token
        assert main([*args, "-q"]) == 0
        assert "compiling" not in capsys.readouterr().err


COSINE = (
    "import numpy as np\n\nclass Cosine:\n    kind = 'bsdf'\n\n    def sample(self, u, ctx):\n"
    "        r, phi = np.sqrt(u[:, 0]), 2 * np.pi * u[:, 1]\n        z = np.sqrt(1 - u[:, 0])\n"
    "        return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1), z / np.pi\n\n"
    "    def pdf(self, wi, ctx):\n        return np.maximum(wi[:, 2], 0) / np.pi\n"
)


@pytest.mark.parametrize(
    ("ending", "said"),
    [
        ("import sys\nsys.exit(0)\n", "line 14: importing it ended the program (sys.exit(0))"),
        ("raise SystemExit('bye')\n", "line 13: importing it ended the program (sys.exit('bye'))"),
        ("import os\nos._exit(0)\n", "importing it ended the whole process (exit status 0, as os._exit does)"),
        ("import os\nos._exit(7)\n", "importing it ended the whole process (exit status 7, as os._exit does)"),
        ("import os, signal\nos.kill(os.getpid(), signal.SIGKILL)\n", "importing it killed the process (SIGKILL)"),
    ],
)
def test_a_technique_file_that_ends_the_program_at_import_is_one_line(tmp_path, ending, said):
    """A file that calls sys.exit() or os._exit() when imported ended `check` with status 0 and nothing printed, which
    a student reads as a pass. Run as a user runs it (a process of its own): os._exit would end a test's process."""
    file = tmp_path / "mine.py"
    file.write_text(COSINE + ending)
    out = subprocess.run([sys.executable, "-m", "lightprobe", "check", f"{file}:Cosine", "--samples", "2000",
                          "-o", str(tmp_path / "c.html")], capture_output=True, text=True, timeout=300)  # fmt: skip
    lines = out.stderr.strip().splitlines()
    assert out.returncode == 2 and len(lines) == 1 and not out.stdout, (out.returncode, out.stdout, out.stderr)
    assert lines[0].startswith(f"lightprobe: error: {file}: ") and said in lines[0], lines
    assert not (tmp_path / "c.html").exists()


def test_the_time_limit_stops_a_slow_technique_and_keeps_its_passes(tmp_path, capsys):
    """--time-limit bounds a render with user techniques as it bounds the core's: a technique's call in flight at
    the limit is stopped and the passes before it written. Before, the limit was looked at between passes only, and
    a call ran on to the technique's own 60-s limit (an error)."""
    target = tmp_path / "ex"
    main(["exercise", "init", str(target)])
    out = tmp_path / "slow.exr"
    args = ["render", str(target / "scene.toml"), "--techniques", f"{TECHNIQUES}:SlowLater", "--spp", "8",
            "--width", "24", "--time-limit", "4", "-o", str(out), "-q"]  # fmt: skip
    capsys.readouterr()
    start = time.perf_counter()
    assert main(args) == 0, capsys.readouterr().err
    assert time.perf_counter() - start < 30.0  # the fourth call sleeps 100 s
    sidecar = json.loads((tmp_path / "slow.exr.json").read_text())
    assert sidecar["stopped_by_time_limit"] is True and sidecar["spp_done"] == 1
    assert "(stopped by the time limit)" in capsys.readouterr().err
    # a technique too slow for a single pass (5 s a call): nothing to write, and the command says so in one line
    args[3], args[9] = f"{TECHNIQUES}:Slow", "1"
    out.unlink()
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()  # the scene's summary, then the error
    assert err[1:] == [f"lightprobe: error: the time limit (1 s) ran out before the first pass was finished; {out} "
                       "was not written"], err  # fmt: skip
    assert not out.exists()
