"""The coordinate types' formulas, the joint primitives and the rigid-motion functions shipped
as generated data (``ncgen/codegen/forms_generator.py``) are what the SymPy derivations give
today, give the same CasADi expressions as translating those derivations, and spare a first
run of a model the import of SymPy (issues 34 and 40: first runs)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from ncgen.codegen import forms_generator as fg
from ncgen.model.sym2casadi import to_casadi
from ncgen.symbolic.coordinates import available_types, coordinate_type

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow      # renders every form from SymPy; fast:
#                       test_member_numeric_forms_equal_lambdify_of_the_derivation (the shipped forms against the
#                       derivation)
def test_shipped_forms_are_regenerated():
    """Each generated file equals what the generator writes from ncgen/symbolic now."""
    stale = [str(path.relative_to(ROOT)) for path, text in fg.rendered().items()
             if path.read_text(encoding="utf-8") != text]
    assert not stale, f"{stale} differ from ncgen/symbolic: run python -m ncgen.codegen.forms_generator"


@pytest.mark.parametrize("dim,name", available_types())
def test_member_numeric_forms_equal_lambdify_of_the_derivation(dim, name):
    """A member's numeric formulas (shipped NumPy source) equal lambdify of the derivation at
    random arguments, bit for bit; its constants by name equal the SymPy-keyed ones."""
    from ncgen.symbolic.member import RigidMember, constant_symbols
    from ncgen.symbolic.numpy_forms import numpy_function

    ct = coordinate_type(name, dim)
    D = ct.derivation
    rng = np.random.default_rng(len(name) + 10 * dim)
    if ct.kind == "body":
        basis = [rng.normal(size=dim)] + [rng.normal(size=dim) for _ in range(dim)]
        inertia = np.diag([1.0, 1.2, 1.5]) if dim == 3 else 0.7
        member = RigidMember.body(ct, 2.0, inertia, basis=basis)
    elif ct.kind == "bar":
        member = RigidMember.bar(ct, 2.0, 1.3, inertia=0.4, com=0.5)
    else:
        member = RigidMember.point(ct, 2.0)
    consts = member.constants()
    assert set(consts) == set(constant_symbols(ct))
    q, qd = rng.normal(size=ct.nq), rng.normal(size=ct.nq)
    R = np.linalg.qr(rng.normal(size=(dim, dim)))[0]
    R[:, 0] *= np.sign(np.linalg.det(R))              # a rotation
    p, w, v, c = rng.normal(size=dim), rng.normal(size=3 if dim == 3 else 1), rng.normal(size=dim), rng.normal(size=ct.k)
    cases = {"M": (), "Phi": ((D.q, q),), "Phi_q": ((D.q, q),), "C": ((D.c, c),), "p": ((D.q, q),),
             "v_com": ((D.q, q), (D.qd, qd)), "q_of_pose": ((D.R_sym, R), (D.p_sym, p)),
             "qd_of_twist": ((D.R_sym, R), (D.p_sym, p), (D.omega_sym, w), (D.v_sym, v))}
    if ct.kind != "point":
        cases.update({"R": ((D.q, q),), "W": ((D.q, q),), "omega": ((D.q, q), (D.qd, qd))})
    for formula, groups in cases.items():
        expr = getattr(D, formula)
        csyms = sorted((s for s in expr.free_symbols if s in consts), key=str)
        reference = numpy_function(expr, [g for g, _ in groups] + [csyms], key=("test", name, dim, formula))
        expected = reference(*[x for _, x in groups], [consts[s] for s in csyms])
        got = member._fn(formula)(*[x for _, x in groups])
        np.testing.assert_array_equal(got, expected, err_msg=f"{name} {dim}D {formula}")
    assert all(np.array_equal(a, np.array(b, dtype=float)) for a, b in zip(member.hessians, D.hessians))


def test_generated_python_follows_to_casadi():
    """The joint primitives and the inverse maps as generated Python give the very
    expression ``to_casadi`` gives for the SymPy formula (constants folded alike), so the
    generated C does not change."""
    from ncgen.model.member_forms import FORMS as MEMBER
    from ncgen.model.primitive_forms import FORMS as PRIMITIVE
    from ncgen.symbolic.joint_primitives import PRIMITIVES, primitive

    for dim in (2, 3):
        for name in PRIMITIVES:
            prim = primitive(name, dim)
            args, vals = [], {}
            for k, sym in enumerate(prim.args):
                if hasattr(sym, "shape"):       # vectors: symbols with a constant entry
                    x = ca.vertcat(ca.SX.sym(f"x{k}", len(sym) - 1), 0.5 * (k + 1))
                    vals.update({s: x[i] for i, s in enumerate(sym)})
                else:                            # scalars: numbers, as the joints pass them
                    x = 0.25 * (k + 1)
                    vals[sym] = x
                args.append(x)
            assert str(PRIMITIVE[name, dim](*args)) == str(to_casadi(prim.expr, vals)), (name, dim)
    for dim, name in available_types():
        D = coordinate_type(name, dim).derivation
        for formula in fg.VALUE_FORMULAS:
            expr = getattr(D, formula)
            symbols = sorted(expr.free_symbols, key=str)
            x = ca.SX.sym("x", len(symbols))
            values = {s: (x[k] if k % 3 else 0.1 * k + 1.0) for k, s in enumerate(symbols)}
            got = MEMBER[name, dim, formula]({str(s): v for s, v in values.items()})
            assert str(got) == str(to_casadi(expr, values)), (name, dim, formula)


def test_primitive_rows_are_the_formulas_rows():
    """``primitive_rows`` (no SymPy) is the row count of each primitive's formula."""
    from ncgen.symbolic.joint_primitives import PRIMITIVES, primitive, primitive_rows

    for dim in (2, 3):
        for name in PRIMITIVES:
            assert primitive_rows(name, dim) == primitive(name, dim).expr.shape[0], (name, dim)
    with pytest.raises(KeyError, match="unknown joint primitive 'hinge'"):
        primitive_rows("hinge", 3)


def test_shipped_sx_functions_equal_the_translation():
    """The serialised instance and rigid-motion functions, called on symbols, print the same
    expression as the translation made now."""
    from ncgen.model.context import instance_form
    from ncgen.rigid_motion import casadi_forms as crm
    from ncgen.symbolic.rigid_motion_forms import NAMES

    for name in (*NAMES, *crm.ROTATIONS):
        f, g = crm.function(name), crm.derived_function(name)
        args = [ca.SX.sym(f"a{k}", f.sparsity_in(k)) for k in range(f.n_in())]
        assert [str(e) for e in f.call(args)] == [str(e) for e in g.call(args)], name
    D = coordinate_type("rrvw", 3).derivation
    names, f = instance_form("rrvw", 3, "omega")
    q, v, c = ca.SX.sym("q", 12), ca.SX.sym("v", 12), ca.SX.sym("c", len(names))
    symbols = {str(s): s for s in D.omega.free_symbols}
    vals = {symbols[n]: c[k] for k, n in enumerate(names) if n in symbols}
    vals.update({s: q[k] for k, s in enumerate(D.q)})
    vals.update({s: v[k] for k, s in enumerate(D.qd)})
    assert str(f(q, v, c)) == str(to_casadi(D.omega, vals))


def test_first_build_and_run_import_no_sympy(tmp_path):
    """An empty cache: a URDF arm and a model file with bodies, bars, joints, springs and a
    torque are built and simulated without importing SymPy."""
    code = ("import sys, warnings\nwarnings.simplefilter('ignore')\nimport ncgen as nc\nfrom ncgen.cli import main\n"
            f"assert main(['simulate', {str(ROOT / 'examples' / 'slider_crank.toml')!r}, '--t-end', '0.02']) == 0\n"
            "m = nc.System.from_urdf(nc.robots.urdf_path('ur5')).build()\n"
            "nc.forward_dynamics(m, m.q0, m.v0, u=[0.0] * m.nu)\n"
            "assert 'sympy' not in sys.modules, 'SymPy imported'\nprint('ok')")
    env = {**os.environ, "PYTHONPATH": str(ROOT), "NCGEN_CACHE_DIR": str(tmp_path / "cache")}
    env.pop("NCGEN_MODEL_CACHE", None)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=tmp_path,
                         timeout=600)
    assert out.returncode == 0 and out.stdout.strip().endswith("ok"), out.stderr[-3000:]
