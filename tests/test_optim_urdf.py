"""Optimal control of a small URDF robot (3D, three hinges, written here) in the joint-space
form: the residual by recursive Newton–Euler against the projected natural-coordinate
dynamics, and a point-to-point motion whose optimal torques, replayed through the joint
forward dynamics (a KKT solve in natural coordinates, independent of the residual), reach
the target joint angles."""
from __future__ import annotations

import numpy as np
import pytest


import ncgen as nc  # noqa: E402
from ncgen.assembly.tree_dynamics import recursive_inverse_dynamics_function  # noqa: E402

G = 9.81


def link(name: str, mass: float, com: str, inertia: str) -> str:
    ixx, iyy, izz = inertia.split()
    return (f'<link name="{name}"><inertial><origin xyz="{com}" rpy="0.1 0 0.2"/><mass value="{mass}"/>'
            f'<inertia ixx="{ixx}" ixy="0.001" ixz="0" iyy="{iyy}" iyz="0" izz="{izz}"/></inertial></link>')


def joint(name: str, parent: str, child: str, xyz: str, axis: str) -> str:
    return (f'<joint name="{name}" type="revolute"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="{xyz}"/><axis xyz="{axis}"/><limit lower="-3" upper="3" effort="40" velocity="5"/></joint>')


ARM = f"""<?xml version="1.0"?>
<robot name="arm3"><link name="base"/>
{link("turret", 2.0, "0 0 0.05", "0.02 0.02 0.01")}
{link("upper", 1.0, "0 0 0.2", "0.015 0.015 0.004")}
{link("fore", 0.5, "0.01 0 0.15", "0.006 0.006 0.003")}
{joint("yaw", "base", "turret", "0 0 0.1", "0 0 1")}
{joint("shoulder", "turret", "upper", "0 0 0.1", "0 1 0")}
{joint("elbow", "upper", "fore", "0 0 0.4", "0 1 0")}
</robot>"""


@pytest.fixture(scope="module")
def arm():
    return nc.System.from_urdf(ARM, gravity=(0.0, 0.0, -G)).build()


def test_recursive_residual_vanishes_on_the_forward_dynamics(arm):
    """``r(q_j, v_j, a_j) = 0`` at the accelerations of the natural-coordinate KKT solve
    (``joint_forward_dynamics(backend="numpy")``), and is linear in ``a_j`` with the
    joint-space mass matrix as slope (≠ 0 off the dynamics)."""
    r = recursive_inverse_dynamics_function(arm)
    rng = np.random.default_rng(3)
    for _ in range(3):
        qj, vj, u = rng.uniform(-1.5, 1.5, 3), rng.normal(size=3), rng.normal(size=3) * 5
        a = nc.joint_forward_dynamics(arm, qj, vj, u, backend="numpy")
        res = np.array(r(0.0, qj, vj, a, u, arm.p0)).reshape(-1)
        assert np.max(np.abs(res)) < 1e-10
        off = np.array(r(0.0, qj, vj, a + [1.0, 0, 0], u, arm.p0)).reshape(-1)
        assert abs(off[0]) > 1e-3          # the yaw joint's inertia about z


@pytest.mark.slow      # robot scale; fast: test_recursive_residual_vanishes_on_the_forward_dynamics (the arm's residual the
#                         transcription uses) and tests/test_optim_cartpole.py (the transcription and the replay)
def test_point_to_point_reaches_the_joint_angles_and_replays(arm):
    from scipy.integrate import solve_ivp

    target = {"yaw": 0.8, "shoulder": 1.0, "elbow": -0.7}
    ocp = nc.OptimalControl(arm, N=12, t_final=1.0).minimize_effort()
    assert ocp.transcription.form == "joint"
    ocp.bound_input("tau", -30.0, 30.0).final(joints=target, v=0)
    res = ocp.solve()
    assert res.stats.success
    js = arm.joint_space
    names = list(js.joint_names)
    qj_end, vj_end = js.to_joint_space(arm, res.q[-1], res.v[-1])
    want = np.array([target[n] for n in names])
    assert np.max(np.abs(qj_end - want)) < 1e-7
    assert np.max(np.abs(vj_end)) < 1e-7
    assert np.max(np.abs(res.u)) <= 30.0 + 1e-6
    # replay the piecewise-constant torques through the forward dynamics
    h = res.t[1] - res.t[0]

    def rhs(t, x):
        k = min(int(t / h), ocp.N - 1)
        return np.concatenate([x[3:], nc.joint_forward_dynamics(arm, x[:3], x[3:], res.u[k], backend="numpy")])

    x0 = np.concatenate(js.to_joint_space(arm, res.q[0], res.v[0]))
    sol = solve_ivp(rhs, (0.0, res.t[-1]), x0, t_eval=res.t, rtol=1e-10, atol=1e-10, max_step=h / 4)
    nodes = np.array([js.to_joint_space(arm, q) for q in res.q])

    def gap(a, b):                                  # angle differences in (−π, π]
        return np.max(np.abs(np.angle(np.exp(1j * (np.asarray(a) - b)))))

    assert gap(sol.y.T[:, :3], nodes) < 5e-3       # Radau IIA(3), N = 12: discretisation error
    assert gap(sol.y.T[-1, :3], want) < 5e-3
    assert gap(sol.y.T[ocp.N // 2, :3], nodes[0]) > 0.5    # it did move
