"""`lightprobe check`'s verification of user techniques: a right one passes, each typical mistake fails with the
message that names it, and every way a call can go wrong is one clear error."""

from pathlib import Path

import pytest

from lightprobe.lab.check import check_technique, figure_png, write_html
from lightprobe.lab.techniques import TechniqueError, load_module, load_technique

HERE = Path(__file__).parent
TECHNIQUES = HERE / "user_techniques.py"
SOLUTIONS = HERE / "solutions" / "sampling.py"
N = 100_000


def check(name, path=TECHNIQUES, **kwargs):
    return check_technique(load_technique(f"{path}:{name}", time_limit=kwargs.pop("time_limit", 60.0)), samples=N,
                           **kwargs)  # fmt: skip


@pytest.mark.parametrize("name", ["UniformHemisphere", "CosineHemisphere", "PhongLobes", "EnvironmentMapSampler"])
def test_right_techniques_pass_every_check(name):
    report = check(name, SOLUTIONS)
    assert report.passed, report.text()
    names = {i.name for i in report.items}
    assert {"runs", "sample pdf = pdf()", "integrates to 1", "chi-square"} <= names
    integrals = [i.numbers["integral"] for i in report.items if i.name == "integrates to 1"]
    assert all(abs(v - 1.0) < 1e-2 for v in integrals)


def test_missing_jacobian_fails_and_says_so():
    report = check("MapWithoutSinTheta")
    failure = report.first_failure
    assert failure is not None and failure.name == "integrates to 1"
    assert "missing the sin theta of the lat-long Jacobian" in failure.message
    assert not 0.99 < failure.numbers["integral"] < 1.01


def test_pdf_of_the_wrong_lobe_fails_sample_pdf_check():
    failure = check("PhongWithCosinePdf").first_failure
    assert failure is not None and failure.name == "sample pdf = pdf()"
    assert "pdf() must return the density sample() draws from" in failure.message
    assert failure.message.startswith("sample ")  # names the first offending sample


def test_non_normalised_pdf_fails_the_integral_naming_pi():
    failure = check("CosineUnnormalised").first_failure
    assert failure.name == "integrates to 1"
    assert "integrates to 3.14" in failure.message and "1/pi" in failure.message


def test_direction_below_the_surface_fails():
    failure = check("CosineBelow").first_failure
    assert failure.name == "below the surface"
    assert "below the surface" in failure.message and "z = -" in failure.message


def test_consistent_but_wrong_distribution_fails_only_chi_square():
    report = check("UniformClaimedCosine")
    failed = [i.name for i in report.items if not i.passed]
    assert failed and set(failed) == {"chi-square"}, report.text()


@pytest.mark.parametrize(
    ("name", "words"),
    [
        ("Raises", ["Raises.sample raised ValueError: my bug", "user_techniques.py", "check: sample runs", "u = "]),
        ("Exits", ["Exits.sample raised SystemExit: 0", "line ", "check: sample runs"]),
        ("ReturnsNaN", ["pdf is not finite at sample 3", "check: finite values"]),
        ("NegativePdf", ["negative pdf -1 at sample 0", "check: pdf >= 0"]),
        ("WrongShape", ["wi has shape (100000, 2), expected (100000, 3)"]),
        ("NotUnit", ["wi is not a unit vector at sample 0", "|wi| = 2"]),
        ("TextResult", ["has dtype <U1, expected float"]),
    ],
)
def test_bad_output_is_one_clear_failure(name, words):
    report = check(name)
    failure = report.first_failure
    assert failure is not None and failure.name == "runs"
    assert "\n" not in failure.message
    for w in words:
        assert w in failure.message, failure.message


def test_a_slow_technique_is_stopped():
    report = check("Slow", time_limit=0.3)
    assert "took longer than 0.3 s" in report.first_failure.message


def test_loading_errors_name_the_file(tmp_path):
    with pytest.raises(TechniqueError, match="no such technique file"):
        load_technique(str(tmp_path / "missing.py"))
    bad = tmp_path / "bad.py"
    bad.write_text("def f(:\n")
    with pytest.raises(TechniqueError, match=r"bad.py: line 1: syntax error"):
        load_technique(str(bad))
    with pytest.raises(TechniqueError, match=r"no technique named 'Nope'.*Cosine"):
        load_technique(f"{TECHNIQUES}:Nope")
    with pytest.raises(TechniqueError, match="name one technique"):
        load_technique(str(TECHNIQUES))
    one = tmp_path / "one.py"
    one.write_text(
        "import numpy as np\nclass Only:\n    def sample(self, u, ctx): pass\n    def pdf(self, wi, ctx): pass\n"
    )
    assert load_technique(str(one)).label == "one.py:Only"
    kind = tmp_path / "kind.py"
    kind.write_text(
        "class K:\n    kind = 'area'\n    def sample(self, u, ctx): pass\n    def pdf(self, wi, ctx): pass\n"
    )
    with pytest.raises(TechniqueError, match="kind must be one of"):
        load_technique(str(kind))


def test_an_unchanged_file_is_imported_once_and_a_changed_one_again(tmp_path):
    """A second load of the same bytes returns the first import's module (its njit functions keep what Numba
    compiled for them); new bytes at the same path are imported anew, and a file that failed is tried again."""
    path = tmp_path / "mine.py"
    path.write_text("import numba\nIMPORTS = []\nIMPORTS.append(1)\n@numba.njit\ndef f(x):\n    return x + 1\n")
    first = load_module(path)
    assert first.f(1) == 2
    again = load_module(path)
    assert again is first and again.f is first.f and len(again.IMPORTS) == 1
    assert len(first.f.overloads) == 1  # compiled once, kept
    path.write_text("import numba\nIMPORTS = []\n@numba.njit\ndef f(x):\n    return x + 2\n")
    changed = load_module(path)
    assert changed is not first and changed.f(1) == 3
    broken = tmp_path / "broken.py"
    broken.write_text("raise ValueError('not yet')\n")
    for _ in range(2):  # a failed import is not remembered: each load reports it
        with pytest.raises(TechniqueError, match="importing it raised ValueError: not yet"):
            load_module(broken)
    broken.write_text("X = 1\n")
    assert load_module(broken).X == 1


def test_pictures_and_page(tmp_path):
    report = check("CosineUnnormalised")
    png = figure_png(report)
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000
    write_html(report, tmp_path / "c.html")
    page = (tmp_path / "c.html").read_text()
    assert "FAILED" in page and "integrates to 3.14" in page and "data:image/png;base64," in page
