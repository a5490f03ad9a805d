"""The rigid-motion teaching report: renders in every format, its LaTeX compiles, the CLI shows it."""
import shutil
import subprocess

import pytest

from ncgen.cli import main
from ncgen.symbolic.se3_report import se3_report


@pytest.fixture(scope="module")
def report():
    return se3_report()


def test_report_content(report):
    titles = [s.title for s in report.steps]
    for expected in ("Rotations", "Poses: homogeneous matrices", "Body twist", "Adjoint and adjacency",
                     "Derivative of the adjoint", "Exponential", "Logarithm", "Wrenches",
                     "Spatial mass matrix", "Homogeneous solids", "Newton-Euler equations"):
        assert expected in titles
    text = report.render("text")
    assert "ω" in text and "ad(T)" in text
    assert report.render("markdown").startswith("# Rigid motion")


def test_latex_compiles(report, tmp_path):
    if shutil.which("pdflatex") is None:
        pytest.skip("pdflatex is not installed")
    (tmp_path / "se3.tex").write_text(report.render("latex"))
    run = subprocess.run(["pdflatex", "-interaction=nonstopmode", "-halt-on-error", "se3.tex"],
                         cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stdout[-2000:]
    assert (tmp_path / "se3.pdf").stat().st_size > 0


@pytest.mark.slow      # SE(3)'s derivation a second time; fast: test_report_content (the same derivation) and
#                       tests/test_cli_derive.py::test_derive_every_type_and_format (`ncgen derive`)
def test_cli_derive_se3(capsys):
    assert main(["derive", "se3"]) == 0
    assert "Newton-Euler" in capsys.readouterr().out
