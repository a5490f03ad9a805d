"""``ncgen tensegrity``: a design file's analysis and forces on the command line, the CSV it
writes balancing the structure, errors naming the key."""
from pathlib import Path

import numpy as np
import pytest

from ncgen.analysis.self_stress import self_stress
from ncgen.analysis.tensegrity_file import read_design
from ncgen.cli import main
from ncgen.errors import NcgenError

DESIGN = Path(__file__).resolve().parents[1] / "examples" / "snelson_prism.tensegrity.toml"


def test_design_file_prints_the_analysis_and_writes_balanced_forces(capsys, tmp_path):
    out_csv = tmp_path / "forces.csv"
    assert main(["tensegrity", str(DESIGN), "-o", str(out_csv)]) == 0
    out = capsys.readouterr().out
    assert "s - m = n_t - (n_free - k): 2 - 1 = 12 - (11 - 0)" in out
    assert "objective stiffness" in out and "prestress stability: stable" in out
    assert "cable rest lengths (m) at 2000 N/m:" in out
    rows = np.genfromtxt(out_csv, delimiter=",", names=True, dtype=None, encoding="utf-8")
    d = read_design(DESIGN)
    an = self_stress(d["nodes"], d["struts"], d["cables"], d["supports"])
    t = np.array(rows["force_N"], float)
    np.testing.assert_allclose(an.A @ t, 0, atol=1e-10)
    assert t[:9].min() >= 10.0 - 1e-8 and t[:9].max() <= 50.0 + 1e-8


@pytest.mark.parametrize("text, match", [
    ("nodes = [[0, 0], [1, 0]]\nstruts = []\ncables = [[0, 1]]\ncolour = 1\n", r"unknown key\(s\) \['colour'\]"),
    ("struts = []\ncables = []\n", "nodes: missing"),
    ("nodes = [[0, 0], [1, 0]]\nstruts = []\ncables = [[0, 1]]\n[prestress]\nobjective = 'cheap'\n",
     "prestress.objective: expected one of"),
    ("nodes = [[0, 0], [1, 0]]\nstruts = []\ncables = [[0, 1]]\nloads = [{ node = 5, force = [0, 1] }]\n",
     r"loads\[0\].node: expected a node index in 0..1"),
    ("nodes = [[0, 0], [1, 0]]\nstruts = []\ncables = [[0, 1]]\nsupports = { a = 'x' }\n",
     "supports.a: expected a node index"),
])
def test_bad_design_files_name_the_key(tmp_path, text, match):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(NcgenError, match=match):
        read_design(path)


def test_cli_reports_a_bad_file_without_a_traceback(capsys, tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("struts = []\ncables = []\n")
    assert main(["tensegrity", str(path)]) != 0
    assert "nodes: missing" in capsys.readouterr().err
