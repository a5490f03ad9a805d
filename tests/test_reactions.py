"""Joint reactions and actuator efforts in SI units against closed forms (Newton–Euler).
Models are built with share=False: a reaction comes from its joint's multipliers (the
joints eliminated by sharing: tests/test_reactions_shared.py)."""
from __future__ import annotations

import numpy as np
import pytest

import ncgen as nc

G, L, MASS = 9.81, 1.2, 2.0


def bar_pendulum(drive=None):
    s = nc.System("pendulum", gravity=(0, -G))
    bar = s.add_bar("bar", mass=MASS, ends=[(0, 0), (L, 0)])
    s.add_joint(nc.Revolute(s.ground, bar, at=(0, 0), name="pivot", drive=drive))
    return s.build(share=False)


def test_pendulum_pivot_force():
    """f = m a_G − m g with a_G = (L/2)(θ̈ e_⊥ − ω² e); no moment about a hinge."""
    model = bar_pendulum()
    th, om = 0.4, 1.3
    q, v = model.from_joint_space([th], [om])
    a, lam = nc.forward_dynamics(model, q, v)
    r = nc.joint_reactions(model, q, lam)["pivot"]
    alpha = -G * L / 2 * np.cos(th) / (L**2 / 3)
    e, e_perp = np.array([np.cos(th), np.sin(th)]), np.array([-np.sin(th), np.cos(th)])
    a_G = L / 2 * (alpha * e_perp - om**2 * e)
    np.testing.assert_allclose(r.force, MASS * a_G - MASS * np.array([0, -G]), rtol=1e-12, atol=1e-12)
    assert abs(r.moment) < 1e-12
    np.testing.assert_allclose(r.point, [0, 0], atol=1e-15)
    assert r.member == "bar" and r.effort is None


def test_driven_crank_torque():
    """A bar turned at constant rate θ = 2t needs τ = m g (L/2) cos θ."""
    model = bar_pendulum(drive="2*t")
    for t in (0.1, 0.3, 1.2):
        q, v = model.from_joint_space([2 * t], [2.0], t=t)
        _, lam = nc.forward_dynamics(model, q, v, t=t)
        r = nc.joint_reactions(model, q, lam, t=t)["pivot"]
        assert abs(r.effort - MASS * G * L / 2 * np.cos(2 * t)) < 1e-10


def test_actuated_joint_reports_its_effort():
    s = nc.System("p", gravity=(0, -G))
    tau = s.add_input("tau")
    bar = s.add_bar("bar", mass=MASS, ends=[(0, 0), (L, 0)])
    s.add_joint(nc.Revolute(s.ground, bar, at=(0, 0), name="pivot", effort=tau))
    model = s.build(share=False)
    q, v = model.from_joint_space([0.2], [0.0])
    _, lam = nc.forward_dynamics(model, q, v, u=[3.5])
    r = nc.joint_reactions(model, q, lam, u=[3.5])["pivot"]
    assert r.effort == pytest.approx(3.5, abs=1e-15)


def test_3d_hinge_wrench_obeys_euler():
    """Body hinged about y at the origin: f = m a_G − m g and, about the fixed pivot,
    M_P + r_G × m g = I_P α + ω × I_P ω (world axes)."""
    s = nc.System("hinge3d")
    I_G = np.array([[0.05, 0.01, 0.0], [0.01, 0.08, 0.02], [0.0, 0.02, 0.06]])
    b = s.add_body("b", mass=MASS, inertia=I_G, position=(0.4, 0.1, -0.2))
    s.add_joint(nc.Revolute(s.ground, b, at=(0, 0, 0), axis=(0, 1, 0), name="hinge"))
    model = s.build(share=False)
    q, v = model.from_joint_space([0.7], [1.1])
    a, lam = nc.forward_dynamics(model, q, v)
    _, vj, aj = model.to_joint_space(q, v, a)
    r = nc.joint_reactions(model, q, lam)["hinge"]
    R, p = model.poses(q)
    R, rG = R[0], p[0]
    w, al = vj[0] * np.array([0, 1.0, 0]), aj[0] * np.array([0, 1.0, 0])
    a_G = np.cross(al, rG) + np.cross(w, np.cross(w, rG))
    g = np.array([0, 0, -9.81])
    np.testing.assert_allclose(r.force, MASS * a_G - MASS * g, atol=1e-11)
    I_P = R @ I_G @ R.T + MASS * (rG @ rG * np.eye(3) - np.outer(rG, rG))
    np.testing.assert_allclose(r.moment + np.cross(rG, MASS * g), I_P @ al + np.cross(w, I_P @ w), atol=1e-11)
    assert abs(r.moment[1]) < 1e-11                  # the hinge carries no moment about its axis


def test_unknown_joint():
    model = bar_pendulum()
    with pytest.raises(nc.ModelError, match="no joint named 'elbow'"):
        nc.joint_reactions(model, model.q0, model.lam0, joints=["elbow"])


def test_trajectory_reactions_follow_the_closed_form():
    """Along a simulated swing, the pivot force is m a_G − m g at every output step."""
    model = bar_pendulum()
    q0, v0 = model.from_joint_space([0.3], [0.0])
    traj = nc.simulate(model, 0.5, 0.1, q0=q0, v0=v0, rtol=1e-10, atol=1e-12)
    force, moment, effort = traj.reaction("pivot")
    th, om = traj.joint("pivot")
    alpha = -G * L / 2 * np.cos(th) / (L**2 / 3)
    e = np.column_stack([np.cos(th), np.sin(th)])
    e_perp = np.column_stack([-np.sin(th), np.cos(th)])
    a_G = L / 2 * (alpha[:, None] * e_perp - om[:, None] ** 2 * e)
    np.testing.assert_allclose(force, MASS * a_G - MASS * np.array([0, -G]), atol=1e-6)
    np.testing.assert_allclose(moment, 0, atol=1e-8)
    assert effort is None and force.shape == (len(traj), 2)


def test_a_joint_replaced_by_shared_coordinates_reports_its_reaction():
    """Sharing (the default) eliminates the pivot; its reaction still comes out: a bar
    released from rest horizontally has α = 3g/(2L), so the pivot carries m g / 4."""
    s = nc.System("hinge", gravity=(0, -G))
    bar = s.add_bar("bar", mass=MASS, ends=[(0, 0), (L, 0)])
    s.add_joint(nc.Revolute(s.ground, bar, at=(0, 0), name="pivot"))
    model = s.build()
    assert "pivot" in model.sharing.eliminated
    r = nc.joint_reactions(model, model.q0, model.lam0)["pivot"]
    np.testing.assert_allclose(r.force, [0, MASS * G / 4], atol=1e-12)
    assert r.member == "bar" and abs(r.moment) < 1e-12
