"""The package is one chain of layers: no import cycle and no import that runs up the chain.

Every ``import``/``from … import`` of an ``ncgen`` module is an edge, wherever it stands
(module level or inside a function).  The layer order, lowest first (also in
docs/architecture.md)::

    base (errors, validation, reproducible, files, interrupts, version, robots, progress, blas_threads, environment)
    ← symbolic ← model ← rigid_motion ← assembly ← codegen ← runtime ← analysis ← viz ← optim ← control ← cli
    ← ncgen (the package root)

A module may import modules of its own layer and of lower ones.  The exceptions, all
conveniences: ``System.build()`` (model) calls :func:`ncgen.codegen.model_cache.build_system`
(the store of built models, then :func:`ncgen.assembly.build.build_model`),
``Model.rank`` (model) calls :func:`ncgen.assembly.manifold.numerical_rank` (the one rank rule),
``Trajectory.reaction()`` (runtime) calls :func:`ncgen.analysis.reactions.joint_reactions`, and
``Trajectory.to_html()`` (runtime) calls :func:`ncgen.viz.html.to_html`, and Jupyter's display
of a model (model) and of a trajectory (runtime), ``_repr_html_``, calls :mod:`ncgen.viz.notebook`.
"""
from __future__ import annotations

import ast
import functools
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1] / "ncgen"

LAYERS = ["base", "symbolic", "model", "rigid_motion", "assembly", "codegen", "runtime", "analysis", "viz", "optim",
          "control", "cli", "root"]
BASE = {"errors", "validation", "reproducible", "files", "interrupts", "version", "robots", "progress",
        "blas_threads", "environment"}
#: (importing module, imported module): the documented exceptions.
EXCEPTIONS = {("ncgen.model.system", "ncgen.codegen.model_cache"), ("ncgen.model.model", "ncgen.assembly.manifold"),
              ("ncgen.runtime.trajectory", "ncgen.analysis.reactions"),
              ("ncgen.runtime.trajectory", "ncgen.viz.html"),
              ("ncgen.model.model", "ncgen.viz.notebook"), ("ncgen.runtime.trajectory", "ncgen.viz.notebook")}


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def modules() -> dict[str, Path]:
    return {module_name(p): p for p in sorted(ROOT.rglob("*.py"))}


def layer(module: str) -> str:
    parts = module.split(".")
    if len(parts) == 1:
        return "root"
    top = parts[1]
    if top in BASE:
        return "base"
    if top in LAYERS:
        return top
    raise AssertionError(f"module {module} is in no layer: add its package to LAYERS or BASE in "
                         f"{Path(__file__).name} and docs/architecture.md")


def imports(module: str, path: Path, known: set[str]) -> set[str]:
    """The ncgen modules ``module`` imports anywhere in its source."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names if a.name.split(".")[0] == "ncgen")
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[:len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target.split(".")[0] != "ncgen":
                continue
            for alias in node.names:
                sub = f"{target}.{alias.name}"
                out.add(sub if sub in known else target)
    out.discard(module)
    return out


@functools.lru_cache(maxsize=None)
def graph() -> dict[str, set[str]]:
    """Each module's ncgen imports, parsed once per process (the tests only read it)."""
    mods = modules()
    return {m: imports(m, p, set(mods)) for m, p in mods.items()}


def test_every_module_has_a_layer():
    for m in modules():
        layer(m)


def test_no_upward_imports():
    upward = []
    for m, targets in graph().items():
        for t in sorted(targets):
            if LAYERS.index(layer(t)) > LAYERS.index(layer(m)) and (m, t) not in EXCEPTIONS:
                upward.append(f"{m} ({layer(m)}) imports {t} ({layer(t)})")
    assert not upward, "imports that run up the layers:\n" + "\n".join(upward)


def test_no_import_cycles():
    g = graph()
    index, low, stack, on_stack, cycles = {}, {}, [], set(), []
    counter = [0]

    def visit(v):                     # Tarjan's strongly connected components
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in g.get(v, ()):
            if w not in g:
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in g:
        if v not in index:
            visit(v)
    assert not cycles, "import cycles:\n" + "\n".join(" ⇄ ".join(c) for c in cycles)


@pytest.mark.parametrize("source, expected", [
    ("from ncgen.runtime import simulate\n", {"ncgen.runtime"}),
    ("def f():\n    import ncgen.cli\n", {"ncgen.cli"}),
    ("from . import errors\n", {"ncgen.errors"}),
])
def test_the_parser_sees_every_kind_of_import(tmp_path, source, expected):
    path = tmp_path / "probe.py"
    path.write_text(source)
    assert imports("ncgen.probe", path, set(modules())) == expected


def test_the_architecture_page_lists_these_layers():
    """docs/architecture.md's block of layers names the same layers in the same order, and
    the same base modules, as this test."""
    page = (ROOT.parent / "docs" / "architecture.md").read_text(encoding="utf-8")
    block = page.split("```")[1]
    rows = [re.match(r"\s*(?:← )?(\w+)\s+(.*?)\s{2,}", line) for line in block.strip().splitlines()]
    assert all(rows), "a row of the layers' block is not `name  modules   description`"
    names = [r[1] for r in rows]
    assert names == [("ncgen" if n == "root" else n) for n in LAYERS]
    assert {m.strip() for m in rows[0][2].split(",")} == BASE
