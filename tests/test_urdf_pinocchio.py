"""URDF robots of example-robot-data against Pinocchio (an independent rigid-body engine).

For two fixed-base arms (Panda, UR5) and a floating-base quadruped (Solo12), at 20 random
states each: joint accelerations from ``forward_dynamics`` + ``to_joint_space`` vs
``pinocchio.aba``, efforts from ``inverse_dynamics`` vs ``pinocchio.rnea`` (1e-8 relative),
and every link frame vs ``pinocchio.framesForwardKinematics`` (1e-10).  Then a UR5 falling
under gravity with zero torque for 1 s: IDAS on the natural coordinates vs Pinocchio's ABA
integrated by scipy at tight tolerance.

example-robot-data (PyPI) ships no Python module: its URDFs are package data under
``cmeel.prefix/share/example-robot-data/robots``, found through the distribution's file list.
Pinocchio parses the URDF without ``<mimic>`` (the Panda's second finger mimics the first:
we drop the tag for both engines; the mimic equation itself is tested in test_joint_space).
"""
from __future__ import annotations

import importlib.metadata as md
import re
from functools import cache
from pathlib import Path

import numpy as np
import pytest

pin = pytest.importorskip("pinocchio")

import ncgen as nc  # noqa: E402
from pinocchio_robots import random_configuration  # noqa: E402

ROBOTS = {
    "panda": ("panda_description/urdf/panda.urdf", False),
    "ur5": ("ur_description/urdf/ur5_robot.urdf", False),
    "solo12": ("solo_description/robots/solo12.urdf", True),
    # its base link is a placeholder of non-physical inertia (1e-6 in every entry) welded to the trunk
    "go1": ("go1_description/urdf/go1.urdf", True),
}
N_STATES = 20
#: Robots of the fast tier: the UR5 (a fixed-base arm) and Solo12 (a floating base); the Panda and Go1
#: take the same code paths at robot scale (their builds and kernels' compiles) in the slow tier.
FAST_ROBOTS = ("ur5", "solo12")


def robots(names, fast=FAST_ROBOTS):
    """``names`` as parameters, those not in ``fast`` marked slow."""
    return [n if n in fast else pytest.param(n, marks=pytest.mark.slow) for n in names]


def robot_file(rel: str) -> Path:
    try:
        files = md.files("example-robot-data") or []
    except md.PackageNotFoundError:
        pytest.skip("example-robot-data is not installed")
    for f in files:
        if str(f).endswith(rel):
            return Path(f.locate())
    pytest.skip(f"example-robot-data has no {rel}")


@cache
def robot(name: str, share: bool = True):
    """``(ncgen model, Pinocchio model)``; ``share=False`` keeps every joint's equations (and
    multipliers, which the joint reactions need)."""
    rel, floating = ROBOTS[name]
    text = re.sub(r"<mimic[^>]*/>", "", robot_file(rel).read_text())
    model = nc.System.from_urdf(text, floating_base=floating).build(share=share)
    pm = pin.buildModelFromXML(text, pin.JointModelFreeFlyer()) if floating else pin.buildModelFromXML(text)
    return model, pm


def ident(s: str) -> str:
    return re.sub(r"\W", "_", s)


def pin_joints(model, pm):
    """(ncgen joint name, Pinocchio joint model) pairs."""
    out = []
    for jid in range(1, pm.njoints):
        n = ident(pm.names[jid])
        out.append(("root" if pm.joints[jid].shortname() == "JointModelFreeFlyer" else n, pm.joints[jid]))
    assert sorted(n for n, _ in out) == sorted(model.joint_names)
    return out


def to_ncgen(model, pm, qp, vp):
    js = model.joint_space
    sq, sv = js.slices(), js.slices(rates=True)
    qj, vj = np.zeros(js.nq), np.zeros(js.nv)
    for n, jm in pin_joints(model, pm):
        qj[sq[n]] = qp[jm.idx_q:jm.idx_q + jm.nq]
        vj[sv[n]] = vp[jm.idx_v:jm.idx_v + jm.nv]
    return qj, vj


def rates_to_pin(model, pm, xj):
    sv = model.joint_space.slices(rates=True)
    out = np.zeros(pm.nv)
    for n, jm in pin_joints(model, pm):
        out[jm.idx_v:jm.idx_v + jm.nv] = xj[sv[n]]
    return out


def states(pm, seed):
    rng = np.random.default_rng(seed)                     # the states depend on ``seed`` alone
    for _ in range(N_STATES):
        qp = random_configuration(pm, rng)
        yield qp, rng.normal(size=pm.nv), 5 * rng.normal(size=pm.nv), rng.normal(size=pm.nv)


@pytest.mark.parametrize("name", robots(ROBOTS))
def test_dynamics_and_kinematics_match_pinocchio(name):
    model, pm = robot(name)
    pd = pm.createData()
    floating = ROBOTS[name][1]
    if floating:
        assert model.joint_names[0] == "root"
    actuated = [n for n in model.joint_names if n != "root"]
    assert model.actuated_joints == actuated
    frames = [f for f in pm.frames if f.type == pin.FrameType.BODY]
    assert {ident(f.name) for f in frames} <= set(model.frames)
    for qp, vp, taup, ap in states(pm, seed=len(name)):
        if floating:
            taup[:6] = 0.0                                  # the base is not actuated
        qj, vj = to_ncgen(model, pm, qp, vp)
        q, v = model.from_joint_space(qj, vj)
        assert np.max(np.abs(model.phi(q))) < 1e-12
        # the round trip is exact
        qj2, vj2 = model.to_joint_space(q, v)
        np.testing.assert_allclose(qj2, qj, atol=1e-12)
        np.testing.assert_allclose(vj2, vj, atol=1e-12)
        # forward dynamics vs ABA
        order = {n: k for k, n in enumerate(model.joint_names)}
        pairs = sorted(((n, jm) for n, jm in pin_joints(model, pm) if n != "root"), key=lambda x: order[x[0]])
        tau_nc = np.concatenate([taup[jm.idx_v:jm.idx_v + jm.nv] for _, jm in pairs])
        a, _ = nc.forward_dynamics(model, q, v, u=tau_nc)
        _, _, aj = model.to_joint_space(q, v, a)
        a_pin = pin.aba(pm, pd, qp, vp, taup)
        scale = max(1.0, np.max(np.abs(a_pin)))
        assert np.max(np.abs(rates_to_pin(model, pm, aj) - a_pin)) <= 1e-8 * scale
        # inverse dynamics vs RNEA (every joint's effort, a floating base's wrench included)
        aj_given = to_ncgen(model, pm, qp, ap)[1]
        tau_all = nc.inverse_dynamics(model, qj, vj, aj_given, joints="all")
        tau_pin = pin.rnea(pm, pd, qp, vp, ap)
        scale = max(1.0, np.max(np.abs(tau_pin)))
        assert np.max(np.abs(rates_to_pin(model, pm, tau_all) - tau_pin)) <= 1e-8 * scale
        if not floating:            # every joint actuated: the actuated efforts are the same
            tau_act = nc.inverse_dynamics(model, qj, vj, aj_given)
            np.testing.assert_allclose(tau_act, tau_all, rtol=0, atol=1e-8 * scale)
        # every link frame vs framesForwardKinematics
        pin.framesForwardKinematics(pm, pd, qp)
        for f in frames:
            R, pos = model.frame_pose(ident(f.name), q)
            oMf = pd.oMf[pm.getFrameId(f.name)]
            assert np.max(np.abs(R - oMf.rotation)) < 1e-10, f.name
            assert np.max(np.abs(pos - oMf.translation)) < 1e-10, f.name


def test_floating_base_root_convention():
    """The root joint is Pinocchio's free flyer: position and quaternion [x, y, z, qx, qy, qz,
    qw] of the base frame, rates [v, ω] in base axes."""
    model, pm = robot("solo12")
    js = model.joint_space
    assert js.position_names[:7] == [f"root.{k}" for k in ("x", "y", "z", "qx", "qy", "qz", "qw")]
    assert js.rate_names[:6] == [f"root.{k}" for k in ("vx", "vy", "vz", "wx", "wy", "wz")]
    qj0 = model.to_joint_space(model.q0)
    np.testing.assert_allclose(qj0[:7], [0, 0, 0, 0, 0, 0, 1], atol=1e-15)


def test_ur5_falls_like_pinocchio():
    """Zero torque, gravity, 1 s: IDAS (natural coordinates) vs scipy on Pinocchio's ABA."""
    from scipy.integrate import solve_ivp

    model, pm = robot("ur5")
    pd = pm.createData()
    qp0 = np.array([0.0, -1.0, 0.8, -0.5, 1.2, 0.3])
    vp0 = np.array([0.5, 0.0, -0.3, 0.2, 0.0, 0.1])
    sol = solve_ivp(lambda t, x: np.concatenate([x[6:], pin.aba(pm, pd, x[:6], x[6:], np.zeros(6))]),
                    (0.0, 1.0), np.concatenate([qp0, vp0]), method="DOP853", rtol=1e-12, atol=1e-12)
    qj0, vj0 = to_ncgen(model, pm, qp0, vp0)
    q0, v0 = model.from_joint_space(qj0, vj0)
    traj = nc.simulate(model, 1.0, 0.5, q0=q0, v0=v0, rtol=1e-10, atol=1e-12)
    qj1, vj1 = model.to_joint_space(traj.q[-1], traj.v[-1])
    ref_q, ref_v = to_ncgen(model, pm, sol.y[:6, -1], sol.y[6:, -1])
    dq = (qj1 - ref_q + np.pi) % (2 * np.pi) - np.pi            # joint angles in (−π, π]
    assert np.max(np.abs(dq)) < 1e-6
    assert np.max(np.abs(vj1 - ref_v)) < 1e-5
    # and the motion is not trivial
    assert np.max(np.abs(ref_q - qj0)) > 0.1


@pytest.mark.parametrize("share", [False, True])
@pytest.mark.parametrize("name", robots(["ur5", "panda"]))
def test_joint_reactions_match_pinocchio_joint_forces(name, share):
    """Under the torques of RNEA, each joint's reaction wrench on its child (world axes, about
    the joint origin) plus the actuator torque about the axis is Pinocchio's ``data.f``
    (the spatial force the parent exerts on the child, in joint axes).  With sharing (the
    default build) the hinges are shared points and axes, and their reactions come from the
    model's unshared form."""
    model, pm = robot(name, share=share)
    if share:
        assert model.sharing.eliminated
    pd = pm.createData()
    order = {n: k for k, n in enumerate(model.joint_names)}
    pairs = sorted(pin_joints(model, pm), key=lambda x: order[x[0]])
    for k, (qp, vp, _, ap) in enumerate(states(pm, seed=7)):
        if k == 3:
            break
        tau = pin.rnea(pm, pd, qp, vp, ap)
        forces = [f.copy() for f in pd.f]
        pin.forwardKinematics(pm, pd, qp)
        pin.computeJointJacobians(pm, pd, qp)
        qj, vj = to_ncgen(model, pm, qp, vp)
        q, v = model.from_joint_space(qj, vj)
        u = np.concatenate([tau[jm.idx_v:jm.idx_v + jm.nv] for _, jm in pairs])
        _, lam = nc.forward_dynamics(model, q, v, u=u)
        reactions = nc.joint_reactions(model, q, lam, u=u)
        for jid in range(1, pm.njoints):
            r = reactions[ident(pm.names[jid])]
            R = pd.oMi[jid].rotation
            S = np.asarray(pd.joints[jid].S).reshape(-1)           # motion subspace [v; ω]
            scale = max(1.0, np.max(np.abs(forces[jid].vector)))
            np.testing.assert_allclose(r.point, pd.oMi[jid].translation, atol=1e-12)
            assert np.max(np.abs(r.force + r.effort * (R @ S[:3]) - R @ forces[jid].linear)) < 1e-9 * scale
            assert np.max(np.abs(r.moment + r.effort * (R @ S[3:]) - R @ forces[jid].angular)) < 1e-9 * scale


@pytest.mark.parametrize("name", robots(["panda", "solo12"]))
def test_joint_space_kernel_matches_aba(name):
    """The one-function joint-space forward dynamics (tree map + Schur solve + a_j), as
    compiled by ``forward_dynamics_kernel(joint_space=True)``, evaluated here by CasADi."""
    from ncgen.assembly.derived import joint_kkt_function

    model, pm = robot(name)
    pd = pm.createData()
    f = joint_kkt_function(model)
    order = {n: k for k, n in enumerate(model.joint_names)}
    pairs = sorted(((n, jm) for n, jm in pin_joints(model, pm) if n != "root"), key=lambda x: order[x[0]])
    for k, (qp, vp, taup, _) in enumerate(states(pm, seed=11)):
        if k == 3:
            break
        if name == "solo12":
            taup[:6] = 0.0
        qj, vj = to_ncgen(model, pm, qp, vp)
        u = np.concatenate([taup[jm.idx_v:jm.idx_v + jm.nv] for _, jm in pairs])
        aj = np.array(f(0.0, qj, vj, u, model.p0)[0]).reshape(-1)
        a_pin = pin.aba(pm, pd, qp, vp, taup)
        assert np.max(np.abs(rates_to_pin(model, pm, aj) - a_pin)) <= 1e-8 * max(1.0, np.max(np.abs(a_pin)))


@pytest.mark.parametrize("name", robots(ROBOTS, fast=("ur5",)))   # a floating base's kernel: joint_space_kernel
def test_joint_forward_dynamics_kernel_matches_aba(name):
    """The joint-space tree kernel (recursive form), at 20 random states: compiled and
    called directly for the Panda (``nc.joint_forward_dynamics_kernel``), its CasADi function
    evaluated for UR5 and Solo12 (the same expressions; compiling them would add seconds)."""
    from ncgen.assembly.tree_dynamics import recursive_dynamics_function

    model, pm = robot(name)
    pd = pm.createData()
    if name == "panda":
        k = nc.joint_forward_dynamics_kernel(model)
        assert k.method == "recursive"
    else:
        f = recursive_dynamics_function(model)

        def k(qj, vj, u):
            return np.array(f(model.t0, qj, vj, u, model.p0)[0]).reshape(-1)
    order = {n: i for i, n in enumerate(model.joint_names)}
    pairs = sorted(((n, jm) for n, jm in pin_joints(model, pm) if n != "root"), key=lambda x: order[x[0]])
    for qp, vp, taup, _ in states(pm, seed=23):
        if ROBOTS[name][1]:
            taup[:6] = 0.0
        qj, vj = to_ncgen(model, pm, qp, vp)
        u = np.concatenate([taup[jm.idx_v:jm.idx_v + jm.nv] for _, jm in pairs])
        a_pin = pin.aba(pm, pd, qp, vp, taup)
        assert np.max(np.abs(rates_to_pin(model, pm, k(qj, vj, u)) - a_pin)) <= 1e-8 * max(1.0, np.max(np.abs(a_pin)))
