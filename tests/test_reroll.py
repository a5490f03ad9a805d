"""Loop rerolling (ncgen.codegen.reroll) and the looped packages of large models
(ncgen.codegen.looped): exact values, code that does not grow with the model, and the
compiled package of a long model against the flat SX functions and IDAS."""
from __future__ import annotations

import json
import re
import shutil
import warnings
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

import ncgen as nc
from ncgen.codegen import compile_package, load_functions
from ncgen.codegen.looped import is_large
from ncgen.codegen.reroll import REROLL_INSTRUCTIONS, reroll

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
needs_cc = pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None,
                              reason="no C compiler")


def example_models() -> list[Path]:
    return [p for p in sorted(EXAMPLES.glob("*.toml")) if "[[members]]" in p.read_text()]


def long_chain(n: int):
    """``n`` bars of unequal mass and length in a chain from the ground, a damped spring from
    every third bar to the ground (its stiffness a parameter), a push input on the last bar
    and a marker at each bar's middle: every kind of input and constant differs per block."""
    s = nc.System(f"long{n}", gravity=(0.0, 0.0, -9.81))
    k = s.add_parameter("k", 30.0)
    push = s.add_input("push")
    start = s.ground.point((0.0, 0.0, 0.0))
    bars = []
    for i in range(n):
        end = (0.1 * (i + 1), 0.01 * np.sin(i), -0.02 * i)
        bar = s.add_bar(f"b{i}", "rr", mass=1.0 + 0.01 * i, ends=[start, end])
        bar.add_marker("mid", (0.05, 0.0, 0.0))
        start = bar.end(1)
        bars.append(bar)
    for i in range(0, n, 3):
        s.add_force(nc.Spring(s.ground, (0.1 * (i + 1), 0.3, 0.0), bars[i], (0.05, 0.0, 0.0), k=k,
                              rest_length=0.25, damping=0.5 + 0.01 * i))
    s.add_force(nc.PointForce(bars[-1], (0.0, 0.0, 0.0), force=ca.vertcat(push, 0, 0)))
    return s.build()


def random_args(f: ca.Function, seed: int = 0) -> list[ca.DM]:
    rng = np.random.default_rng(seed)
    return [ca.DM(f.sparsity_in(i), rng.uniform(-1.0, 1.0, f.nnz_in(i))) for i in range(f.n_in())]


def assert_same(f: ca.Function, g: ca.Function, rtol: float = 1e-12, seed: int = 0) -> None:
    """``g`` computes ``f``: same sparsity, same values at a random point."""
    args = random_args(f, seed)
    for i, (a, b) in enumerate(zip(f.call(args), g.call(args))):
        assert a.sparsity() == b.sparsity(), (f.name(), f.name_out(i))
        a, b = np.array(a.nonzeros()), np.array(b.nonzeros())
        np.testing.assert_allclose(b, a, rtol=rtol, atol=rtol * (1 + np.max(np.abs(a), initial=0)),
                                   err_msg=f"{f.name()}.{f.name_out(i)}")


def n_maps(g: ca.Function) -> int:
    """How many mapped kernels the MX function ``g`` calls."""
    return sum(1 for k in range(g.n_instructions()) if g.instruction_id(k) == ca.OP_CALL
               and g.instruction_MX(k).which_function().is_a("Map"))


# ------------------------------------------------------------------ reroll itself
def test_constants_differing_per_block_are_lifted_into_one_kernel():
    x = ca.SX.sym("x", 21)
    rng = np.random.default_rng(1)
    c, d = rng.uniform(0.5, 2.0, 20), rng.uniform(-1.0, 1.0, 20)
    y = ca.vertcat(*[c[i] * ca.sin(x[i]) + d[i] * x[i + 1] ** 2 for i in range(20)])
    f = ca.Function("f", [x], [y], ["x"], ["y"])
    g = reroll(f)
    assert g.is_a("MXFunction") and n_maps(g) == 1
    assert_same(f, g, rtol=1e-15)


def test_rare_shapes_global_rows_and_constants_stay_exact():
    """A unique block, a row depending on everything (a sum), constant rows and copies of
    inputs are kept outside the loops, in their places among the outputs."""
    x = ca.SX.sym("x", 300)
    rows = [ca.exp(x[i]) * x[i + 1] for i in range(0, 200, 2)]
    rows.insert(7, ca.sum1(x ** 2))                     # global: stays flat
    rows.insert(3, ca.atan2(x[250], x[251]) * x[252])   # one of a kind: stays flat
    rows.insert(50, ca.SX(4.25))                        # constant
    rows.insert(20, x[299])                             # a copy of an input
    f = ca.Function("f", [x], [ca.vertcat(*rows), ca.sin(x[:5]), x[100:140]], ["x"], ["y", "z", "w"])
    g = reroll(f)
    assert g.is_a("MXFunction") and n_maps(g) == 2      # the copies are one gather, not a loop
    assert_same(f, g, rtol=1e-15)


def test_operations_without_a_derivative_are_gathered_too():
    """``floor`` and comparisons contribute nothing to the Jacobian sparsity, yet their
    inputs must be gathered for the kernel."""
    x = ca.SX.sym("x", 40)
    y = ca.vertcat(*[ca.floor(3 * x[i]) * x[i + 20] + ca.if_else(x[i] > 0, 1.0, -2.0) for i in range(20)])
    f = ca.Function("f", [x], [y], ["x"], ["y"])
    assert_same(f, reroll(f), rtol=1e-15)


def test_nothing_to_reroll_returns_the_function():
    x = ca.SX.sym("x", 3)
    f = ca.Function("f", [x], [ca.sum1(ca.sin(x))])
    assert reroll(f) is f
    mx = ca.MX.sym("x", 3)
    h = ca.Function("h", [mx], [mx * 2])
    assert reroll(h) is h


@pytest.mark.parametrize("path", [pytest.param(p, marks=pytest.mark.slow) if p.stem == "box_stack" else p   # the largest;
                                  for p in example_models()], ids=lambda p: p.stem)   # the others take its path
def test_reroll_reproduces_every_function_of_the_shipped_examples(path):
    """Every system function and the DAE Jacobian of each shipped example, rerolled even
    where two blocks repeat: same sparsity, same values."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = nc.System.from_toml(path).build()
    functions = dict(model.functions, jac_dae=model.functions["dae"].jacobian())
    looped = 0
    for name, f in functions.items():
        if name == "accel":
            continue                      # MX with a QR solve: never expanded, never rerolled
        g = reroll(f.expand(), min_instances=2)
        looped += g.is_a("MXFunction")
        assert_same(f, g)
    assert looped >= 3, path.stem


def test_generated_code_does_not_grow_with_the_number_of_members():
    """Same kernels for 30 and 60 bars: only the index and constant tables grow."""
    graphs = []
    for n in (30, 60):
        model = long_chain(n)
        dae = reroll(model.functions["dae"])
        jac = reroll(model.functions["dae"].jacobian())
        graphs.append((dae.n_instructions(), n_maps(dae), jac.n_instructions(), n_maps(jac)))
        assert_same(model.functions["dae"], dae)
    assert graphs[0] == graphs[1]
    assert graphs[0][1] >= 3


# ------------------------------------------------------------------ looped packages
@pytest.mark.slow      # a long model's package compiled at -O2; fast:
#                       test_reroll_reproduces_every_function_of_the_shipped_examples (looped functions equal the flat
#                       ones)
@needs_cc
def test_package_of_a_long_model_is_looped_compiles_at_o2_and_is_exact(tmp_path):
    model = long_chain(60)
    assert is_large(model, 1_000)
    pkg = nc.generate(model, tmp_path / "pkg", reroll_instructions=1_000)
    manifest = json.loads((pkg.path / "manifest.json").read_text())
    sizes = {f["name"]: f["n_instructions"] for f in manifest["functions"]}
    for name in ("dae", "alg", "ode", "poses", "step_newton", "step_velocity"):
        assert sizes[name] < 200, (name, sizes[name])          # MX nodes, not straight-line code
    assert manifest["build"]["large_sources"] == []
    compiled = load_functions(compile_package(pkg, cflags="-O2"), backend="compiled")    # not the fast tier's -O0
    for name, f in model.functions.items():
        assert_same(f, compiled[name], rtol=1e-10)
    J = model.functions["dae"].jacobian()
    assert_same(J, compiled["dae"].jacobian(), rtol=1e-10)


@pytest.mark.slow      # fast: the looped package's kernels, step_newton and step_velocity included, equal the flat ones above
@needs_cc
def test_looped_stepper_and_idas_agree_on_a_long_model(monkeypatch):
    """The compiled stepper built from looped kernels against IDAS on the flat functions,
    with the damped springs, the parameter and the input all acting."""
    from ncgen.codegen import looped

    model = long_chain(45)
    monkeypatch.setattr(looped, "LARGE_MODEL_INSTRUCTIONS", 10_000)      # treat it as large
    assert looped.reroll_limit(model) == looped.LARGE_MODEL_REROLL
    assert is_large(model, looped.reroll_limit(model))
    u = lambda t: [0.5 * np.sin(5 * t)]
    p = {"k": 45.0}
    ref = nc.simulate(model, 0.2, 0.02, rtol=1e-10, atol=1e-10, u=u, p=p)
    fine = nc.simulate(model, 0.2, 0.02, method="stepper", substeps=40, u=u, p=p)
    assert np.max(np.abs(fine.q - ref.q)) < 1e-4
    assert np.all(fine.constraint_residual <= 1e-10)


@pytest.mark.slow      # a long model's package written twice; fast:
#                       test_generated_code_does_not_grow_with_the_number_of_members
def test_looped_package_is_reproducible(tmp_path):
    """Two builds of the same long model give the same bytes: the shapes, kernels and
    tables do not depend on hashing or on the objects' identity."""
    texts = []
    for k in range(2):
        pkg = nc.generate(long_chain(45), tmp_path / f"pkg{k}", reroll_instructions=1_000)
        texts.append({p.name: p.read_bytes() for p in sorted(pkg.path.iterdir())})
    assert texts[0] == texts[1]
    kernels = b"".join(v for name, v in texts[0].items() if "_kernels_" in name and name.endswith(".c"))
    assert re.search(rb"for \(i=0; i<\d+; \+\+i\)", kernels)       # a mapped kernel's loop


def test_large_models_reroll_shorter_functions(monkeypatch):
    from ncgen.codegen import looped

    model = long_chain(30)
    assert looped.reroll_limit(model) == REROLL_INSTRUCTIONS
    assert looped.reroll_limit(model, None) is None
    monkeypatch.setattr(looped, "LARGE_MODEL_INSTRUCTIONS", 1_000)
    assert looped.reroll_limit(model) == looped.LARGE_MODEL_REROLL
    assert looped.reroll_limit(model, 500) == 500


def test_composites_in_mx_match_the_model_and_only_the_named_ones_are_built():
    from ncgen.assembly.functions import composite_functions
    from ncgen.assembly.mass import sparse_dm
    from ncgen.codegen.looped import primitives

    model = long_chain(8)
    prim = primitives(model)
    built = composite_functions(prim, prim["V"], sparse_dm(model.M), *model.baumgarte, ca.MX, ("alg", "energy"))
    assert sorted(built) == ["alg", "energy"]
    for name, f in built.items():
        assert f.is_a("MXFunction")
        assert_same(model.functions[name], f, rtol=1e-10)
    with pytest.raises(ValueError, match="unknown function.*'dea'"):
        composite_functions(prim, prim["V"], sparse_dm(model.M), *model.baumgarte, ca.MX, ("dea",))
