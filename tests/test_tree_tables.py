"""The joint-space algorithms over tree tables (issue 34): RNEA, CRBA, forward dynamics and
their derivatives from the tree library (one kernel per joint kind, hand-written loops over
the model's tables, compiled once per ncgen version) equal the model's flat SX functions to
1e-12 (evaluated by CasADi, nothing compiled per model), forward dynamics equals the KKT solve
in natural coordinates and a mimic gripper's closed form, derivatives equal central
differences (positions moved in the tangent space); models the tables do not cover are
refused by name and ``kernels="auto"`` falls back to the flat kernels; the joint-space
simulation on the tables conserves energy (and, slow, equals the flat loop); forward dynamics'
Cholesky fallback is compiled only when a tree first needs it and then equals the Lagrangian's
closed form; a new tree (and,
slow, a URDF robot not seen before) is evaluated and simulated in a process with no compiler
on PATH.
Slow tier: example-robot-data's URDFs against the flat compiled kernels (1e-12) and Pinocchio
(1e-10)."""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.assembly import tree_algorithms as flat
from ncgen.assembly.joint_tree import quaternion_matrix
from ncgen.assembly.tree_dynamics import MimicMap
from ncgen.codegen.compiler import CANDIDATES
from ncgen.codegen.tree_tables import UnsupportedTree, tree_tables
from ncgen.errors import ShapeError
from ncgen.runtime import tree_algorithm_kernels as rta
from ncgen.runtime.tree_library import build_tree_library, load_tree_library

ROOT = Path(__file__).resolve().parent.parent
G = 9.81

pytestmark = pytest.mark.skipif(not any(shutil.which(c) for c in CANDIDATES) and not os.environ.get("CC"),
                                reason="no C compiler to build the tree library")


@pytest.fixture(scope="module")
def library():
    """Every unit of the tree library compiled (the children with no compiler need them)."""
    build_tree_library()
    return load_tree_library()


@pytest.fixture(scope="module")
def tree():
    """Every joint kind of the tables on rigid bodies, a rotated body, and a mimic pair."""
    return make_tree(mimic=True)


@pytest.fixture(scope="module")
def free_tree():
    """The same tree without the mimic pair: forward dynamics by the articulated-body algorithm alone."""
    return make_tree(mimic=False)


def make_tree(mimic: bool):
    s = nc.System("table_tree" if mimic else "table_tree_free", gravity=(0.3, 0, -G))
    R = quaternion_matrix(np.array([0.2, -0.4, 0.3, 0.8]) / np.linalg.norm([0.2, -0.4, 0.3, 0.8]))
    b = [s.add_body(f"b{k}", mass=1.0 + 0.2 * k, inertia=np.diag([0.1, 0.2, 0.25]) * (1 + 0.1 * k),
                    position=(k + 0.5, 0.1 * k, 0), rotation=R if k == 2 else np.eye(3)) for k in range(10)]
    s.add_joint(nc.Free(s.ground, b[0], at=(0.5, 0, 0), rotation=np.eye(3), name="root"))
    s.add_joint(nc.Revolute(b[0], b[1], at=(1, 0, 0), axis=(0, 0.6, 0.8), name="hinge"))
    s.add_joint(nc.Prismatic(b[1], b[2], at=(2, 0.1, 0), axis=(1, 0, 0), name="slider"))
    s.add_joint(nc.Cylindrical(b[2], b[3], at=(3, 0.2, 0), axis=(1, 0, 0), name="cyl"))
    s.add_joint(nc.Universal(b[3], b[4], at=(4, 0.3, 0), axis_a=(0, 1, 0), axis_b=(0, 0, 1), name="hooke"))
    s.add_joint(nc.Spherical(b[4], b[5], at=(5, 0.4, 0), name="ball"))
    s.add_joint(nc.Planar(b[5], b[6], at=(6, 0.5, 0), normal=(0, 1, 0), name="plane"))
    s.add_joint(nc.Fixed(b[6], b[7], at=(7, 0.6, 0), name="weld"))
    j1 = s.add_joint(nc.Revolute(b[7], b[8], at=(8, 0.7, 0), axis=(0, 0, 1), name="f1"))
    j2 = s.add_joint(nc.Revolute(b[7], b[9], at=(9, 0.8, 0), axis=(1, 0, 0), name="f2"))
    if mimic:
        s.add_joint(nc.Mimic(j1, j2, multiplier=-2.0, offset=0.1, name="link"))
    return s.build(assemble=True)


def random_state(model, rng):
    js, mimic = model.joint_space, MimicMap(model)
    qj = rng.uniform(-1, 1, js.nq)
    for name, sl in js.slices().items():
        if js.nq_joint[name] in (4, 7):
            qj[sl.stop - 4:sl.stop] /= np.linalg.norm(qj[sl.stop - 4:sl.stop])
    for i, (lead, k, off) in mimic.position.items():
        qj[i] = k * qj[lead] + off
    n = mimic.G.shape[1]
    return qj, mimic.G @ rng.normal(size=n), mimic.G @ rng.normal(size=n), rng.normal(size=n)


#: Tolerances relative to the largest entry against the flat functions: values to 1e-12; the
#: derivatives (a 20-rate chain, rotated frames) differ from the flat code's by up to 6e-12 of
#: the largest entry (round-off of the other order of operations; both equal central differences).
TOL = {"tau": 1e-12, "M": 1e-12, "aj": 1e-12, "dtau_dq": 2e-11, "dtau_dv": 2e-11, "dtau_da": 1e-12,
       "da_dq": 2e-11, "da_dv": 2e-11, "da_dtau": 1e-12}


def flat_values(model, name, *args):
    f = getattr(flat, f"{name}_function")(model)
    out = f(0.0, *args, model.p0)
    out = out if isinstance(out, (list, tuple)) else [out]
    return [np.array(o).squeeze(-1) if np.array(o).shape[-1] == 1 and o.size2() == 1 else np.array(o)
            for o in out][:len(rta.ALGORITHMS[name][1])]


def assert_equal_to_flat(model, names, seed=0, states=2):
    rng = np.random.default_rng(seed)
    for _ in range(states):
        qj, vj, aj, tau = random_state(model, rng)
        for name in names:
            args = (qj, vj, aj) if "rnea" in name else (qj,) if name == "crba" else (qj, vj, tau)
            got = getattr(nc, name)(model, *args, kernels="tables")
            got = got if isinstance(got, tuple) else (got,)
            for g, w, what in zip(got, flat_values(model, name, *args), rta.ALGORITHMS[name][1]):
                np.testing.assert_allclose(g, w.reshape(g.shape), rtol=0, atol=TOL[what] * max(1.0, np.abs(w).max()),
                                           err_msg=f"{name}: {what}")


def test_tables_equal_the_flat_functions(tree, library):
    """RNEA, CRBA and forward dynamics (the articulated-body algorithm with the mimic follower
    held by its constraint) over local frames: every joint kind, axes off the coordinate axes."""
    assert_equal_to_flat(tree, ("rnea", "crba", "aba"), states=1)


def test_articulated_body_algorithm_equals_the_flat_function_and_the_kkt_solve(free_tree, library):
    """Without mimic joints forward dynamics (20 rates) is the articulated-body algorithm alone:
    equal to the flat function (1e-12) and to the constrained equations in natural coordinates."""
    assert_equal_to_flat(free_tree, ("aba", "rnea"), seed=3, states=2)
    rng = np.random.default_rng(4)
    qj, vj, _, tau = random_state(free_tree, rng)
    aj = nc.aba(free_tree, qj, vj, np.zeros(len(tau)), kernels="tables")
    q, v = free_tree.from_joint_space(qj, vj)
    a, _ = nc.forward_dynamics(free_tree, q, v)
    np.testing.assert_allclose(aj, free_tree.to_joint_space(q, v, a)[2], rtol=0, atol=1e-9)
    tau_back = nc.rnea(free_tree, qj, vj, nc.aba(free_tree, qj, vj, tau, kernels="tables"), kernels="tables")
    np.testing.assert_allclose(tau_back, tau, rtol=0, atol=1e-10 * max(1.0, np.abs(tau).max()))


@pytest.mark.parametrize("mimic", [False, True])
def test_small_trees_forward_dynamics_by_cholesky(mimic, library):
    """A tree of 11 rates (a free root, a ball, two hinges; with or without a mimic pair), at most
    the 12 up to which forward dynamics is M_i a_i = τ_i − b_i by Cholesky (M_i, b_i of one pass
    in the ground frame): equal to the constrained equations in natural coordinates (1e-9, as
    above) and to the derivatives' own forward dynamics (M_i by the composite-rigid-body
    algorithm about each body's origin, b_i by the local recursion: 1e-12)."""
    s = nc.System(f"small_tree_{int(mimic)}", gravity=(0.3, 0, -G))
    R = quaternion_matrix(np.array([0.2, -0.4, 0.3, 0.8]) / np.linalg.norm([0.2, -0.4, 0.3, 0.8]))
    b = [s.add_body(f"b{k}", mass=1.0 + 0.2 * k, inertia=np.diag([0.1, 0.2, 0.25]) * (1 + 0.1 * k),
                    position=(0.3 * k + 0.2, 0.1 * k, 0), rotation=R if k == 1 else np.eye(3)) for k in range(4)]
    s.add_joint(nc.Free(s.ground, b[0], at=(0.2, 0, 0), rotation=np.eye(3), name="root"))
    s.add_joint(nc.Spherical(b[0], b[1], at=(0.4, 0.05, 0), name="ball"))
    j1 = s.add_joint(nc.Revolute(b[1], b[2], at=(0.7, 0.15, 0), axis=(0, 0.6, 0.8), name="f1"))
    j2 = s.add_joint(nc.Revolute(b[1], b[3], at=(1.0, 0.25, 0), axis=(1, 0, 0), name="f2"))
    if mimic:
        s.add_joint(nc.Mimic(j1, j2, multiplier=-2.0, offset=0.1, name="link"))
    model = s.build(assemble=True)
    assert model.joint_space.nv == 11
    qj, vj, _, tau = random_state(model, np.random.default_rng(5))
    aj = nc.aba(model, qj, vj, tau, kernels="tables")
    scale = max(1.0, np.abs(aj).max())
    np.testing.assert_allclose(aj, nc.aba_derivatives(model, qj, vj, tau, kernels="tables")[0], rtol=0,
                               atol=1e-12 * scale)
    a0 = nc.aba(model, qj, vj, np.zeros(len(tau)), kernels="tables")
    q, v = model.from_joint_space(qj, vj)
    a, _ = nc.forward_dynamics(model, q, v)
    np.testing.assert_allclose(a0, model.to_joint_space(q, v, a)[2], rtol=0, atol=1e-9)


@pytest.mark.slow
def test_forward_dynamics_equals_the_flat_function(tree, library):
    assert_equal_to_flat(tree, ("aba",))


@pytest.mark.slow
def test_derivatives_equal_the_flat_functions(tree, library):
    assert_equal_to_flat(tree, ("rnea_derivatives", "aba_derivatives"))


def test_forward_dynamics_equals_the_kkt_solve(tree, library):
    """ABA from the tables against the constrained equations in natural coordinates (no joint
    space, no recursion): ``M q̈ + Aᵀλ = F``, ``A q̈ = γ``, mapped to joint accelerations."""
    rng = np.random.default_rng(1)
    qj, vj, _, _ = random_state(tree, rng)
    aj = nc.aba(tree, qj, vj, np.zeros(len(MimicMap(tree).independent)), kernels="tables")
    q, v = tree.from_joint_space(qj, vj)
    a, _ = nc.forward_dynamics(tree, q, v)
    np.testing.assert_allclose(aj, tree.to_joint_space(q, v, a)[2], rtol=0, atol=1e-9)


def test_mimic_gripper_closed_form(library):
    """Two fingers sliding along z, the second mimicking the first with factor −2: under
    gravity ``z̈1 (m + 4m) = −m g + 2 m g``."""
    s = nc.System("table_gripper", gravity=(0, 0, -G))
    b1 = s.add_body("b1", mass=1.0, inertia=np.diag([0.1, 0.2, 0.25]), position=(0.5, 0, 0))
    b2 = s.add_body("b2", mass=1.0, inertia=np.diag([0.1, 0.2, 0.25]), position=(0.5, 1, 0))
    j1 = s.add_joint(nc.Prismatic(s.ground, b1, at=(0.5, 0, 0), axis=(0, 0, 1), name="f1"))
    j2 = s.add_joint(nc.Prismatic(s.ground, b2, at=(0.5, 1, 0), axis=(0, 0, 1), name="f2"))
    s.add_joint(nc.Mimic(j1, j2, multiplier=-2.0, name="link"))
    model = s.build()
    np.testing.assert_allclose(nc.aba(model, [0.1, -0.2], [0.0, 0.0], [0.0], kernels="tables"),
                               [G / 5, -2 * G / 5], atol=1e-12)
    np.testing.assert_allclose(nc.crba(model, [0.1, -0.2], kernels="tables"), [[5.0]], atol=1e-12)
    np.testing.assert_allclose(nc.rnea(model, [0.1, -0.2], [0.0, 0.0], [1.0, -2.0], kernels="tables"),
                               [5.0 + G - 2 * G], atol=1e-12)


def _moved(model, qj, delta, h):
    """``q_j ⊕ h G δ`` to second order: integrated along the position rates (RK4, 8 steps)."""
    js, mimic = model.joint_space, MimicMap(model)
    w = mimic.G @ delta
    sq, sv = js.slices(), js.slices(rates=True)
    import casadi as ca

    x = ca.SX.sym("x", js.nq)
    rates = ca.Function("r", [x], [ca.vertcat(*[js.position_rates(n, x[sq[n]], ca.DM(w[sv[n]]))
                                                for n in js.joint_names])])
    q, dt = np.array(qj, float), h / 8
    for _ in range(8):
        k1 = np.array(rates(q)).ravel()
        k2 = np.array(rates(q + dt / 2 * k1)).ravel()
        k3 = np.array(rates(q + dt / 2 * k2)).ravel()
        k4 = np.array(rates(q + dt * k3)).ravel()
        q = q + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return q


def test_derivatives_against_central_differences(tree, library):
    rng = np.random.default_rng(2)
    qj, vj, aj, tau = random_state(tree, rng)
    G_ = MimicMap(tree).G
    n, h = G_.shape[1], 1e-4
    t0, dq, dv, M = nc.rnea_derivatives(tree, qj, vj, aj, kernels="tables")
    a0, da_dq, da_dv, Minv = nc.aba_derivatives(tree, qj, vj, tau, kernels="tables")
    np.testing.assert_allclose(Minv @ M, np.eye(n), atol=1e-10)
    for c in range(n):
        e = np.eye(n)[c]
        qp, qm = _moved(tree, qj, e, h), _moved(tree, qj, e, -h)
        fd_tq = (nc.rnea(tree, qp, vj, aj, kernels="tables") - nc.rnea(tree, qm, vj, aj, kernels="tables")) / (2 * h)
        fd_tv = (nc.rnea(tree, qj, vj + h * G_ @ e, aj, kernels="tables")
                 - nc.rnea(tree, qj, vj - h * G_ @ e, aj, kernels="tables")) / (2 * h)
        fd_aq = (nc.aba(tree, qp, vj, tau, kernels="tables") - nc.aba(tree, qm, vj, tau, kernels="tables")) / (2 * h)
        fd_av = (nc.aba(tree, qj, vj + h * G_ @ e, tau, kernels="tables")
                 - nc.aba(tree, qj, vj - h * G_ @ e, tau, kernels="tables")) / (2 * h)
        ind = MimicMap(tree).independent
        for got, want, what in ((dq[:, c], fd_tq, "dtau_dq"), (dv[:, c], fd_tv, "dtau_dv"),
                                (da_dq[:, c], fd_aq[ind], "da_dq"), (da_dv[:, c], fd_av[ind], "da_dv")):
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-6 * max(1.0, np.abs(want).max()), err_msg=what)


def test_batched_calls(tree, library):
    rng = np.random.default_rng(3)
    rows = [random_state(tree, rng) for _ in range(4)]
    Q, V, A, T = (np.array(x) for x in zip(*rows))
    tau = nc.rnea(tree, Q, V, A, kernels="tables")
    M = nc.crba(tree, Q, kernels="tables")
    a, da_dq, _, _ = nc.aba_derivatives(tree, Q, V, T, kernels="tables")
    assert tau.shape == (4, T.shape[1]) and M.shape == (4, T.shape[1], T.shape[1]) and a.shape == V.shape
    for i in range(4):
        np.testing.assert_array_equal(tau[i], nc.rnea(tree, Q[i], V[i], A[i], kernels="tables"))
        np.testing.assert_array_equal(M[i], nc.crba(tree, Q[i], kernels="tables"))
        np.testing.assert_array_equal(da_dq[i], nc.aba_derivatives(tree, Q[i], V[i], T[i], kernels="tables")[1])


def test_uncovered_models_are_refused_by_name_and_auto_runs_flat(library):
    s = nc.System("sprung", gravity=(0, 0, -G))
    b = s.add_body("b", mass=1.0, inertia=np.diag([0.1, 0.2, 0.25]), position=(0.5, 0, 0))
    s.add_joint(nc.Revolute(s.ground, b, at=(0, 0, 0), axis=(0, 1, 0), name="hinge"))
    s.add_force(nc.Spring(s.ground, (0.0, 0.0, 1.0), b, (0.5, 0.0, 0.0), k=30.0, rest_length=0.5))
    model = s.build()
    with pytest.raises(UnsupportedTree, match="passive forces other than a uniform gravity"):
        tree_tables(model)
    with pytest.raises(UnsupportedTree, match="sprung"):
        nc.rnea(model, [0.3], [0.0], [0.0], kernels="tables")
    assert rta.algorithm_kernels(model, "rnea") == "flat"
    with pytest.raises(nc.NcgenError, match="kernels: expected one of 'auto', 'tables', 'flat'"):
        nc.rnea(model, [0.3], [0.0], [0.0], kernels="table")


def test_bad_arguments_are_refused(tree, library):
    qj, vj, aj, _ = random_state(tree, np.random.default_rng(4))
    with pytest.raises(ShapeError, match="vj"):
        nc.rnea(tree, qj, vj[:-1], aj, kernels="tables")
    with pytest.raises(ShapeError, match="aj"):
        nc.rnea(tree, qj, vj, np.full_like(aj, np.nan), kernels="tables")


def test_joint_simulation_on_the_tables_conserves_energy(tree, library):
    """``method="joint"`` on the tree tables (Dormand–Prince, then RK4): the free motion of the
    every-kind tree under gravity keeps its energy; a model the tables do not cover is refused
    by name with ``kernels="tables"``."""
    q0, v0 = tree.from_joint_space(*random_state(tree, np.random.default_rng(5))[:2])
    for opts in ({"integrator": "dopri5", "rtol": 1e-10, "atol": 1e-12}, {"integrator": "rk4", "substeps": 20}):
        traj = nc.simulate(tree, 0.5, 0.01, q0=q0, v0=v0, method="joint", kernels="tables", **opts)
        assert traj.info["kernels"] == "tables"
        assert traj.energy_drift <= 1e-6 * max(1.0, traj.energy_scale), (opts, traj.energy_drift)
    s = nc.System("sprung_sim", gravity=(0, 0, -G))
    b = s.add_body("b", mass=1.0, inertia=np.diag([0.1, 0.2, 0.25]), position=(0.5, 0, 0))
    s.add_joint(nc.Revolute(s.ground, b, at=(0, 0, 0), axis=(0, 1, 0), name="hinge"))
    s.add_force(nc.Spring(s.ground, (0.0, 0.0, 1.0), b, (0.5, 0.0, 0.0), k=30.0, rest_length=0.5))
    with pytest.raises(UnsupportedTree, match="sprung_sim"):
        nc.simulate(s.build(), 0.1, 0.01, method="joint", kernels="tables")


@pytest.mark.slow
def test_joint_simulation_tables_equal_flat(tree, library):
    """The joint-space run on the tables equals the flat compiled loop (same integrator steps)."""
    q0, v0 = tree.from_joint_space(*random_state(tree, np.random.default_rng(6))[:2])
    a, b = (nc.simulate(tree, 0.3, 0.01, q0=q0, v0=v0, method="joint", kernels=k) for k in ("tables", "flat"))
    assert (a.info["kernels"], b.info["kernels"]) == ("tables", "flat")
    np.testing.assert_allclose(a.qj, b.qj, rtol=0, atol=1e-10)


def test_auto_uses_the_tables_for_a_covered_tree_only_without_a_compiler(tree, library, monkeypatch):
    """``kernels="auto"`` keeps the faster flat kernels where a compiler can build them and
    takes the tables where none can (the CRBA; this tree's ABA, of more than 12 rates, is the
    tables' anyway)."""
    from ncgen.model.data import model_data

    assert rta.algorithm_kernels(tree, "crba") == "flat"
    assert rta.algorithm_kernels(tree, "aba") == "tables" and tree.joint_space.nv > rta.TABLES_ABA_RATES
    monkeypatch.setattr(rta, "compiler_present", lambda cc=None: False)
    monkeypatch.delitem(model_data(tree).algorithm_kernels, ("crba", None), raising=False)
    assert rta.algorithm_kernels(tree, "crba") == "tables"


URDF = """<robot name="{name}">
  <link name="base"><inertial><mass value="2.0"/><origin xyz="0 0 0.05"/>
    <inertia ixx="0.01" iyy="0.012" izz="0.013" ixy="0" ixz="0" iyz="0"/></inertial></link>
  {links}
</robot>"""
LINK = """<link name="l{k}"><inertial><mass value="{m}"/><origin xyz="0.01 0.02 {c}" rpy="0.1 0.2 0.3"/>
    <inertia ixx="{i}" iyy="0.011" izz="0.009" ixy="0.001" ixz="0" iyz="0.0005"/></inertial></link>
  <joint name="j{k}" type="{kind}"><parent link="{parent}"/><child link="l{k}"/>
    <origin xyz="0.02 0.01 0.3" rpy="0.3 -0.2 0.1"/><axis xyz="{axis}"/>
    <limit effort="50" velocity="3" lower="-2" upper="2"/></joint>"""

CHILD = r"""
import json, shutil, sys
import numpy as np
import ncgen as nc
import ncgen.codegen.compile_cache as cc

assert not any(shutil.which(c) for c in ("cc", "gcc", "clang")), "a compiler is on PATH"
def no_compile(*a, **k):
    raise AssertionError("the compiler was called")
cc.compile_package = no_compile
if sys.argv[1].endswith(".urdf"):
    model = nc.System.from_urdf(sys.argv[1]).build()
else:
    s = nc.System(sys.argv[1], gravity=(0.0, 0.0, -9.81))
    b1 = s.add_body("b1", mass=1.3, inertia=np.diag([0.1, 0.2, 0.25]), position=(0.4, 0.0, 0.1))
    b2 = s.add_body("b2", mass=0.8, inertia=np.diag([0.05, 0.06, 0.07]), position=(0.9, 0.1, 0.0))
    s.add_joint(nc.Revolute(s.ground, b1, at=(0.0, 0.0, 0.0), axis=(0.0, 1.0, 0.0), name="hinge"))
    s.add_joint(nc.Prismatic(b1, b2, at=(0.8, 0.0, 0.0), axis=(1.0, 0.0, 0.0), name="slide"))
    model = s.build()
qj = np.array(model.joint_space.positions(model.q0)).ravel() + 0.2
v = np.full(model.joint_space.nv, 0.3)
tau = nc.rnea(model, qj, v, np.zeros_like(v))
a = nc.aba(model, qj, v, tau)
M = nc.crba(model, qj)
traj = nc.simulate(model, 0.2, 0.01)
print(json.dumps({"a": np.abs(a).max(), "M": M.tolist(), "tau": tau.tolist(), "method": traj.info["method"],
                  "kernels": traj.info["kernels"], "drift": traj.energy_drift / max(1.0, traj.energy_scale)}))
"""


def new_urdf(name: str) -> str:
    kinds = ["revolute", "prismatic", "continuous"]
    axes = ["0 0 1", "1 0 0", "0.6 0 0.8"]
    links = "\n  ".join(LINK.format(k=k, m=0.5 + 0.1 * k, c=0.1 + 0.01 * k, i=0.01 + 0.001 * k, kind=kinds[k],
                                    parent="base" if k == 0 else f"l{k - 1}", axis=axes[k]) for k in range(3))
    return URDF.format(name=name, links=links)


def no_compiler_run(tmp_path, arg: str) -> dict:
    """The CHILD's output for ``arg`` (a URDF path or a System's name), run with no compiler."""
    empty = tmp_path / "bin"
    empty.mkdir(exist_ok=True)
    env = {k: v for k, v in os.environ.items() if k not in ("CC", "PATH")}
    env["PATH"] = str(empty)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    out = subprocess.run([sys.executable, "-c", CHILD, arg], env=env, capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr[-3000:]
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["a"] <= 1e-10                     # ABA of the RNEA efforts of a = 0 gives back a = 0
    M = np.array(got["M"])
    np.testing.assert_allclose(M, M.T, atol=1e-14)
    assert np.all(np.linalg.eigvalsh(M) > 0)
    # simulated in joint space on the tables (method="auto" picks it with no compiler)
    assert (got["method"], got["kernels"]) == ("joint", "tables")
    assert got["drift"] <= 1e-6, got["drift"]
    return got


def test_a_new_tree_needs_no_compiler(library, tmp_path):
    """Once the tree library is cached, a new tree gets RNEA, ABA and CRBA and is simulated
    in joint space in a process with no compiler on PATH (and compile_package replaced by a
    failure); the energy of the free motion is conserved."""
    got = no_compiler_run(tmp_path, f"new_tree_{os.getpid()}")
    assert len(got["tau"]) == 2 and np.all(np.abs(got["tau"]) > 0.1)      # both joints hold weight


@pytest.mark.slow
def test_a_new_urdf_robot_needs_no_compiler(library, tmp_path):
    """The same for a URDF robot not seen before (revolute, prismatic, continuous joints,
    rotated inertias)."""
    path = tmp_path / "new_arm.urdf"
    path.write_text(new_urdf(f"new_arm_{os.getpid()}"))
    no_compiler_run(tmp_path, str(path))


ROBOTS = ("panda", "ur5", "solo12", "talos")


@pytest.mark.slow
@pytest.mark.timeout(3600)
@pytest.mark.parametrize("name", ROBOTS)
def test_urdf_robots_match_pinocchio_and_the_flat_kernels(name, library, monkeypatch):
    """example-robot-data's URDFs as shipped (the Panda's mimic finger, Solo12's and Talos'
    free flyers): every algorithm from the tables against Pinocchio to 1e-10 of the largest
    entry (the checks of tests/test_tree_algorithms_pinocchio.py, which ``kernels="auto"``
    sends to the tables when no compiler is present), and RNEA, CRBA, ABA against the flat compiled kernels to 1e-12."""
    pytest.importorskip("pinocchio")
    import test_tree_algorithms_pinocchio as ref

    model = ref.model_of(name)
    monkeypatch.setattr(rta, "compiler_present", lambda cc=None: False)
    assert rta.algorithm_kernels(model, "rnea") == "tables"
    monkeypatch.setattr(ref, "TOL", 1e-10)
    monkeypatch.setattr(ref, "model_of", lambda _: model)
    ref.check_robot(name)
    pm_mimic, pm = ref.pinocchio_models(name)
    jm, mimic = ref.JointMap(model, pm), MimicMap(model)
    for qj, _, v_i, a_i, tau_i in ref.states(model, pm, jm, mimic, seed=7):
        vj, aj = mimic.G @ v_i, mimic.G @ a_i
        for alg, args in (("rnea", (qj, vj, aj)), ("crba", (qj,)), ("aba", (qj, vj, tau_i))):
            want = getattr(nc, alg)(model, *args, kernels="flat")
            np.testing.assert_allclose(getattr(nc, alg)(model, *args, kernels="tables"), want, rtol=0,
                                       atol=1e-12 * max(1.0, np.abs(want).max()), err_msg=f"{name} {alg}")


@pytest.mark.slow      # writes every unit twice, compiles each source at -Werror (≈ 25 gcc calls); fast:
#                       test_tables_equal_the_flat_functions compiles every unit through the library fixture
def test_tree_package_is_deterministic_and_warning_free(tmp_path):
    """The tree library's package (every unit in one library) and each of its units: the same
    bytes when written twice, and their C compiles with -Wall -Wextra -Werror."""
    from ncgen.codegen.tree_kernels import ALGORITHM_UNITS, kernel_units, write_tree_package, write_tree_unit

    cc = os.environ.get("CC") or next(shutil.which(c) for c in CANDIDATES if shutil.which(c))
    writers = {"all": write_tree_package, **{u: (lambda out, u=u: write_tree_unit(u, out))
                                            for u in (*ALGORITHM_UNITS, *kernel_units())}}
    for unit, write in writers.items():
        a, b = write(tmp_path / unit / "a"), write(tmp_path / unit / "b")
        files = sorted(p.name for p in a.path.iterdir())
        assert files == sorted(p.name for p in b.path.iterdir())
        for name in files:
            assert (a.path / name).read_bytes() == (b.path / name).read_bytes(), (unit, name)
        for src in a.manifest["build"]["sources"]:
            out = subprocess.run([*cc.split(), "-std=c99", "-Wall", "-Wextra", "-Werror", "-O0", "-I.", "-c", src,
                                  "-o", str(tmp_path / f"{src}.o")], cwd=a.path, capture_output=True, text=True,
                                 timeout=600)
            assert out.returncode == 0, (unit, out.stderr[-3000:])


@pytest.mark.slow      # compiles six units into an empty cache; fast: test_tables_equal_the_flat_functions,
#                       test_auto_joint_run_takes_the_tables_and_says_why (missing_units)
def test_units_are_compiled_as_trees_need_them(tmp_path, monkeypatch):
    """A fresh compile cache: forward dynamics of a revolute/prismatic tree compiles the forward
    unit alone, its RNEA the inverse unit; a spherical joint adds its local kernel unit, the
    derivatives the derivatives unit with the edge kernels of its kinds and the body's; the
    tables of a kind whose kernels are not set are refused by the unit's check."""
    import ctypes

    import ncgen.runtime.tree_library as tl
    from ncgen.codegen.tree_tables import tree_tables

    monkeypatch.setenv("NCGEN_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(tl, "_LOADED", {})
    compiled = []
    unit_library = tl.unit_library
    monkeypatch.setattr(tl, "unit_library", lambda unit, cflags=None: compiled.append(unit) or unit_library(unit, cflags))
    model = small_tree(f"units_tree_{os.getpid()}")
    qj, vj = np.array([0.3, 0.1]), np.array([0.2, -0.1])
    assert tl.missing_units(["revolute", "prismatic"]) == ["forward"]
    nc.aba(model, qj, vj, np.zeros(2), kernels="tables")
    assert compiled == ["forward"] and tl.missing_units(["revolute", "prismatic"]) == []
    nc.rnea(model, qj, vj, np.zeros(2), kernels="tables")
    assert compiled == ["forward", "inverse"]
    s = nc.System(f"units_ball_{os.getpid()}", gravity=(0.0, 0.0, -G))
    b = s.add_body("b", mass=1.0, inertia=np.diag([0.1, 0.2, 0.3]), position=(0.0, 0.0, -0.5))
    s.add_joint(nc.Spherical(s.ground, b, at=(0.0, 0.0, 0.0), name="ball"))
    ball = s.build()
    q = np.array(ball.joint_space.positions(ball.q0)).ravel()
    unit = tl.load_tree_library().unit("forward", ["revolute"])
    tables = tree_tables(ball)
    arrays = {f: np.ascontiguousarray(tables.arrays[f], dtype=np.int32 if "int" in t else np.float64)
              for t, f in tl.TREE_FIELDS if "*" in t}
    struct = tl._Tree(nb=tables.nb, nq=tables.nq, nv=tables.nv, ni=tables.ni,
                      **{k: v.ctypes.data for k, v in arrays.items()})
    assert unit.fn["check"](ctypes.addressof(struct)) == 3            # the spherical joint's tl kernel not set
    a = nc.aba(ball, q, np.zeros(3), np.zeros(3), kernels="tables")
    np.testing.assert_allclose(a, nc.aba(ball, q, np.zeros(3), np.zeros(3), kernels="flat"), atol=1e-12)
    assert compiled[2:] == ["local_spherical"]
    nc.aba_derivatives(ball, q, np.full(3, 0.1), np.zeros(3), kernels="tables")
    assert compiled[3:] == ["derivatives", "edge_spherical", "body"]



def test_a_unit_loaded_under_other_flags_is_never_reused(monkeypatch):
    """The tree library's loaded units, the bound tables and their algorithms are kept per
    process by the flags of the units (``cflags`` and ``$NCGEN_CFLAGS``): under other flags
    ``table_algorithm`` binds the tables again to a library of its own, which loads the unit
    compiled with those flags (recorded here, not compiled), and the earlier ones are found
    again under their own flags."""
    import ncgen.runtime.tree_library as tl

    model = small_tree(f"flags_tree_{os.getpid()}")
    k = tl.table_algorithm(model, "aba")
    assert tl.table_algorithm(model, "aba") is k and k.tree.library is tl.load_tree_library()
    flags = os.environ.get("NCGEN_CFLAGS")
    loads = []

    class Loaded(Exception):
        pass

    def unit_library(unit, cflags=None):
        loads.append((unit, cflags, os.environ["NCGEN_CFLAGS"]))         # what cached_library compiles with
        raise Loaded

    monkeypatch.setattr(tl, "unit_library", unit_library)
    monkeypatch.setenv("NCGEN_CFLAGS", f"{flags or ''} -DNCGEN_OTHER_FLAGS")
    assert tl.load_tree_library() is not k.tree.library
    assert tl.bound_tree(model) is not k.tree and tl.bound_tree(model).library is tl.load_tree_library()
    with pytest.raises(Loaded):
        tl.table_algorithm(model, "aba")
    assert loads == [("forward", None, f"{flags or ''} -DNCGEN_OTHER_FLAGS")]
    monkeypatch.undo()
    assert tl.table_algorithm(model, "aba") is k and tl.load_tree_library() is k.tree.library



def test_a_library_built_at_given_flags_is_found_under_those_flags_only(tmp_path, monkeypatch):
    """The compile cache's index of a shared library (the tree library's units, the element
    library) names the flags it was built with, given (``UNIT_CFLAGS``) or ``$NCGEN_CFLAGS``: a
    library built at -O1 is not taken for -O3 or ncgen's defaults, nor the reverse; the same flags
    from the environment find it (compiles recorded here, not run)."""
    from types import SimpleNamespace

    import ncgen.codegen.compile_cache as cc
    import ncgen.runtime.table_library as tab

    monkeypatch.setenv("NCGEN_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("NCGEN_CFLAGS", raising=False)
    built = []

    def compile_package(out, cflags=None, env_flags=True):
        built.append(cflags)
        library = tmp_path / f"probe_{len(built)}.so"
        library.write_text(str(cflags))
        return SimpleNamespace(path=library, compiler=SimpleNamespace(version="cc 12"))

    monkeypatch.setattr(cc, "compile_package", compile_package)
    monkeypatch.setattr(tab, "entry_problem", lambda d, library: None if library.exists() else "missing")
    monkeypatch.setattr(tab, "installed_library", lambda *a: None)
    source = "s" * 64
    paths = {flags: tab.cached_library("probe", source, lambda out: out, "probe", flags)[0]
             for flags in ("-O1", "-O3", None)}
    assert built == ["-O1", "-O3", None] and len(set(paths.values())) == 3
    assert tab.cached_library("probe", source, lambda out: out, "probe", "-O3") == (paths["-O3"], False)
    assert tab.library_ready("probe", source, "-O1") and not tab.library_ready("probe", source, "-O2")
    monkeypatch.setenv("NCGEN_CFLAGS", "-O1")
    assert tab.cached_library("probe", source, lambda out: out, "probe") == (paths["-O1"], False)
    assert not tab.library_ready("probe", source, "-O2") and len(built) == 3


#: Bodies of mass 1 sliding freely along z on the ground (a = τ − g each) beside a small mimic tree:
#: with them it has more than 12 rates (NCGEN_TREE_DENSE_NV of ncgen_tree_tables.h, up to which
#: forward dynamics is a Cholesky of M_i), so its forward dynamics runs the articulated-body algorithm.
FREE_SLIDERS = 11


def add_free_sliders(s) -> None:
    for k in range(FREE_SLIDERS):
        b = s.add_body(f"s{k}", mass=1.0, inertia=np.diag([0.1, 0.2, 0.25]), position=(2.0 + k, 0.0, 0.0))
        s.add_joint(nc.Prismatic(s.ground, b, at=(2.0 + k, 0.0, 0.0), axis=(0, 0, 1), name=f"s{k}"))


def fallback_tree(name: str):
    """Where forward dynamics needs the Cholesky fallback: b2 (mass 1e-13) slides along z on the
    ground, a mimic follower of b1 (z2 = −2 z1), and carries b3 sliding along z; the tree with every
    rate free has a relative ABA pivot of 1e-13 at b2's joint, while M_i (rates z1, z3) is well
    conditioned.  Lagrangian in (z1, z3), b3 at height z2 + z3: M_i = [[m1 + 4 ε + 4 m3, −2 m3],
    [−2 m3, m3]], gravity forces −g (m1 − 2 ε − 2 m3, m3); then the free sliders (rates after z3)."""
    s = nc.System(name, gravity=(0.0, 0.0, -G))
    bodies = [s.add_body(f"b{k}", mass=m, inertia=np.diag([0.1, 0.2, 0.25]) * m, position=(0.5, y, 0.0))
              for k, (m, y) in enumerate(((1.0, 0.0), (1e-13, 1.0), (1.0, 1.0)), start=1)]
    j1 = s.add_joint(nc.Prismatic(s.ground, bodies[0], at=(0.5, 0.0, 0.0), axis=(0, 0, 1), name="f1"))
    j2 = s.add_joint(nc.Prismatic(s.ground, bodies[1], at=(0.5, 1.0, 0.0), axis=(0, 0, 1), name="f2"))
    s.add_joint(nc.Prismatic(bodies[1], bodies[2], at=(0.5, 1.0, 0.0), axis=(0, 0, 1), name="f3"))
    s.add_joint(nc.Mimic(j1, j2, multiplier=-2.0, name="link"))
    add_free_sliders(s)
    return s.build()


@pytest.mark.slow      # a fallback unit compiled into an empty cache; fast:
#                       test_articulated_body_algorithm_equals_the_flat_function_and_the_kkt_solve
def test_the_cholesky_fallback_is_compiled_when_a_tree_first_needs_it(tmp_path, monkeypatch):
    """A fresh compile cache: a mimic tree whose constrained ABA succeeds (the gripper, beside
    the free sliders) compiles the forward unit alone; a tree whose constrained ABA fails its pivot check
    (:func:`fallback_tree`) then gets the Cholesky fallback, the inverse unit's: its joint-space
    run (restarted once the fallback is set) and its forward dynamics equal the closed form of
    the Lagrangian in the independent rates and the flat function (1e-12), and its energy holds."""
    import ncgen.runtime.tree_library as tl

    monkeypatch.setenv("NCGEN_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(tl, "_LOADED", {})
    compiled = []
    unit_library = tl.unit_library
    monkeypatch.setattr(tl, "unit_library", lambda unit, cflags=None: compiled.append(unit) or unit_library(unit, cflags))
    s = nc.System(f"fallback_gripper_{os.getpid()}", gravity=(0, 0, -G))
    b1 = s.add_body("b1", mass=1.0, inertia=np.diag([0.1, 0.2, 0.25]), position=(0.5, 0, 0))
    b2 = s.add_body("b2", mass=1.0, inertia=np.diag([0.1, 0.2, 0.25]), position=(0.5, 1, 0))
    j1 = s.add_joint(nc.Prismatic(s.ground, b1, at=(0.5, 0, 0), axis=(0, 0, 1), name="f1"))
    j2 = s.add_joint(nc.Prismatic(s.ground, b2, at=(0.5, 1, 0), axis=(0, 0, 1), name="f2"))
    s.add_joint(nc.Mimic(j1, j2, multiplier=-2.0, name="link"))
    add_free_sliders(s)
    gripper = s.build()
    traj = nc.simulate(gripper, 0.2, 0.05, method="joint", kernels="tables")
    np.testing.assert_allclose(traj.qj[-1, 0] - traj.qj[0, 0], G / 5 * 0.2 ** 2 / 2, rtol=1e-9)
    assert compiled == ["forward"] and not tl.load_tree_library().fallback

    model = fallback_tree(f"fallback_tree_{os.getpid()}")
    eps, m = 1e-13, 1.0
    Mi = np.array([[m + 4 * eps + 4 * m, -2 * m], [-2 * m, m]])
    a_i = np.linalg.solve(Mi, -G * np.array([m - 2 * eps - 2 * m, m]))          # (−g, −3g)
    traj = nc.simulate(model, 0.2, 0.05, method="joint", kernels="tables", integrator="dopri5",
                       rtol=1e-10, atol=1e-12)
    assert compiled == ["forward", "inverse"] and tl.load_tree_library().fallback
    assert traj.info["kernels"] == "tables"
    t = traj.t - traj.t[0]
    free = np.full(FREE_SLIDERS, -G)
    expected = traj.qj[0][None, :] + np.outer(t ** 2 / 2, [a_i[0], -2 * a_i[0], a_i[1], *free])
    np.testing.assert_allclose(traj.qj, expected, rtol=0, atol=1e-9)
    assert traj.energy_drift <= 1e-9 * max(1.0, traj.energy_scale)
    qj = np.r_[0.1, -0.2, 0.3, np.linspace(-0.5, 0.5, FREE_SLIDERS)]
    vj = np.r_[0.4, -0.8, -0.1, np.linspace(1.0, -1.0, FREE_SLIDERS)]
    for tau in (np.zeros(2 + FREE_SLIDERS), np.r_[0.7, -0.3, np.linspace(-2.0, 2.0, FREE_SLIDERS)]):
        got = nc.aba(model, qj, vj, tau, kernels="tables")
        want = np.linalg.solve(Mi, tau[:2] - G * np.array([m - 2 * eps - 2 * m, m]))
        np.testing.assert_allclose(got, [want[0], -2 * want[0], want[1], *(tau[2:] - G)], rtol=0, atol=1e-12)
        np.testing.assert_allclose(got, nc.aba(model, qj, vj, tau, kernels="flat"), rtol=0, atol=1e-12)
    assert compiled == ["forward", "inverse"]


def small_tree(name: str):
    """A hinge and a slider on two bodies: a tree the tables cover, new to this process."""
    s = nc.System(name, gravity=(0.0, 0.0, -G))
    b1 = s.add_body("b1", mass=1.3, inertia=np.diag([0.1, 0.2, 0.25]), position=(0.4, 0.0, 0.1))
    b2 = s.add_body("b2", mass=0.8, inertia=np.diag([0.05, 0.06, 0.07]), position=(0.9, 0.1, 0.0))
    s.add_joint(nc.Revolute(s.ground, b1, at=(0.0, 0.0, 0.0), axis=(0.0, 1.0, 0.0), name="hinge"))
    s.add_joint(nc.Prismatic(b1, b2, at=(0.8, 0.0, 0.0), axis=(1.0, 0.0, 0.0), name="slide"))
    return s.build()


def test_auto_runs_the_aba_of_a_tree_of_more_than_12_rates_on_the_tables():
    """``kernels="auto"`` takes the tables' articulated-body loops for the ABA of a tree of
    more than :data:`~ncgen.runtime.tree_algorithm_kernels.TABLES_ABA_RATES` rates (a hinge and
    a slider beside 11 free sliders: 13) and the flat kernel up to them; its accelerations
    equal the flat kernel's (1e-12) and, for the free sliders of mass 1, the closed form
    a = τ − g; the call goes straight to the tables' C caller."""
    s = nc.System(f"auto_aba_tree_{os.getpid()}", gravity=(0.0, 0.0, -G))
    b1 = s.add_body("b1", mass=1.3, inertia=np.diag([0.1, 0.2, 0.25]), position=(0.4, 0.0, 0.1))
    b2 = s.add_body("b2", mass=0.8, inertia=np.diag([0.05, 0.06, 0.07]), position=(0.9, 0.1, 0.0))
    s.add_joint(nc.Revolute(s.ground, b1, at=(0.0, 0.0, 0.0), axis=(0.0, 1.0, 0.0), name="hinge"))
    s.add_joint(nc.Prismatic(b1, b2, at=(0.8, 0.0, 0.0), axis=(1.0, 0.0, 0.0), name="slide"))
    add_free_sliders(s)
    model = s.build()
    assert model.joint_space.nv == rta.TABLES_ABA_RATES + 1
    assert rta.algorithm_kernels(model, "aba") == "tables" and "measures faster" in rta.kernels_reason(model, "aba")
    assert rta.algorithm_kernels(model, "crba") == "flat"
    assert rta.algorithm_kernels(small_tree(f"auto_aba_small_{os.getpid()}"), "aba") == "flat"
    rng = np.random.default_rng(13)
    qj, vj, tau = (rng.uniform(-1, 1, model.joint_space.nv) for _ in range(3))
    a = nc.aba(model, qj, vj, tau)
    assert rta.door(model, "aba").tables and rta.door(model, "aba").free is not None
    np.testing.assert_allclose(a, nc.aba(model, qj, vj, tau, kernels="flat"), rtol=0, atol=1e-12)
    np.testing.assert_allclose(a[2:], tau[2:] - G, rtol=0, atol=1e-12)



def test_rate_kernels_only_where_the_position_rates_are_not_the_rates():
    """The kinds whose ``q̇`` the loops copy from ``w`` (no ``tk_<k>_qdot``) are exactly those
    whose position rates (ncgen.assembly.joint_space, at random positions and rates) equal
    the rates; the others keep their kernels in every algorithm unit."""
    import casadi as ca

    from ncgen.assembly.joint_space import joint_position_rates
    from ncgen.codegen.tree_kernels import ALGORITHM_UNITS, JOINT_KINDS, rate_kernel_kinds, unit_kernels

    rng = np.random.default_rng(3)
    copied = []
    for k in JOINT_KINDS:
        if not k.nq:
            continue
        q, w = rng.normal(size=k.nq), rng.normal(size=k.nv)
        rates = np.array(ca.evalf(joint_position_rates(k.kind, 3, k.nq, ca.DM(q), ca.DM(w)))).ravel()
        if rates.shape == w.shape and np.array_equal(rates, w):
            copied.append(k.name)
    assert set(copied) == {"revolute", "prismatic", "cylindrical", "universal", "planar"}
    assert rate_kernel_kinds() == tuple(k.name for k in JOINT_KINDS if k.nq and k.name not in copied)
    for unit in ALGORITHM_UNITS:
        assert [f.name() for f in unit_kernels(unit)] == [f"tk_{k}_qdot" for k in rate_kernel_kinds()]


def test_joint_kernels_rule():
    """``backend_policy.choose_joint_kernels``: the tables for a short run, the flat loop when
    it is ready or when the run is long enough for its faster evaluations to pay its compile."""
    from ncgen.runtime import backend_policy as bp

    assert bp.choose_joint_kernels(9, 10, None).backend == "tables"
    assert bp.choose_joint_kernels(9, 10, "loaded in this process").backend == "flat"
    cost = bp.JOINT_COMPILE_FIXED_SECONDS + 9 * bp.JOINT_COMPILE_SECONDS_PER_RATE
    pays = int(cost / (bp.JOINT_EVALS_PER_OUTPUT * 9 * bp.TABLES_EXTRA_SECONDS)) + 1
    assert bp.choose_joint_kernels(9, pays - 1, None).backend == "tables"
    choice = bp.choose_joint_kernels(9, pays, None)
    assert choice.backend == "flat" and "saves" in choice.reason
    # the forward unit not compiled yet: the tables while it costs less than the model's own loop
    choice = bp.choose_joint_kernels(9, 10, None, ("forward",))
    assert choice.backend == "tables" and choice.reason.startswith("compiling the tree library's forward")
    units = bp.TREE_UNIT_COMPILE_SECONDS
    assert bp.choose_joint_kernels(9, pays - int(units / (bp.JOINT_EVALS_PER_OUTPUT * 9 * bp.TABLES_EXTRA_SECONDS)),
                                   None, ("forward",)).backend == "flat"
    many = ("forward", "local_spherical", "local_free", "local_planar", "local_universal")
    choice = bp.choose_joint_kernels(2, 10, None, many)                          # more to compile than a small loop
    assert choice.backend == "flat" and "local_universal not compiled yet" in choice.reason


def test_auto_joint_run_takes_the_tables_and_says_why(library, monkeypatch):
    """``method="joint"`` with ``kernels="auto"`` runs a new tree on the tables (nothing
    compiled for it: ``compile_package`` fails if called) and the summary says which kernels
    ran and why; a controller, joint dynamics or the user's choice send it to the flat loop;
    a bad value is refused by name."""
    import ncgen.codegen.compile_cache as cc
    from ncgen.runtime.joint_simulation import choose_kernels

    import ncgen.runtime.tree_library as tl

    model = small_tree(f"auto_tree_{os.getpid()}")
    assert tl.tree_library_ready() and not tl.missing_units(["revolute", "prismatic"])   # the fixture compiled it
    assert choose_kernels(model, 10).backend == "tables"
    missing = tl.missing_units
    monkeypatch.setattr(tl, "missing_units", lambda kinds, unit: ["forward"])
    from ncgen.runtime import backend_policy as bp
    assert choose_kernels(model, 10) == bp.choose_joint_kernels(2, 10, None, ("forward",))   # the unit's cost counted
    monkeypatch.setattr(tl, "missing_units", missing)
    assert choose_kernels(model, 10, controller=nc.PD(kp=10.0, kd=1.0, target=[0.0, 0.0])).backend == "flat"
    assert choose_kernels(model, 10, joint_dynamics=True).backend == "flat"
    assert choose_kernels(model, 10, kernels="flat").reason == "chosen"
    with pytest.raises(nc.NcgenError, match="kernels: expected one of 'auto', 'tables', 'flat', got 'table'"):
        choose_kernels(model, 10, kernels="table")

    def no_compile(*a, **k):
        raise AssertionError("the compiler was called")
    monkeypatch.setattr(cc, "compile_package", no_compile)
    traj = nc.simulate(model, 0.1, 0.01, method="joint")
    assert (traj.info["kernels"], traj.info["kernels_reason"].split(";")[0]) == ("tables", "nothing to compile")
    assert "  kernels: tables: nothing to compile" in traj.summary()
    assert traj.energy_drift <= 1e-6 * max(1.0, traj.energy_scale)


def test_cli_kernels_option_and_stored_tables(library, tmp_path, monkeypatch, capsys):
    """``ncgen simulate robot.urdf --kernels tables`` prints the kernels line; a later run of
    the same file reads the model's tree tables from the store of built models (not packed
    again)."""
    from ncgen.cli import main
    from ncgen.codegen import tree_tables as tt

    monkeypatch.setenv("NCGEN_MODEL_CACHE", "1")
    path = tmp_path / "arm.urdf"
    path.write_text(new_urdf(f"cli_arm_{os.getpid()}"))
    assert main(["simulate", str(path), "--t-end", "0.05", "--kernels", "tables"]) == 0
    assert "  kernels: tables: chosen" in capsys.readouterr().out
    monkeypatch.setattr(tt, "_pack", lambda model: pytest.fail("the tree tables were packed again"))
    assert main(["simulate", str(path), "--t-end", "0.05"]) == 0
    assert "  kernels: tables: nothing to compile" in capsys.readouterr().out


@pytest.mark.slow
@pytest.mark.timeout(1800)
def test_panda_joint_run_tables_equal_flat(library):
    """The Panda of example-robot-data (its mimic finger), 0.1 s under gravity in joint space:
    ``kernels="auto"`` runs the tables while the flat loop is not built, the flat loop once it
    is loaded; the tables' run equals the flat loop's to 1e-9 (the same steps).  The model is
    named for this process, so that no other test's Panda flat loop is in the compile cache."""
    try:
        path = nc.robots.urdf_path("panda")
    except Exception as e:  # noqa: BLE001 - example-robot-data not installed
        pytest.skip(f"no Panda URDF: {e}")
    model = nc.System.from_urdf(path, name=f"panda_tables_{os.getpid()}").build()
    auto = nc.simulate(model, 0.1, 0.01, method="joint")
    assert auto.info["kernels"] == "tables", auto.info["kernels_reason"]
    flat_run = nc.simulate(model, 0.1, 0.01, method="joint", kernels="flat")
    again = nc.simulate(model, 0.1, 0.01, method="joint")
    assert (again.info["kernels"], again.info["kernels_reason"]) == \
        ("flat", "the model's own loop is ready (loaded in this process)")
    assert auto.info["stats"] == flat_run.info["stats"]
    for x in ("qj", "vj"):
        a, b = getattr(auto, x), getattr(flat_run, x)
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9 * max(1.0, np.abs(b).max()), err_msg=x)


def test_member_twist_map_at_identity_equals_the_symbolic_map():
    """``member_twist_map_at_identity`` (the form evaluated in floats at the six unit twists)
    equals the symbolic map's Jacobian ``member_twist_map(js, m)(I, 0)`` for every 3D
    coordinate type, with random constants (its columns rely on ``q̇`` being linear in the twist)."""
    from types import SimpleNamespace

    from ncgen.assembly.tree_dynamics import member_twist_map, member_twist_map_at_identity
    from ncgen.model.member_forms import FORMS

    class Recorder(dict):
        def __missing__(self, key):
            self.setdefault("_keys", set()).add(key)
            return 0.5

    rng = np.random.default_rng(3)
    kinds = sorted(k for k, dim, what in FORMS if dim == 3 and what == "qd_of_twist")
    assert len(kinds) >= 5
    for kind in kinds:
        rec = Recorder()
        FORMS[kind, 3, "qd_of_twist"](rec)
        pose = re.compile(r"^(R_\d\d|p_[xyz]|omega_[xyz]|v_[xyz])$")
        constants = {k: np.float64(rng.uniform(-1.0, 1.0)) for k in rec["_keys"] if not pose.match(k)}
        member = SimpleNamespace(ctype=SimpleNamespace(name=kind), rigid=SimpleNamespace(constant_values=constants))
        js = SimpleNamespace(members={"m": member})
        expected = np.array(member_twist_map(js, "m")(np.eye(3), np.zeros(3)))
        got = member_twist_map_at_identity(js, "m")
        assert got.shape == expected.shape == (expected.shape[0], 6), kind
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-14 * max(1.0, np.max(np.abs(expected))),
                                   err_msg=kind)


def test_sources_key_follows_an_edited_source(tmp_path, monkeypatch):
    """The library's content key is cached per process but read again when a source changes on
    disk: a copy of the templates gives the shipped key, an edited template another, the original
    text back the shipped key again (hashes of the files' bytes, not of their dates)."""
    import os
    import shutil

    from ncgen.codegen.render import shipped_templates_dir
    from ncgen.codegen.tree_kernels import SOURCES
    from ncgen.runtime import tree_library

    shipped = tree_library.sources_key()
    for rel in SOURCES:
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(shipped_templates_dir() / rel, tmp_path / rel)
    monkeypatch.setattr(tree_library, "shipped_templates_dir", lambda: tmp_path)
    assert tree_library.sources_key() == shipped
    first = tmp_path / SOURCES[0]
    text = first.read_bytes()
    first.write_bytes(text + b"\n")
    edited = tree_library.sources_key()
    assert edited != shipped
    first.write_bytes(text)
    os.utime(first, ns=(1, 1))
    assert tree_library.sources_key() == shipped


def test_a_unit_compiled_ahead_is_compiled_once_and_leaves_the_choice_alone(tmp_path, monkeypatch):
    """``compile_ahead`` compiles a missing unit in a background thread (one the process waits
    for at exit); the unit's use waits for it and compiles nothing more; the run's choice still
    sees the unit missing (what a run that found it missing chooses, however far the compile
    got); nothing starts for a unit compiled already or without a compiler.  ``ncgen
    simulate`` starts the forward unit for a URDF run in joint space on the tables only."""
    import argparse
    import threading

    import ncgen.runtime.tree_library as tl
    from ncgen.cli import simulate as cli_simulate

    monkeypatch.setattr(tl, "_AHEAD", {})
    release, calls, built = threading.Event(), [], []

    def compile_(prefix, source, write, package, cflags=None):
        if built:
            return built[0], False
        calls.append((prefix, threading.current_thread().name))
        assert release.wait(30)
        built.append(tmp_path / package)
        return built[0], True

    monkeypatch.setattr(tl, "cached_library", compile_)
    monkeypatch.setattr(tl, "library_ready", lambda prefix, source, cflags=None: bool(built))
    monkeypatch.setattr(tl, "compiler_path", lambda: "/usr/bin/cc")
    assert tl.compile_ahead(["forward"]) == ["forward"] and tl.compile_ahead(["forward"]) == []
    thread = tl._AHEAD[("forward", None)]
    assert not thread.daemon and tl.missing_units(["revolute"]) == ["forward"]
    threading.Timer(0.3, release.set).start()
    assert tl.unit_library("forward") == (tmp_path / f"{tl.PACKAGE}_forward", False)       # waited for, found
    assert not thread.is_alive()
    assert calls == [("tree-tables-forward", "ncgen-compile-ahead")]
    assert tl.missing_units(["revolute"]) == [] and tl.compile_ahead(["forward"]) == []    # used: ready
    built.clear()
    monkeypatch.setattr(tl, "compiler_path", lambda: None)
    assert tl.compile_ahead(["forward"]) == [] and tl._AHEAD == {}                          # no compiler
    started = []
    monkeypatch.setattr(tl, "compile_ahead", started.append)
    run = dict(model="robot.urdf", method="auto", kernels="auto", controller=None, joint_dynamics=False,
               backend="auto")
    for change in ({}, {"method": "joint"}, {"kernels": "tables"}, {"model": "chain.toml"}, {"method": "idas"},
                   {"kernels": "flat"}, {"controller": "kind = 'pd'"}, {"joint_dynamics": True}, {"backend": "vm"}):
        cli_simulate._compile_ahead(argparse.Namespace(**{**run, **change}))
    assert started == [("forward",)] * 3
