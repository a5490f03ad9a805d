"""Exact derivatives of one RATTLE step (``nc.step_function``) against central finite
differences of the compiled step itself, on a chain, a closed loop, a robot tree and a model
with parameters, inputs and dampers; rollouts against repeated steps and against the
compiled stepper; the rollout adjoint against finite differences over 1000 steps; the
tangent parametrisation."""
from __future__ import annotations

from pathlib import Path

import casadi as ca
import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import NcgenError

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
REL = 1e-6


def spring_damper():
    """Bar pendulum tied to a point mass by a damped spring; the mass hangs from the ground on
    a damped spring of stiffness ``k`` (a parameter) and is pushed by the input ``push``."""
    s = nc.System("ctl_spring_damper", gravity=(0.0, 0.0, -9.81))
    bar = s.add_bar("bar", "rr", mass=1.0, ends=[s.ground.point((0.0, 0.0, 0.0)), (1.0, 0.0, 0.0)])
    mass = s.add_point("mass", mass=0.5, position=(1.0, 0.3, -0.5), velocity=(0.0, 0.5, 0.0))
    k = s.add_parameter("k", 40.0)
    push = s.add_input("push")
    s.add_force(nc.Spring(bar, (0.5, 0.0, 0.0), mass, (0.0, 0.0, 0.0), k=80.0, rest_length=0.4, damping=2.0))
    s.add_force(nc.Spring(s.ground, (1.0, 0.0, 0.5), mass, (0.0, 0.0, 0.0), k=k, rest_length=0.8, damping=1.5))
    s.add_force(nc.PointForce(mass, (0.0, 0.0, 0.0), force=ca.vertcat(0, push, 0)))
    return s.build()


ARM = """<?xml version="1.0"?>
<robot name="ctl_arm3"><link name="base"/>
<link name="turret"><inertial><origin xyz="0 0 0.05" rpy="0.1 0 0.2"/><mass value="2.0"/>
<inertia ixx="0.02" ixy="0.001" ixz="0" iyy="0.02" iyz="0" izz="0.01"/></inertial></link>
<link name="upper"><inertial><origin xyz="0 0 0.2"/><mass value="1.0"/>
<inertia ixx="0.015" ixy="0" ixz="0" iyy="0.015" iyz="0" izz="0.004"/></inertial></link>
<link name="fore"><inertial><origin xyz="0.01 0 0.15"/><mass value="0.5"/>
<inertia ixx="0.006" ixy="0" ixz="0" iyy="0.006" iyz="0" izz="0.003"/></inertial></link>
<joint name="yaw" type="revolute"><parent link="base"/><child link="turret"/><origin xyz="0 0 0.1"/><axis xyz="0 0 1"/></joint>
<joint name="shoulder" type="revolute"><parent link="turret"/><child link="upper"/><origin xyz="0 0 0.1"/><axis xyz="0 1 0"/></joint>
<joint name="elbow" type="revolute"><parent link="upper"/><child link="fore"/><origin xyz="0 0 0.4"/><axis xyz="0 1 0"/></joint>
</robot>"""


def models():
    yield "chain", nc.System.from_toml(EXAMPLES / "chain.toml").build(), 0.01
    yield "fourbar", nc.System.from_toml(EXAMPLES / "fourbar_planar.toml").build(), 0.01
    yield "cartpole", nc.System.from_toml(EXAMPLES / "cartpole.toml").build(), 0.02
    yield "spring_damper", spring_damper(), 0.01
    pytest.importorskip("yourdfpy")
    arm = nc.System.from_urdf(ARM, gravity=(0.0, 0.0, -9.81)).build()
    yield "arm", arm, 0.005


@pytest.fixture(scope="module")
def cases():
    return {name: (model, nc.step_function(model, h)) for name, model, h in models()}


def moving_state(model, st, seed=0):
    """A state on both constraint levels, moving: a few steps from the model's initial state
    with random inputs and, through one projection, random rates."""
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
    return np.column_stack(cols) if cols else np.zeros((0, 0))


def rel_err(J, J_fd):
    return np.max(np.abs(J - J_fd)) / max(np.max(np.abs(J_fd)), 1e-300)


@pytest.mark.parametrize("name", ["chain", "fourbar", "cartpole", "spring_damper", "arm"])
def test_step_jacobians_match_central_differences(cases, name):
    model, st = cases[name]
    x, u = moving_state(model, st)
    x1, A, B, C = st.jacobians(x, u, parameters=True)
    assert np.allclose(x1, st(x, u), rtol=0, atol=1e-14)
    A_fd = central(lambda y: st(y, u), x, 1e-5)
    assert rel_err(A, A_fd) < REL, name
    if model.nu:
        assert rel_err(B, central(lambda y: st(x, y), u, 1e-5)) < REL, name
    if model.np:
        assert rel_err(C, central(lambda y: st(x, u, p=y), model.p0.copy(), 1e-5)) < REL, name


def test_step_matches_the_compiled_stepper(cases):
    """Same scheme as ``nc.simulate(method="stepper", scheme="rattle")`` (independent code:
    its Newton loop is the template's C): 200 steps of the spring-damper with a held input."""
    model, st = cases["spring_damper"]
    traj = nc.simulate(model, 2.0, 0.01, method="stepper", u=lambda t: [0.3], check=False, scheme="rattle")
    x = np.concatenate([model.q0, model.v0])
    X = st.rollout(x, np.full((200, 1), 0.3))
    assert np.max(np.abs(X[-1, :model.nq] - traj.q[-1])) < 1e-9
    assert np.max(np.abs(X[-1, model.nq:] - traj.v[-1])) < 1e-8


def test_tangent_basis_and_reduced_jacobians(cases):
    """``T(x)`` spans the tangent space of both constraint levels, and ``A`` maps every
    perturbation (on the manifold or not) into the tangent space at ``x⁺``."""
    model, st = cases["fourbar"]
    x, u = moving_state(model, st, seed=2)
    T = st.tangent_basis(x)
    assert T.shape == (2 * model.nq, 2 * model.dof)
    assert np.allclose(T.T @ T, np.eye(2 * model.dof), atol=1e-12)
    J = np.array(st._J(x, model.p0, model.t0))
    assert np.max(np.abs(J @ T)) < 1e-10
    x1, A, B = st.jacobians(x, u)
    T1 = st.tangent_basis(x1)
    P1 = T1 @ T1.T
    assert np.max(np.abs(P1 @ A - A)) < 1e-8 * np.max(np.abs(A))
    _, A_T, B_T = st.reduced_jacobians(x, u)
    assert np.allclose(T1 @ A_T, A @ T, atol=1e-8)


@pytest.mark.slow      # 1000-step rollouts differenced; fast: test_step_jacobians_match_central_differences (the
#                       step's own Jacobians)
def test_rollout_gradient_matches_central_differences_over_1000_steps(cases):
    model, st = cases["spring_damper"]
    rng = np.random.default_rng(5)
    x0, _ = moving_state(model, st, seed=5)
    N = 1000
    U = 0.5 * np.sin(np.arange(N) * 0.01 * 3.0)[:, None]
    W = rng.normal(size=(N, st.nx))

    def J(x0_, U_):
        return float(np.sum(W * st.rollout(x0_, U_)))

    X = st.rollout(x0, U)
    assert np.allclose(X[0], st(x0, U[0]), atol=1e-14) and np.allclose(X[1], st(X[0], U[1]), atol=1e-13)
    dx0, dU, dp = st.rollout_gradient(x0, U, W, parameters=True)
    g_x0 = central(lambda y: np.array([J(y, U)]), x0, 1e-6).ravel()
    assert rel_err(dx0, g_x0) < REL
    picks = rng.choice(N, 12, replace=False).tolist() + [0, N - 1]
    eps = 1e-5
    for k in picks:
        Up, Um = U.copy(), U.copy()
        Up[k] += eps
        Um[k] -= eps
        fd = (J(x0, Up) - J(x0, Um)) / (2 * eps)
        assert abs(dU[k, 0] - fd) < REL * np.max(np.abs(dU)), k
    fd_p = (float(np.sum(W * st.rollout(x0, U, p=[40.0 + 1e-4])))
            - float(np.sum(W * st.rollout(x0, U, p=[40.0 - 1e-4])))) / 2e-4
    assert abs(dp[0] - fd_p) < REL * max(abs(fd_p), 1.0)


def test_bad_arguments_are_named(cases):
    model, st = cases["cartpole"]
    with pytest.raises(NcgenError, match=r"x: expected 16"):
        st(np.zeros(3), 0.0)
    with pytest.raises(NcgenError, match=r"u: expected 1 .*NaN"):
        st(np.concatenate([model.q0, model.v0]), np.nan)
    with pytest.raises(NcgenError, match=r"U: expected finite inputs of shape \(N, 1\)"):
        st.rollout(np.concatenate([model.q0, model.v0]), np.zeros((4, 2)))
    with pytest.raises(NcgenError, match=r"h: expected a positive, finite step"):
        nc.step_function(model, -1.0)
    with pytest.raises(NcgenError, match=r"method: expected one of rattle"):
        nc.step_function(model, 0.01, method="euler")


def test_a_step_that_cannot_converge_is_refused(cases):
    model, st = cases["cartpole"]
    x = np.concatenate([model.q0, model.v0])
    x[:model.nq] += 5.0                      # far off the constraints: one Newton solve cannot reach them
    with pytest.raises(nc.StepDidNotConverge, match="residual"):
        nc.step_function(model, 0.02, max_iter=1)(x, 0.0)


@pytest.mark.parametrize("name", ["spring_damper", "arm"])
def test_step_sensitivities_match_central_differences_of_the_residual(name):
    """``G_z`` and ``G_y = ∂G/∂[x; u; p]``, the matrices of the step's Jacobians, against central
    differences of the residual ``G`` itself, at a random point off the solution: the
    spring-damper has dampers (``F`` depends on ``w``) and a parameter, the arm's joint torques
    depend on ``q``."""
    from ncgen.control.discrete import step_functions, step_residual

    model, h = next((m, h) for n, m, h in models() if n == name)
    fs, G = step_functions(model, h), step_residual(model, h)
    nq, nu = model.nq, model.nu
    rng = np.random.default_rng(7)
    z = rng.normal(size=2 * (nq + model.nc))
    y = np.concatenate([model.q0 + 0.01 * rng.normal(size=nq), rng.normal(size=nq), rng.normal(size=nu), model.p0])
    t = model.t0 + 0.1

    def residual(z_, y_):
        return np.array(G(z_, y_[:2 * nq], y_[2 * nq:2 * nq + nu], y_[2 * nq + nu:], t)).ravel()

    args = (z, y[:2 * nq], y[2 * nq:2 * nq + nu], y[2 * nq + nu:], t)
    G_z = np.array(ca.densify(fs["step_G_z"](*args)))
    G_y = np.array(ca.densify(fs["step_G_y"](*args)))
    assert rel_err(G_z, central(lambda z_: residual(z_, y), z, 1e-6)) < REL, name
    assert rel_err(G_y, central(lambda y_: residual(z, y_), y, 1e-6)) < REL, name
