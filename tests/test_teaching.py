"""Teaching reports: what they show is the derivation, in the seed's form; LaTeX compiles."""
import shutil
import subprocess

import pytest
import sympy as sp
from sympy.matrices.expressions.kronecker import KroneckerProduct

from natural_helpers import ALL_TYPES, IDS, YBAR
from ncgen.cli import main
from ncgen.symbolic.coordinates import coordinate_type
from ncgen.symbolic.report import Report, latex_to_text
from ncgen.symbolic.teaching import FactorisationError, coordinates_report, kron_factor, phi_q_blocks


def _equations(rep: Report, lhs: str):
    return [e.rhs for s in rep.steps for e in s.equations if e.lhs == lhs]


@pytest.fixture(scope="module")
def reports():
    return {(d, n): coordinates_report(coordinate_type(n, d)) for d, n in ALL_TYPES}


@pytest.mark.parametrize("dim,name", ALL_TYPES, ids=IDS)
def test_report_shows_the_seed_Y_in_kronecker_form(reports, dim, name):
    rep = reports[(dim, name)]
    (Ybar,) = _equations(rep, r"\bar{Y}")
    assert Ybar == sp.Matrix(YBAR[(dim, name)])
    kron, full = _equations(rep, "Y")
    assert isinstance(kron, KroneckerProduct) and sp.Matrix(kron.args[0]) == Ybar
    assert full == coordinate_type(name, dim).derivation.Y


@pytest.mark.parametrize("dim,name", ALL_TYPES, ids=IDS)
def test_report_factorisations_rebuild_the_derivation(reports, dim, name):
    D = coordinate_type(name, dim).derivation
    rep = reports[(dim, name)]
    hess = [rhs for s in rep.steps for e in s.equations if e.lhs.startswith("H_") for rhs in [e.rhs]]
    assert len(hess) == len(D.hessians)
    for shown, H in zip(hess, D.hessians):
        assert sp.kronecker_product(sp.Matrix(shown.args[0]), sp.eye(dim)) == H
    (Mbar,) = _equations(rep, r"\bar{M}")
    assert (sp.kronecker_product(Mbar, sp.eye(dim)) - D.M).applyfunc(sp.expand) == sp.zeros(*D.M.shape)
    (G,) = _equations(rep, "G")
    assert G == D.G
    Cbar = _equations(rep, r"\bar{C}(c)" if D.ctype.k else r"\bar{C}")[0]
    assert (sp.kronecker_product(Cbar, sp.eye(dim)) - D.C).applyfunc(sp.expand) == sp.zeros(*D.C.shape)


@pytest.mark.parametrize("dim,name", [t for t in ALL_TYPES if t[1] != "r"], ids=[i for t, i in zip(ALL_TYPES, IDS) if t[1] != "r"])
def test_phi_q_block_form_expands_to_the_jacobian(dim, name):
    ct = coordinate_type(name, dim)
    D = ct.derivation
    blocks = phi_q_blocks(ct, D)
    # replace the block symbols u, v, w by the derived base vectors in terms of q
    sub = {sp.MatrixSymbol("uvw"[s], dim, 1): sp.ImmutableMatrix(D.x[s]) for s in range(ct.k)}
    expanded = sp.Matrix(blocks.xreplace(sub).as_explicit())
    assert (expanded - D.Phi_q).applyfunc(sp.expand) == sp.zeros(*D.Phi_q.shape)


def test_rrvw_shows_u_as_rj_minus_ri(reports):
    (u,) = _equations(reports[(3, "rrvw")], "u")
    r_i, r_j = sp.MatrixSymbol("r_i", 3, 1), sp.MatrixSymbol("r_j", 3, 1)
    assert sp.simplify(u - (r_j - r_i)) == sp.ZeroMatrix(3, 1)
    # vectors that are coordinates themselves are not restated (v = v)
    assert _equations(reports[(3, "rrvw")], "v") == []


@pytest.mark.parametrize("dim", [3, 2])
def test_uniform_bar_example(reports, dim):
    m = coordinate_type("rr", dim).derivation.m
    (rr,) = _equations(reports[(dim, "rr")], r"\bar{M}_{\mathrm{uniform}}")
    assert rr == m / 6 * sp.Matrix([[2, 1], [1, 2]])
    (ru,) = _equations(reports[(dim, "ru")], r"\bar{M}_{\mathrm{uniform}}")
    assert ru == sp.Matrix([[m, m / 2], [m / 2, m / 3]])


def test_inertia_formulas_are_the_derivation_objects(reports):
    D = coordinate_type("ruvw").derivation
    rep = reports[(3, "ruvw")]
    assert _equations(rep, "c_g") == [D.c_g_formula]
    assert _equations(rep, "B") == [D.B_formula]
    assert _equations(rep, r"\bar{J}") == [D.Jbar_formula]
    assert _equations(rep, r"\bar{X}^{+}") == [D.Xbar_pinv]


def test_kron_factor_rejects_non_kronecker_matrices():
    assert kron_factor(sp.kronecker_product(sp.Matrix([[1, 2], [3, 4]]), sp.eye(3)), 3) == sp.Matrix([[1, 2], [3, 4]])
    with pytest.raises(FactorisationError):
        kron_factor(sp.Matrix([[1, 1], [0, 1]]), 2)
    with pytest.raises(FactorisationError):
        kron_factor(sp.eye(3), 2)


@pytest.mark.parametrize("fmt", ["text", "markdown"])
def test_renderings_have_every_step(reports, fmt):
    for (dim, name), rep in reports.items():
        out = rep.render(fmt)
        for step in rep.steps:
            assert step.title in out
        if fmt == "text":
            assert "\\" not in out, f"LaTeX left in the text rendering of {name} ({dim}D)"


def test_text_alignment_with_accented_names():
    # regression: the padding of a multi-line equation counted the combining macron of Ȳ
    text = coordinates_report(coordinate_type("rr", 3)).render("text")
    lines = text.splitlines()
    i = next(k for k, line in enumerate(lines) if "Y\u0304 = " in line)
    block = lines[i - 1:i + 2]
    cols = [len(line.replace("\u0304", "")) - len(line.replace("\u0304", "").lstrip()) for line in (block[0], block[2])]
    assert cols[0] == cols[1] == block[1].replace("\u0304", "").index("⎢")


def test_latex_to_text_handles_greek_accents():
    assert latex_to_text(r"\hat{\omega} = \dot{X} \bar{G}") == "\u03c9\u0302 = X\u0307 G\u0304"


def test_jupyter_reprs():
    ct = coordinate_type("ru", 2)
    md = ct._repr_markdown_()
    assert md.startswith("# Natural coordinates: 2D bar ru") and "$$" in md
    assert ct.derivation._repr_markdown_() == md
    tex = ct._repr_latex_()
    assert tex.startswith("$$") and r"\otimes I_{2}" in tex and "\\section" not in tex


# ------------------------------------------------------------------------- pdflatex
LATEX_CASES = [(n, str(d)) for d, n in ALL_TYPES] + [("se3", "3")]
#: Report typeset in the fast tier: a planar body's (pdflatex's time: ≈ 3 CPU-s a report); the other types'
#: (the same template over fewer or other columns, SE(3)'s) in the slow tier.
FAST_LATEX = {("rrv", "2")}


@pytest.mark.skipif(shutil.which("pdflatex") is None, reason="pdflatex not installed")
@pytest.mark.parametrize("name,dim", [c if c in FAST_LATEX else pytest.param(*c, marks=pytest.mark.slow)
                                      for c in LATEX_CASES], ids=[f"{n}-{d}d" for n, d in LATEX_CASES])
def test_latex_report_compiles(tmp_path, name, dim):
    tex = tmp_path / "d.tex"
    args = ["derive", name, "--format", "latex", "-o", str(tex)] + ([] if name == "se3" else ["--dim", dim])
    assert main(args) == 0
    run = subprocess.run(["pdflatex", "-interaction=nonstopmode", "-halt-on-error", "d.tex"],
                         cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stdout[-3000:]
    assert (tmp_path / "d.pdf").stat().st_size > 1000
