"""Step Jacobians of the table-driven stepper (``nc.step_function(..., kernels="tables")``,
issues 34 and 37): the implicit function theorem on the table stepper's own Newton systems,
with no compiler call.  Checked against the flat step function (the same equations through
CasADi's generated code: steps and Jacobians equal to 1e-10) and against central differences
of the step itself (1e-6), on a chain, a chain of 25 bars (its 150 columns in three blocks), a
spatial four-bar, a controlled cart-pole (an input
force), a chain of spring-dampers pushed by inputs (the dampers' ∂F/∂w in both stages), a
planar arm on two actuated hinges, a URDF arm of three hinges and a slider (actuated:
their efforts' Hessians) and a URDF gripper whose second finger mimics the first (two
sliders in a fixed ratio); the z1 and the UR10 from their URDFs (slow); Talos against
Richardson-extrapolated differences (slow); a new model's Jacobians in a process with no
compiler on PATH; the automatic choice, the override and the refusal."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

import ncgen as nc
from ncgen.codegen.compiler import CANDIDATES
from ncgen.codegen.model_tables import UnsupportedElements
from ncgen.errors import NcgenError

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"
#: Agreement with the flat step function (relative to the largest entry, or 1).
FLAT = 1e-10
#: Agreement with central differences of the step (relative to the largest entry).
FD = 1e-6

pytestmark = pytest.mark.skipif(not any(shutil.which(c) for c in CANDIDATES) and not os.environ.get("CC"),
                                reason="no C compiler to build the element library")

ARM = """<?xml version="1.0"?>
<robot name="tab_arm3"><link name="base"/>
<link name="turret"><inertial><origin xyz="0 0 0.05" rpy="0.1 0 0.2"/><mass value="2.0"/>
<inertia ixx="0.02" ixy="0.001" ixz="0" iyy="0.02" iyz="0" izz="0.01"/></inertial></link>
<link name="upper"><inertial><origin xyz="0 0 0.2"/><mass value="1.0"/>
<inertia ixx="0.015" ixy="0" ixz="0" iyy="0.015" iyz="0" izz="0.004"/></inertial></link>
<link name="fore"><inertial><origin xyz="0.01 0 0.15"/><mass value="0.5"/>
<inertia ixx="0.006" ixy="0" ixz="0" iyy="0.006" iyz="0" izz="0.003"/></inertial></link>
<link name="slider"><inertial><origin xyz="0 0 0.05"/><mass value="0.3"/>
<inertia ixx="0.002" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.001"/></inertial></link>
<joint name="yaw" type="revolute"><parent link="base"/><child link="turret"/><origin xyz="0 0 0.1"/><axis xyz="0 0 1"/></joint>
<joint name="shoulder" type="revolute"><parent link="turret"/><child link="upper"/><origin xyz="0 0 0.1"/><axis xyz="0 1 0"/></joint>
<joint name="elbow" type="revolute"><parent link="upper"/><child link="fore"/><origin xyz="0 0 0.4"/><axis xyz="0 1 0"/></joint>
<joint name="extend" type="prismatic"><parent link="fore"/><child link="slider"/><origin xyz="0 0 0.3"/><axis xyz="0 0.6 0.8"/></joint>
</robot>"""

#: A hinge carrying two fingers on sliders, the second mimicking the first (the
#: ``slider_ratio`` primitive), tilted so that gravity moves both.
GRIPPER = """<?xml version="1.0"?>
<robot name="tab_gripper"><link name="base"/>
<link name="palm"><inertial><origin xyz="0.02 0 0.05" rpy="0.2 0 0"/><mass value="1.0"/>
<inertia ixx="0.01" ixy="0.001" ixz="0" iyy="0.012" iyz="0" izz="0.008"/></inertial></link>
<link name="left"><inertial><origin xyz="0 0.01 0.02"/><mass value="0.2"/>
<inertia ixx="0.0005" ixy="0" ixz="0" iyy="0.0004" iyz="0" izz="0.0003"/></inertial></link>
<link name="right"><inertial><origin xyz="0 -0.01 0.02"/><mass value="0.3"/>
<inertia ixx="0.0006" ixy="0" ixz="0" iyy="0.0005" iyz="0" izz="0.0004"/></inertial></link>
<joint name="wrist" type="revolute"><parent link="base"/><child link="palm"/><origin xyz="0 0 0.1"/><axis xyz="0.6 0 0.8"/></joint>
<joint name="finger" type="prismatic"><parent link="palm"/><child link="left"/><origin xyz="0 0.02 0.1"/><axis xyz="0 1 0"/></joint>
<joint name="finger_mimic" type="prismatic"><parent link="palm"/><child link="right"/><origin xyz="0 -0.02 0.1"/><axis xyz="0 -0.8 0.6"/>
<mimic joint="finger" multiplier="0.7"/></joint>
</robot>"""


def pushed_springs(n: int = 3, name: str = "tab_pushed_springs"):
    """A chain of ``n`` points hanging from the ground on spring-dampers, the last one pushed
    by the inputs ``push`` (3) and the middle one along a fixed direction by ``side``."""
    s = nc.System(name, gravity=(0.0, 0.0, -9.81))
    prev, pts = s.ground, []
    at = (0.0, 0.0, 0.0)
    for k in range(n):
        p = s.add_point(f"p{k}", mass=0.4 + 0.1 * k, position=(0.3 * (k + 1), 0.05 * k, -0.2 * (k + 1)),
                        velocity=(0.0, 0.3, 0.0))
        s.add_force(nc.Spring(prev, at, p, (0.0, 0.0, 0.0), k=60.0 + 10 * k, rest_length=0.3, damping=1.5))
        prev, at = p, (0.0, 0.0, 0.0)
        pts.append(p)
    push, side = s.add_input("push", 3), s.add_input("side")
    s.add_force(nc.PointForce(pts[-1], (0.0, 0.0, 0.0), force=push))
    s.add_force(nc.PointForce(pts[n // 2], (0.0, 0.0, 0.0), force=ca.vertcat(0.6 * side, -0.8 * side, 0)))
    return s.build()


def planar_arm():
    """A planar body and bar on two actuated hinges (efforts = the inputs ``tau``)."""
    s = nc.System("tab_planar_arm", gravity=(0.0, -9.81))
    tau = s.add_input("tau", 2)
    b1 = s.add_body("b1", coords="rrv", mass=1.0, inertia=0.05, position=(0.3, -0.1), rotation=0.2)
    b2 = s.add_bar("b2", coords="rr", mass=0.5, ends=[(0.6, -0.2), (1.0, -0.6)])
    s.add_joint(nc.Revolute(s.ground, b1, at=(0.0, 0.0), effort=tau[0]))
    s.add_joint(nc.Revolute(b1, b2, at=(0.6, -0.2), effort=tau[1]))
    return s.build()


def long_chain(n: int = 25):
    """``n`` bars sharing their ends in a staircase from a ground point (as
    benchmarks/common.py's chain): 3n coordinates, so that the step Jacobians' 6n columns are
    taken in several blocks of TAB_JAC_BLOCK (ncgen_table_jacobians.h) and the last one partial."""
    s = nc.System(f"tab_chain{n}", gravity=(0.0, 0.0, -9.81))
    start, at = s.ground.point((0.0, 0.0, 0.0)), np.zeros(3)
    for k in range(1, n + 1):
        at = at + (0.3 * (k % 2), 0.3 * (1 - k % 2), 0.0)
        start = s.add_bar(f"bar{k}", coords="rr", mass=0.2, ends=[start, tuple(at)]).end(1)
    return s.build()


def models():
    yield "chain", nc.System.from_toml(EXAMPLES / "chain.toml").build(), 0.01
    yield "long_chain", long_chain(), 1e-3
    yield "planar_arm", planar_arm(), 0.01
    yield "fourbar_3d", nc.System.from_toml(EXAMPLES / "fourbar_3d.toml").build(), 0.01
    yield "cartpole", nc.System.from_toml(EXAMPLES / "cartpole.toml").build(), 0.02
    yield "pushed_springs", pushed_springs(), 0.01
    pytest.importorskip("yourdfpy")
    yield "arm", nc.System.from_urdf(ARM, gravity=(0.0, 0.0, -9.81)).build(), 0.005
    yield "gripper", nc.System.from_urdf(GRIPPER, gravity=(0.0, 0.0, -9.81)).build(), 0.005


@pytest.fixture(scope="module")
def cases():
    return {name: (model, h) for name, model, h in models()}


def moving_state(model, st, seed=0):
    """A state on both constraint levels, moving: random rates projected, three steps with
    random inputs."""
    rng = np.random.default_rng(seed)
    v = nc.project_velocity(model, model.q0, rng.normal(size=model.nq)) if model.dof else model.v0
    x = np.concatenate([model.q0, v])
    for _ in range(3):
        x = st(x, rng.normal(size=model.nu))
    return x, rng.normal(size=model.nu)


def central(f, x, eps):
    cols = []
    for i in range(x.size):
        e = np.zeros_like(x)
        e[i] = eps * max(1.0, abs(x[i]))
        cols.append((f(x + e) - f(x - e)) / (2 * e[i]))
    return np.column_stack(cols)


def rel(a, b) -> float:
    return float(np.max(np.abs(a - b)) / max(1.0, np.max(np.abs(b)))) if b.size else 0.0


def check_against_differences(st, x, u, tag, u_eps=1e-5):
    """``u_eps``: the inputs' difference step (larger where light members make the step's
    Newton tolerance, divided by it, the larger error)."""
    x1, A, B = st.jacobians(x, u)
    assert np.array_equal(x1, st(x, u)), tag
    assert A.shape == (st.nx, st.nx) and B.shape == (st.nx, st.nu), tag
    assert rel(A, central(lambda y: st(y, u), x, 1e-6)) < FD, tag
    if st.nu:
        assert rel(B, central(lambda y: st(x, y), u, u_eps)) < FD, tag
    T1 = st.tangent_basis(x1)           # A maps into the tangent space at x⁺ (the exact derivative does)
    assert np.max(np.abs(T1 @ (T1.T @ A) - A)) < 1e-8 * max(1.0, np.max(np.abs(A))), tag
    return x1, A, B


#: The models whose flat step function is compiled in the fast tests (the others' in the slow ones).
FAST_FLAT = ("chain", "cartpole")


@pytest.mark.parametrize("name", ["chain", "long_chain", "fourbar_3d", "cartpole", "pushed_springs", "planar_arm",
                                  "arm", "gripper"])
def test_table_jacobians_equal_central_differences(cases, name):
    if name not in cases:
        pytest.skip("yourdfpy not installed")
    model, h = cases[name]
    st = nc.step_function(model, h)
    assert st.kernels == "tables" and "kernels='tables'" in repr(st)
    x, u = moving_state(model, st)
    check_against_differences(st, x, u, name)
    if name in FAST_FLAT:
        compare_with_flat(model, h, st, x, u)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["fourbar_3d", "pushed_springs", "planar_arm", "arm", "gripper"])
def test_table_jacobians_equal_the_flat_ones(cases, name):
    if name not in cases:
        pytest.skip("yourdfpy not installed")
    model, h = cases[name]
    st = nc.step_function(model, h)
    compare_with_flat(model, h, st, *moving_state(model, st))


def compare_with_flat(model, h, st, x, u):
    """The tables' step and Jacobians against the flat step function's: equal to FLAT."""
    flat = nc.step_function(model, h, kernels="flat")
    assert flat.kernels == "flat"
    x1, A, B = st.jacobians(x, u)
    x1f, Af, Bf = flat.jacobians(x, u)
    assert rel(x1, x1f) < FLAT and rel(A, Af) < FLAT and rel(B, Bf) < FLAT, (rel(x1, x1f), rel(A, Af), rel(B, Bf))


def test_parameters_and_rollouts(cases):
    """``parameters=True`` gives the same step and an empty ``C`` (a covered model has no
    parameters); rollouts run through the tables (nothing compiled); their gradients, which
    the tables do not provide, compile the flat package at first use and equal central
    differences of the tables' rollout."""
    model, h = cases["cartpole"]
    st = nc.step_function(model, h)
    x, u = moving_state(model, st)
    x1, A, B, C = st.jacobians(x, u, parameters=True)
    assert C.shape == (st.nx, 0) and st._flat is None
    x1t, At, Bt = st.jacobians(x, u)
    assert np.array_equal(x1t, x1) and np.array_equal(At, A) and np.array_equal(Bt, B)
    U = np.tile(u, (4, 1))
    X = st.rollout(x, U)
    assert st._flat is None and np.array_equal(X[0], x1t) and np.array_equal(X[1], st(X[0], u))
    W = np.random.default_rng(5).normal(size=X.shape)
    dx0, dU = st.rollout_gradient(x, U, W)
    assert st._flat is not None
    g = central(lambda y: np.array([np.sum(W * st.rollout(y, U))]), x, 1e-6).ravel()
    assert rel(dx0, g) < FD


def test_non_finite_arguments_are_named(cases):
    """float64 vectors of the right sizes pass to the C step as they are (their finiteness by
    one dot product); NaN or inf in x or u still ends in the argument check's error naming
    it, through the step and its Jacobians."""
    model, h = cases["cartpole"]
    st = nc.step_function(model, h)
    x, u = moving_state(model, st)
    for bad_x, bad_u, name in ((np.where(np.arange(x.size) == 3, np.nan, x), u, "x"),
                               (x, np.full(model.nu, np.inf), "u")):
        for call in (st, st.jacobians):
            with pytest.raises(NcgenError, match=rf"^{name}: expected {bad_x.size if name == 'x' else model.nu} "
                                                 r"finite number\(s\).*with NaN or inf"):
                call(bad_x, bad_u)


def test_auto_choice_override_and_refusal(cases):
    """"auto" takes the tables for a covered model and flat for one with a parameter;
    "tables" on that one names it; a bad value is refused; a step that cannot converge is
    refused naming its residual."""
    s = nc.System("tab_param_pendulum", gravity=(0.0, -9.81))
    s.add_parameter("m", 1.0)
    s.add_bar("bar", coords="rr", mass=1.0, ends=[s.ground.point((0.0, 0.0)), (0.6, -0.3)])
    s.add_force(nc.Spring(s.members["bar"], (0.3, 0.0), s.ground, (1.0, 0.0), k="m*10", rest_length=0.5))
    param = s.build()
    with pytest.raises(UnsupportedElements, match=r"parameter \(parameter 'm'\)"):
        nc.step_function(param, 0.01, kernels="tables")
    with pytest.raises(NcgenError, match="kernels: expected one of 'auto', 'tables', 'flat'"):
        nc.step_function(param, 0.01, kernels="fast")
    model, h = cases["cartpole"]
    assert nc.step_function(model, h, kernels="flat").kernels == "flat"
    x = np.concatenate([model.q0, model.v0])
    x[:model.nq] += 5.0                      # far off the constraints: one Newton iteration cannot reach them
    with pytest.raises(nc.StepDidNotConverge, match="residual"):
        nc.step_function(model, 0.02, max_iter=1)(x, 0.0)


@pytest.mark.slow      # a controlled model compiled flat and on the tables; fast:
#                       test_table_jacobians_equal_central_differences
def test_table_stepper_runs_a_controlled_model_as_the_flat_one(cases):
    """The table stepper with inputs (an input force, actuated joints) runs the same motion
    as the flat stepper under a time-varying input."""
    for name in ("cartpole", "arm"):
        if name not in cases:
            continue
        model, h = cases[name]
        u = (lambda t: [3.0 * np.sin(5 * t)]) if model.nu == 1 else (lambda t: 0.2 * np.cos(3 * t) * np.ones(model.nu))
        runs = {k: nc.simulate(model, 0.3, 0.01, method="stepper", kernels=k, u=u, check=False)
                for k in ("tables", "flat")}
        assert runs["tables"].info["kernels"] == "tables"
        a, b = runs["tables"], runs["flat"]
        assert np.max(np.abs(a.q - b.q)) < 1e-10 * (1 + np.max(np.abs(b.q))), name
        assert np.max(np.abs(a.energy - b.energy)) < 1e-8 * (1 + np.max(np.abs(b.energy))), name


CHILD = r"""
import json, shutil
import casadi as ca
import numpy as np
import ncgen as nc
import ncgen.codegen.compile_cache as cc
assert not any(shutil.which(c) for c in ("cc", "gcc", "clang")), "a compiler is on PATH"
def no_compile(*a, **k):
    raise AssertionError("the compiler was called")
cc.compile_package = no_compile
s = nc.System("nocc_pushed_chain")
start = s.ground.point((0.0, 0.0, 0.0))
pos = np.zeros(3)
bars = []
for k in range(6):
    pos = pos + np.array([0.27 + 0.01 * k, 0.11 * (k % 3), -0.05])
    bars.append(s.add_bar(f"link{k}", coords="rr", mass=0.3 + 0.02 * k, ends=[start, tuple(pos)]))
    start = bars[-1].end(1)
f = s.add_input("lift", 2)
s.add_force(nc.PointForce(bars[-1], (0.1, 0.0, 0.0), force=ca.vertcat(f[0], 0, f[1])))
model = s.build()
st = nc.step_function(model, 0.005)
rng = np.random.default_rng(1)
x = np.concatenate([model.q0, nc.project_velocity(model, model.q0, rng.normal(size=model.nq))])
uu = rng.normal(size=2)
x1, A, B = st.jacobians(x, uu)
def central(f, y, eps=1e-6):
    cols = []
    for i in range(y.size):
        e = np.zeros_like(y); e[i] = eps * max(1.0, abs(y[i]))
        cols.append((f(y + e) - f(y - e)) / (2 * e[i]))
    return np.column_stack(cols)
err_A = float(np.max(np.abs(A - central(lambda y: st(y, uu), x))) / np.max(np.abs(A)))
err_B = float(np.max(np.abs(B - central(lambda y: st(x, y), uu, 1e-5))) / np.max(np.abs(B)))
print(json.dumps({"kernels": st.kernels, "err_A": err_A, "err_B": err_B}))
"""


@pytest.mark.slow      # a subprocess without a compiler; fast:
#                       tests/test_tree_tables.py::test_a_new_tree_needs_no_compiler
def test_new_model_step_jacobians_with_no_compiler(tmp_path):
    """Once the element library is cached, a new chain pushed by inputs gets its step
    Jacobians in a process with no compiler on PATH (and compile_package replaced by a
    failure), equal to central differences."""
    from ncgen.runtime.table_library import load_element_library
    load_element_library()
    empty = tmp_path / "bin"
    empty.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("CC", "PATH")}
    env["PATH"] = str(empty)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    out = subprocess.run([sys.executable, "-c", CHILD], env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    r = json.loads(out.stdout.strip().splitlines()[-1])
    assert r["kernels"] == "tables" and r["err_A"] < FD and r["err_B"] < FD, r


@pytest.mark.slow
@pytest.mark.parametrize("robot", ["z1", "ur10"])
def test_robot_table_jacobians_equal_the_flat_ones_and_central_differences(robot):
    """The z1 and the UR10 from their URDFs: covered (actuated hinges), their step Jacobians
    from the tables equal the flat step function's and central differences; the table
    stepper's Newton takes a few iterations per step (its momentum test is relative to the
    mass matrix)."""
    pytest.importorskip("yourdfpy")
    try:
        urdf = nc.robots.urdf_path(robot)
    except nc.ModelError as exc:             # example-robot-data not installed
        pytest.skip(str(exc))
    model = nc.System.from_urdf(urdf).build()
    st = nc.step_function(model, 1e-3)
    assert st.kernels == "tables"
    rng = np.random.default_rng(3)
    x = np.concatenate([model.q0, nc.project_velocity(model, model.q0, 0.5 * rng.normal(size=model.nq))])
    iterations = []
    for _ in range(3):
        status, x, _, it, _, _ = st._table(x, rng.normal(size=model.nu), 0.0, False)
        assert status == 0
        iterations.append(it)
    assert max(iterations) <= 5, iterations
    u = rng.normal(size=model.nu)
    check_against_differences(st, x, u, robot)
    compare_with_flat(model, 1e-3, st, x, u)


@pytest.mark.slow
def test_stock_panda_table_jacobians_equal_central_differences():
    """The Panda with its finger ``<mimic>`` (two sliders in a fixed ratio): covered, its
    step Jacobians from the tables (no flat step: its generated C is too large to compile)
    against central differences, the inputs' at 1e-3 (the fingers' small masses)."""
    pytest.importorskip("yourdfpy")
    try:
        urdf = nc.robots.urdf_path("panda")
    except nc.ModelError as exc:             # example-robot-data not installed
        pytest.skip(str(exc))
    model = nc.System.from_urdf(urdf).build()
    assert any(j.kind == "Mimic" for j in model.joints)
    st = nc.step_function(model, 1e-3)
    assert st.kernels == "tables"
    x, u = moving_state(model, st, seed=4)
    check_against_differences(st, x, u, "panda", u_eps=1e-3)


def richardson(f, z, eps):
    """``(R, error)``: central differences of ``f`` at ``z`` (absolute steps) extrapolated by
    Richardson from the steps ``eps`` and ``eps / 2`` (the ``eps²`` term removed), and the
    reference's own error estimated as its distance to the extrapolation from ``eps / 2`` and
    ``eps / 4``."""
    def central_at(e):
        return np.column_stack([(f(z + d) - f(z - d)) / (2 * e) for d in np.eye(z.size) * e])

    D = [central_at(eps / 2 ** k) for k in range(3)]
    R1, R2 = (4 * D[1] - D[0]) / 3, (4 * D[2] - D[1]) / 3
    return R2, np.max(np.abs(R2 - R1))


@pytest.mark.slow
def test_talos_table_jacobians_equal_extrapolated_differences():
    """Talos (floating base, 32 actuated joints, 450 state entries): its step Jacobians from
    the tables equal Richardson-extrapolated central differences of the step to 1e-6 relative
    to max |J|, with the reference's own error estimate below 1e-7.  Central differences at one
    step carry two errors of opposite trends, which the 4.4e-6 of stop 47 was: the truncation ∝
    eps² (A's columns off the constraint manifold, corrected within one step, are strongly
    curved: 7.3e-6 at eps = 1e-5, 1.8e-6 at 5e-6, 4.6e-7 at 2.5e-6) and the step's round-off
    (≈ 4e-11 in x⁺, divided by eps: B's 2.8e-6 at 1e-5, 4e-5 at 1e-6).  Extrapolation removes the
    eps² term, so that each is taken where its round-off is small: A and B agree with it to
    6.5e-9 and 6.7e-9 (the estimates 8.7e-9 and 7.8e-9)."""
    pytest.importorskip("yourdfpy")
    try:
        urdf = nc.robots.urdf_path("talos_reduced")
    except nc.ModelError as exc:             # example-robot-data not installed
        pytest.skip(str(exc))
    model = nc.System.from_urdf(urdf, floating_base=True).build()
    st = nc.step_function(model, 1e-3)
    assert st.kernels == "tables"
    rng = np.random.default_rng(4)
    x = np.concatenate([model.q0, nc.project_velocity(model, model.q0, 0.5 * rng.normal(size=model.nq))])
    for _ in range(3):
        x = st(x, rng.normal(size=model.nu))
    u = rng.normal(size=model.nu)
    x1, A, B = st.jacobians(x, u)
    assert np.array_equal(x1, st(x, u))
    for name, J, f, z, eps in (("A", A, lambda y: st(y, u), x, 4e-6), ("B", B, lambda w: st(x, w), u, 2e-2)):
        R, error = richardson(f, z, eps)
        scale = max(1.0, np.max(np.abs(J)))
        assert error / scale < 1e-7, (name, error / scale)
        assert np.max(np.abs(J - R)) / scale < FD, (name, np.max(np.abs(J - R)) / scale, error / scale)


def test_stepper_tables_struct_matches_its_python_mirror():
    """The fields of ``ncgen_stepper_tables`` (templates/c/runtime/ncgen_table_stepper.h), in
    order, are those of ``STEPPER_FIELDS`` (ncgen/runtime/table_stepper.py) and then ``qr``,
    ``lu`` and ``ct``, those of ``struct ncgen_contact_tables`` the contact tables' sizes,
    ``gravity_norm`` and arrays (ncgen/codegen/contact_tables.py), and those of
    ``ncgen_lu_pattern`` (ncgen_sparse_lu.h) those of ``_LU_FIELDS``: ctypes lays the structs out
    from these lists, so a field added on one side only would shift every field after it."""
    import re

    from ncgen.codegen.contact_tables import INT_ARRAYS, REAL_ARRAYS, SIZES
    from ncgen.runtime.table_stepper import _LU_FIELDS, STEPPER_FIELDS

    def fields(header: str, pattern: str) -> list[str]:
        text = (ROOT / "templates" / "c" / "runtime" / header).read_text()
        body = re.sub(r"/\*.*?\*/", "", re.search(pattern, text, re.S).group(1), flags=re.S)
        return [re.split(r"[\s*]+", part.strip())[-1] for decl in filter(None, (d.strip() for d in body.split(";")))
                for part in decl.split(",")]

    def typedef(struct: str) -> str:
        return r"typedef struct \{(.*?)\} " + struct + ";"

    assert fields("ncgen_table_stepper.h", typedef("ncgen_stepper_tables")) == \
        [f for _, f in STEPPER_FIELDS] + ["qr", "lu", "ct"]
    assert fields("ncgen_table_stepper.h", r"struct ncgen_contact_tables \{(.*?)\};") == \
        [*SIZES, "gravity_norm", *INT_ARRAYS, *REAL_ARRAYS]
    assert fields("ncgen_sparse_lu.h", typedef("ncgen_lu_pattern")) == [f for _, f, _ in _LU_FIELDS]


def test_forces_without_table_jacobians_take_the_flat_path():
    """A force the step Jacobians of the tables have no derivatives for (here a constant
    Torque: the table stepper covers it) keeps "auto" on the flat step function and is named
    by "tables"; a constant PointForce (a constant load: no derivative) is covered, its
    Jacobians equal central differences."""
    from ncgen.control.step import _jacobian_uncovered

    s = nc.System("tab_const_twist", gravity=(0.0, -9.81))
    bar = s.add_bar("bar", coords="rr", mass=1.0, ends=[s.ground.point((0.0, 0.0)), (0.6, -0.3)])
    s.add_force(nc.Torque(bar, (0.4,), name="twist"))
    model = s.build()
    assert _jacobian_uncovered(model) == {"Torque (no step Jacobian from the tables)": ["force 'twist'"]}
    with pytest.raises(UnsupportedElements, match=r"Torque \(no step Jacobian from the tables\)"):
        nc.step_function(model, 0.01, kernels="tables")
    s = nc.System("tab_const_push", gravity=(0.0, -9.81))
    bar = s.add_bar("bar", coords="rr", mass=1.0, ends=[s.ground.point((0.0, 0.0)), (0.6, -0.3)])
    s.add_force(nc.PointForce(bar, (0.3, 0.0), force=(1.0, 0.0), name="push"))
    model = s.build()
    assert _jacobian_uncovered(model) == {}
    st = nc.step_function(model, 0.01, kernels="tables")
    x, u = moving_state(model, st)
    check_against_differences(st, x, u, "constant push")


def test_input_force_map_is_checked_once_per_model(monkeypatch):
    """``input_force_map``'s symbolic check runs once per force of a model, however many of
    ``uncovered_elements``, ``input_forces`` and the step Jacobians' coverage ask for it; the
    maps are the constant ``B`` of ``Q = B u`` (checked against ``F`` at two inputs)."""
    from ncgen.codegen import stepper_tables
    from ncgen.control.step import _jacobian_uncovered

    model = pushed_springs(name="tab_pushed_once")
    checked = []
    real = stepper_tables._input_force_map
    monkeypatch.setattr(stepper_tables, "_input_force_map", lambda m, f: checked.append(f.name) or real(m, f))
    stepper_tables.uncovered_elements(model)
    maps = stepper_tables.input_forces(model)
    assert _jacobian_uncovered(model) == {}
    stepper_tables.stepper_tables(model)
    assert sorted(checked) == sorted(f.name for f in model.forces if type(f) is nc.PointForce)
    B = sum(b for _, b in maps)
    F = model.functions["F"]
    u = np.array([0.3, -1.2, 0.7, 2.0])
    dF = np.asarray(F(0.0, model.q0, model.v0, u, [])).ravel() - np.asarray(F(0.0, model.q0, model.v0, 0 * u, [])).ravel()
    np.testing.assert_allclose(B @ u, dF, rtol=0, atol=1e-12)
    with pytest.raises(ValueError):
        maps[0][1][0, 0] = 1.0                       # the cached map is read-only
