"""The packaged Krivanek exercise: the skeleton fails `exercise check` as shipped, the reference solutions pass it,
and a typical mistake fails the step it belongs to with a message that says how."""

import shutil
from pathlib import Path

import pytest

from lightprobe.errors import LightprobeError
from lightprobe.lab.exercise import FILES, grade, init_exercise

SOLUTIONS = Path(__file__).parent / "solutions" / "sampling.py"


@pytest.fixture
def exercise(tmp_path):
    init_exercise(tmp_path / "ex")
    return tmp_path / "ex"


def test_init_writes_the_files_and_keeps_existing_ones(exercise):
    assert sorted(p.name for p in exercise.iterdir()) == sorted(FILES)
    assert "TODO step 4" in (exercise / "sampling.py").read_text()
    with pytest.raises(LightprobeError, match="already exists"):
        init_exercise(exercise)
    (exercise / "sampling.py").write_text("# mine")
    init_exercise(exercise, force=True)
    assert "TODO" in (exercise / "sampling.py").read_text()


def test_the_skeleton_fails_at_step_1(exercise):
    result = grade(exercise, samples=20_000)
    assert not result.passed
    assert result.steps[0].passed is False and "not written yet" in result.steps[0].message
    assert all(s.passed is None for s in result.steps[1:])


def test_the_reference_solutions_pass_every_step(exercise):
    shutil.copyfile(SOLUTIONS, exercise / "sampling.py")
    result = grade(exercise)
    assert result.passed, result.text()
    assert "matches lightprobe's" in result.steps[-1].message


def _with(exercise, old: str, new: str) -> None:
    text = SOLUTIONS.read_text()
    assert old in text
    (exercise / "sampling.py").write_text(text.replace(old, new))


def test_missing_jacobian_fails_step_4_and_says_so(exercise):
    _with(exercise, "self.density[j, i] / (2.0 * np.pi**2 * sin_theta)", "self.density[j, i] / (2.0 * np.pi**2)")
    result = grade(exercise, samples=50_000)
    step = result.steps[3]
    assert step.passed is False and "missing the sin theta of the lat-long Jacobian" in step.message, result.text()
    assert [s.passed for s in result.steps[:3]] == [True, True, True]


def test_brdf_normalisation_in_the_lobe_pdf_fails_step_3(exercise):
    _with(exercise, "(1.0 - p_d) * (n + 1.0) / (2.0 * np.pi)", "(1.0 - p_d) * (n + 2.0) / (2.0 * np.pi)")
    step = grade(exercise, samples=50_000).steps[2]
    assert step.passed is False and "integrates to 1" in step.message and "(n + 2) / (2 pi)" in step.message


def test_a_heuristic_without_the_counts_fails_step_5(exercise):
    _with(exercise, "a = n_f * np.asarray(p_f, dtype=np.float64)", "a = np.asarray(p_f, dtype=np.float64)")
    _with_more = (
        (exercise / "sampling.py")
        .read_text()
        .replace("b = n_g * np.asarray(p_g, dtype=np.float64)", "b = np.asarray(p_g, dtype=np.float64)")
    )
    (exercise / "sampling.py").write_text(_with_more)
    step = grade(exercise, samples=20_000).steps[4]
    assert step.passed is False and "balance_heuristic(4, " in step.message and "expected" in step.message


def test_errors_name_the_directory(tmp_path):
    with pytest.raises(LightprobeError, match=r"no sampling\.py here"):
        grade(tmp_path)
    (tmp_path / "sampling.py").write_text("import numpy as np\nraise RuntimeError('half written')\n")
    with pytest.raises(LightprobeError, match=r"sampling\.py: line 2: importing it raised RuntimeError"):
        grade(tmp_path)


def test_a_heuristic_that_exits_fails_step_5(exercise):
    """A sys.exit() in the student's heuristic ended `exercise check` with the student's status and no verdict."""
    _with(exercise, "    a = n_f * np.asarray(p_f, dtype=np.float64)", "    raise SystemExit(0)")
    step = grade(exercise, samples=20_000).steps[4]
    assert step.passed is False and "balance_heuristic(1, p_f, 1, p_g) raised SystemExit: 0" in step.message, step
