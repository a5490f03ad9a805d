"""Where things live (docs/architecture.md): whole-system CasADi functions are built in
ncgen/assembly, a model's run-time data is kept in one place (ncgen/model/data.py), and the
rank tolerance of the manifold's numerics is defined once (ncgen/assembly/manifold.py), the
rank of a constraint Jacobian is taken by its rule, and the manifold's Newton, null basis and
KKT solves are not written again outside it."""
from __future__ import annotations

import ast
import re
from functools import cache
from pathlib import Path
from typing import NamedTuple

ROOT = Path(__file__).resolve().parents[1] / "ncgen"


class Facts(NamedTuple):
    """What the checks read from one source file, gathered in one walk of its tree."""
    calls: dict[str, list[int]]     # attribute → lines of its ``<anything>.<attribute>(...)`` calls
    assigned: frozenset[str]        # names assigned (``name = ...``), at any depth
    defined: frozenset[str]         # names of functions and classes, and names assigned or annotated


@cache
def facts(path: Path) -> Facts:
    """:class:`Facts` of ``path`` (each file parsed once per run: ncgen's 260 modules take
    ≈ 2.5 CPU-s a parse)."""
    found: dict[str, list[int]] = {}
    assigned, defined = set(), set()
    for n in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute):
            found.setdefault(n.func.attr, []).append(n.lineno)
        elif isinstance(n, (ast.FunctionDef, ast.ClassDef)):
            defined.add(n.name)
        elif isinstance(n, (ast.Assign, ast.AnnAssign)):
            names = {t.id for t in (n.targets if isinstance(n, ast.Assign) else [n.target]) if isinstance(t, ast.Name)}
            defined |= names
            if isinstance(n, ast.Assign):
                assigned |= names
    return Facts(found, frozenset(assigned), frozenset(defined))


def calls(path: Path, attribute: str) -> list[int]:
    """Lines of ``<anything>.<attribute>(...)`` calls in ``path``."""
    return facts(path).calls.get(attribute, [])


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
    owners = [str(p.relative_to(ROOT)) for p in sorted(ROOT.rglob("*.py")) for name in ("RANK_TOL", "RCOND")
              if name in facts(p).assigned]
    assert owners == ["assembly/manifold.py"], owners


def test_ranks_of_the_constraint_jacobian_by_the_manifold_rule():
    """``np.linalg.matrix_rank`` (NumPy's own tolerance) only for matrices other than ``A``: the
    modal matrix of a steady motion and the centred points of form-finding; ranks of ``A`` go
    through ``manifold.numerical_rank`` (tests/test_rank_rule.py)."""
    allowed = {ROOT / "analysis" / "steady_motion.py", ROOT / "analysis" / "formfinding.py"}
    found = [f"{p.relative_to(ROOT.parent)}:{line}" for p in sorted(ROOT.rglob("*.py")) if p not in allowed
             for line in calls(p, "matrix_rank")]
    assert not found, "a rank outside ncgen.assembly.manifold.numerical_rank:\n" + "\n".join(found)


#: Modules whose numerics on the constraint manifold go through ncgen/assembly/manifold.py (issue 33's
#: list), and what each takes from it.
MANIFOLD_USERS = {"assembly/drive_assembly.py": {"newton"},
                  "assembly/redundancy.py": {"newton", "null_basis"},
                  "assembly/joint_space.py": {"newton", "solve_linear"},
                  "assembly/kinematics.py": {"newton", "numerical_rank"},
                  "optim/interpolate.py": {"kkt_solve"},
                  "codegen/tree_check.py": {"numerical_rank"},
                  "model/model.py": {"numerical_rank"}}
#: Dense solves, ranks and bases that would be manifold numerics written again.
LINEAR_ALGEBRA = ("solve", "lstsq", "svd", "pinv", "matrix_rank", "null_space", "qr")
#: The calls left, and why they are not a second copy of the manifold's numerics.
LINEAR_ALGEBRA_LEFT = {
    # the rates and accelerations of a fully driven mechanism: A v = −Φ_t, A a = γ with A of
    # full column rank (numerical_rank checked just before), an exact overdetermined solve
    "assembly/kinematics.py": 2,
}


def test_manifold_numerics_in_one_place():
    """The Newton onto Φ = 0, the null basis, the KKT solves and the rank of A are imported
    from ncgen/assembly/manifold.py by the modules that need them (Model.rank, dof_report and
    the tree check by its one rank rule, tests/test_rank_rule.py), which call no dense solve,
    rank or basis of their own but the counted ones of ``LINEAR_ALGEBRA_LEFT``.  (The optimal
    control guess, optim/guess.py, takes its accelerations and multipliers from the model's
    ``accel``; its least squares fit inputs to accelerations, not a point to the manifold.)"""
    for rel, names in MANIFOLD_USERS.items():
        tree = ast.parse((ROOT / rel).read_text(encoding="utf-8"))
        imported = {a.name for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)
                    and n.module == "ncgen.assembly.manifold" for a in n.names}
        assert names <= imported, (rel, names - imported)
        found = [line for attribute in LINEAR_ALGEBRA for line in calls(ROOT / rel, attribute)]
        assert len(found) == LINEAR_ALGEBRA_LEFT.get(rel, 0), (rel, found)


def test_libraries_are_opened_in_one_place():
    """Every library ncgen compiles is opened by ``c_binding.open_library`` (docs/architecture.md:
    one loader idiom); ``ctypes.CDLL(None)`` of the IPOPT options is the C library's own ``fflush``;
    ``blas_threads`` loads CasADi's own OpenBLAS (not compiled by ncgen) to limit its threads."""
    allowed = {ROOT / "codegen" / "c_binding.py", ROOT / "optim" / "ipopt_options.py", ROOT / "blas_threads.py"}
    found = [f"{p.relative_to(ROOT.parent)}:{line}" for p in sorted(ROOT.rglob("*.py")) if p not in allowed
             for line in calls(p, "CDLL")]
    assert not found, "a library opened outside ncgen.codegen.c_binding.open_library:\n" + "\n".join(found)


DOC = ROOT.parent / "docs" / "architecture.md"
SOURCE_DIRS = (ROOT.parent, ROOT, ROOT.parent / "templates" / "c", ROOT.parent / "templates" / "c" / "runtime")


def _defines(path: Path, name: str) -> bool:
    """Whether ``path`` defines ``name`` at its top level or in a class (def, class, assignment)."""
    return name in facts(path).defined


def _source(ref: str) -> Path | None:
    """The file a page's ``path`` names: relative to the repository, ncgen/ or templates/c/, or
    a bare file name found once under ncgen/ or templates/."""
    for d in SOURCE_DIRS:
        if (d / ref).is_file():
            return d / ref
    if "/" not in ref:
        found = [p for top in (ROOT, ROOT.parent / "templates") for p in top.rglob(ref)]
        return found[0] if len(found) == 1 else None
    return None


def test_the_architecture_page_names_files_and_definitions_that_exist():
    """Each ``file.py``, ``file.h`` or ``template.j2`` the page names exists, and each
    ``file.py: name`` defines ``name``; each dotted ``ncgen.module.name`` imports (package
    files written per model, ``main.c``, ``<name>_mpc.c``, are not sources)."""
    import importlib

    wrong = []
    text = re.sub(r"```.*?```", "", DOC.read_text(encoding="utf-8"), flags=re.S)     # the layers' block
    refs = sorted(set(re.findall(r"`([^`]+)`", text)))
    assert len(refs) > 100, "the page's references were not found"
    for ref in refs:
        path = re.fullmatch(r"([\w./]+\.(?:py|h|j2))(?::\s*(\w+))?", ref)
        dotted = re.fullmatch(r"ncgen(?:\.\w+)+", ref)
        if path:
            source = _source(path[1])
            if source is None:
                wrong.append(f"{ref}: no such file")
            elif path[2] and not _defines(source, path[2]):
                wrong.append(f"{ref}: {path[2]} is not defined in {source.relative_to(ROOT.parent)}")
        elif dotted:
            parts = ref.split(".")
            for k in range(len(parts), 0, -1):
                try:
                    obj = importlib.import_module(".".join(parts[:k]))
                except ModuleNotFoundError:
                    continue
                for attr in parts[k:]:
                    obj = getattr(obj, attr, None)
                if obj is None:
                    wrong.append(f"{ref}: not found")
                break
    assert not wrong, "docs/architecture.md names what is not there:\n" + "\n".join(wrong)
