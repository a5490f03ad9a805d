"""Where things live (docs/architecture.md): whole-system CasADi functions are built in
ncgen/assembly, a model's run-time data is kept in one place (ncgen/model/data.py), and the
rank tolerance of the manifold's numerics is defined once (ncgen/assembly/manifold.py) and
the rank of a constraint Jacobian is taken by its rule."""
from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "ncgen"


def calls(path: Path, attribute: str) -> list[int]:
    """Lines of ``<anything>.<attribute>(...)`` calls in ``path``."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return [n.lineno for n in ast.walk(tree)
            if isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute) and n.func.attr == attribute]


def test_runtime_and_analysis_build_no_casadi_function():
    """Runtime only loads and drives compiled code (it wraps the model's dae for IDAS in
    idas.py); analysis evaluates functions that assembly builds."""
    allowed = {ROOT / "runtime" / "idas.py"}
    found = [f"{p.relative_to(ROOT.parent)}:{line}"
             for layer in ("runtime", "analysis") for p in sorted((ROOT / layer).glob("*.py")) if p not in allowed
             for line in calls(p, "Function")]
    assert not found, "casadi.Function built outside ncgen/assembly:\n" + "\n".join(found)


def test_model_keyed_caches_live_in_the_model_data():
    found = [f"{p.relative_to(ROOT.parent)}:{line}" for p in sorted(ROOT.rglob("*.py"))
             if p != ROOT / "model" / "data.py" for line in calls(p, "WeakKeyDictionary")]
    assert not found, "a model-keyed cache outside ncgen/model/data.py (add a slot to ModelData):\n" + "\n".join(found)


def test_one_rank_tolerance_for_the_manifold():
    """``RANK_TOL`` is assigned in assembly/manifold.py only."""
    owners = []
    for p in sorted(ROOT.rglob("*.py")):
        for n in ast.walk(ast.parse(p.read_text(encoding="utf-8"))):
            if isinstance(n, ast.Assign) and any(isinstance(t, ast.Name) and t.id in ("RANK_TOL", "RCOND")
                                                 for t in n.targets):
                owners.append(str(p.relative_to(ROOT)))
    assert owners == ["assembly/manifold.py"], owners


def test_ranks_of_the_constraint_jacobian_by_the_manifold_rule():
    """``np.linalg.matrix_rank`` (NumPy's own tolerance) only for matrices other than ``A``: the
    modal matrix of a steady motion and the centred points of form-finding; ranks of ``A`` go
    through ``manifold.numerical_rank`` (tests/test_rank_rule.py)."""
    allowed = {ROOT / "analysis" / "steady_motion.py", ROOT / "analysis" / "formfinding.py"}
    found = [f"{p.relative_to(ROOT.parent)}:{line}" for p in sorted(ROOT.rglob("*.py")) if p not in allowed
             for line in calls(p, "matrix_rank")]
    assert not found, "a rank outside ncgen.assembly.manifold.numerical_rank:\n" + "\n".join(found)
