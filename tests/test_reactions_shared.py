"""Reactions of joints eliminated by coordinate sharing (build(share=True), the default):
against closed forms (pendulum pivot along a swing, double-pendulum elbow from Lagrange's
equations, a weld's transmitted wrench from statics and from Newton–Euler) and against the
same systems built with share=False, whose multipliers are their own (four-bar, a robot arm
of bodies, a chain of bars with Spherical joints).  The share=False states are made from the
members' poses and twists, not from the map the reactions use."""
import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import ModelError

G = 9.81


# ----------------------------------------------------------------------------- builders
def bar_pendulum_3d(L=1.3, m=2.0):
    """A uniform bar on a Spherical joint at the origin, released horizontally along x."""
    s = nc.System("spherical_pendulum")
    bar = s.add_bar("bar", mass=m, ends=[(0, 0, 0), (L, 0, 0)])
    s.add_joint(nc.Spherical(s.ground, bar, at=(0, 0, 0), name="pivot"))
    return s


def double_pendulum(l1=1.0, l2=0.7, m1=1.5, m2=0.9):
    s = nc.System("double_pendulum", gravity=(0, -G))
    b1 = s.add_bar("upper", mass=m1, ends=[(0, 0), (l1, 0)])
    b2 = s.add_bar("lower", mass=m2, ends=[(l1, 0), (l1 + l2, 0)])
    s.add_joint(nc.Revolute(s.ground, b1, at=(0, 0), name="shoulder"))
    s.add_joint(nc.Revolute(b1, b2, at=(l1, 0), name="elbow"))
    return s


def fourbar():
    """Planar crank-rocker with four explicit Revolute joints; the coupler is a body."""
    s = nc.System("fourbar", gravity=(0, -G))
    B = np.array([0.5, 0.8660254037844386])
    C = np.array([3.0428529212959905, 2.4578479506333157])
    D = np.array([3.5, 0.0])
    crank = s.add_bar("crank", mass=0.5, ends=[(0, 0), B])
    coupler = s.add_body("coupler", coords="rrv", mass=1.5, inertia=0.4, position=(B + C) / 2 + [0, 0.1])
    rocker = s.add_bar("rocker", mass=1.2, ends=[C, D])
    s.add_joint(nc.Revolute(s.ground, crank, at=(0, 0), name="O"))
    s.add_joint(nc.Revolute(crank, coupler, at=B, name="B"))
    s.add_joint(nc.Revolute(coupler, rocker, at=C, name="C"))
    s.add_joint(nc.Revolute(rocker, s.ground, at=D, name="D"))
    return s


def robot():
    """3D arm of bodies: yaw, shoulder and elbow hinges, a tool welded to the last link."""
    s = nc.System("robot")
    I = np.array([[0.02, 0.002, 0.0], [0.002, 0.03, 0.001], [0.0, 0.001, 0.04]])
    w = np.array([0, 0, 1.0])
    base = s.add_body("base", mass=2.0, inertia=I, position=(0, 0, 0.1), angular_velocity=w)
    l1 = s.add_body("link1", mass=1.0, inertia=I, position=(0.25, 0.02, 0.2), angular_velocity=w,
                    velocity=np.cross(w, [0.25, 0.02, 0.2]))
    l2 = s.add_body("link2", mass=0.8, inertia=I, position=(0.75, 0, 0.25), angular_velocity=w,
                    velocity=np.cross(w, [0.75, 0, 0.25]))
    tool = s.add_body("tool", mass=0.3, inertia=0.5 * I, position=(1.05, 0.05, 0.2), angular_velocity=w,
                      velocity=np.cross(w, [1.05, 0.05, 0.2]))
    s.add_joint(nc.Revolute(s.ground, base, at=(0, 0, 0), axis=(0, 0, 1), name="yaw"))
    s.add_joint(nc.Revolute(base, l1, at=(0, 0, 0.2), axis=(0, 1, 0), name="shoulder"))
    s.add_joint(nc.Revolute(l1, l2, at=(0.5, 0, 0.2), axis=(0, 0.6, 0.8), name="elbow"))
    s.add_joint(nc.Fixed(l2, tool, at=(1.0, 0, 0.2), name="flange"))
    return s


def bar_chain(n=4):
    s = nc.System("chain")
    prev = s.ground
    pts = [np.array([k, 0.1 * k * k, 0.0]) for k in range(n + 1)]
    for k in range(n):
        bar = s.add_bar(f"b{k}", mass=1.0, ends=[pts[k], pts[k + 1]])
        s.add_joint(nc.Spherical(prev, bar, at=pts[k], name=f"ball{k}"))
        prev = bar
    return s


# ----------------------------------------------------------------------------- helpers
def member_q(model, name, x, constants=True):
    idx = model.layout.member_indices(name)
    const = model.layout.member_constant(name) if constants else np.zeros(len(idx))
    return np.array([x[i] if i is not None else c for i, c in zip(idx, const)])


def explicit_state(shared, explicit, q, v):
    """The same state in the share=False model, from every member's pose and twist."""
    qu, vu = np.full(explicit.nq, np.nan), np.full(explicit.nq, np.nan)
    for name in shared.member_names:
        ms, mu = shared.members[name], explicit.members[name]
        qm, vm = member_q(shared, name, q), member_q(shared, name, v, constants=False)
        R, p = ms.rigid.pose(qm)
        w, vc = ms.rigid.twist(qm, vm)
        for x, val in ((qu, mu.rigid.q_from_pose(R, p)), (vu, mu.rigid.qd_from_twist(R, p, w, vc))):
            for i, y in zip(explicit.layout.member_indices(name), val):
                if i is not None:
                    x[i] = y
    assert not np.isnan(qu).any() and not np.isnan(vu).any()
    return qu, vu


def close(a, b, tol):
    a, b = np.atleast_1d(a), np.atleast_1d(b)
    np.testing.assert_allclose(a, b, rtol=0, atol=tol * max(1.0, np.abs(b).max()))


# ----------------------------------------------------------------------------- closed forms
def test_spherical_pivot_force_along_a_swing():
    """Uniform bar (m, L) released from rest horizontally about a ball joint: with θ below the
    horizontal, energy gives ω² = 3 g sinθ / L and the moment α = 3 g cosθ / (2L), so the
    pivot force is f = m a_G − m g with a_G = (L/2)(α t − ω² e)."""
    L, m = 1.3, 2.0
    model = bar_pendulum_3d(L, m).build()
    assert "pivot" in model.sharing.eliminated and model.nc == 1        # only the bar's length
    traj = nc.simulate(model, 0.8, 0.02, rtol=1e-11, atol=1e-11)
    force, moment, effort = traj.reaction("pivot")
    assert effort is None
    tip = traj.point("bar", (L / 2, 0, 0))
    th = np.arctan2(-tip[:, 2], tip[:, 0])
    assert th.max() > 1.2                                              # it swings past 70°
    w2, al = 3 * G * np.sin(th) / L, 3 * G * np.cos(th) / (2 * L)
    e = np.stack([np.cos(th), 0 * th, -np.sin(th)], 1)
    t = np.stack([-np.sin(th), 0 * th, -np.cos(th)], 1)                # de/dθ, direction of increasing θ
    a_G = (L / 2) * (al[:, None] * t - w2[:, None] * e)
    np.testing.assert_allclose(force, m * a_G - m * np.array([0, 0, -G]), rtol=0, atol=1e-6 * m * G)
    np.testing.assert_allclose(moment, 0, atol=1e-9)                   # a ball joint carries no moment
    radial = np.einsum("ij,ij->i", force, -e)                          # towards the pivot
    np.testing.assert_allclose(radial, m * (w2 * L / 2 + G * np.sin(th)), atol=1e-6 * m * G)


def test_double_pendulum_elbow_reaction_from_lagrange():
    """Elbow force on the lower bar, f = m₂ a_G2 − m₂ g, with the accelerations of Lagrange's
    equations of two uniform bars in absolute angles φ₁, φ₂."""
    l1, l2, m1, m2 = 1.0, 0.7, 1.5, 0.9
    model = double_pendulum(l1, l2, m1, m2).build()
    assert set(model.sharing.eliminated) == {"shoulder", "elbow"}
    rng = np.random.default_rng(3)
    for _ in range(5):
        th, om = rng.uniform(-2, 2, 2), rng.uniform(-3, 3, 2)
        q, v = model.from_joint_space(th, om)
        R, _ = model.poses(q)
        phi = [np.arctan2(R[k][1, 0], R[k][0, 0]) for k in range(2)]
        np.testing.assert_allclose(np.unwrap(phi), np.unwrap([th[0], th[0] + th[1]]), atol=1e-12)
        f1, f2 = om[0], om[0] + om[1]
        c, s = m2 * l1 * l2 / 2 * np.cos(phi[0] - phi[1]), m2 * l1 * l2 / 2 * np.sin(phi[0] - phi[1])
        Mq = np.array([[m1 * l1**2 / 3 + m2 * l1**2, c], [c, m2 * l2**2 / 3]])
        rhs = np.array([-G * np.cos(phi[0]) * (m1 * l1 / 2 + m2 * l1) - s * f2**2,
                        -G * m2 * l2 / 2 * np.cos(phi[1]) + s * f1**2])
        a1, a2 = np.linalg.solve(Mq, rhs)
        e = [np.array([np.cos(x), np.sin(x)]) for x in phi]
        n = [np.array([-np.sin(x), np.cos(x)]) for x in phi]
        a_G2 = l1 * (a1 * n[0] - f1**2 * e[0]) + l2 / 2 * (a2 * n[1] - f2**2 * e[1])
        _, lam = nc.forward_dynamics(model, q, v)
        r = nc.joint_reactions(model, q, lam, v=v)
        assert set(r) == {"shoulder", "elbow"} and r["elbow"].member == "lower"
        close(r["elbow"].force, m2 * a_G2 - m2 * np.array([0, -G]), 1e-10)
        assert abs(r["elbow"].moment) < 1e-10
        close(r["elbow"].point, l1 * e[0], 1e-12)
        a_G1 = l1 / 2 * (a1 * n[0] - f1**2 * e[0])                    # the shoulder carries both bars
        close(r["shoulder"].force, m1 * a_G1 + m2 * a_G2 - (m1 + m2) * np.array([0, -G]), 1e-10)


def welded_pair(drive=None):
    """Body 1 hinged to the ground about y at the origin; body 2 welded to it at P."""
    s = nc.System("welded")
    I1 = np.diag([0.05, 0.08, 0.06])
    I2 = np.array([[0.03, 0.004, 0.002], [0.004, 0.02, 0.001], [0.002, 0.001, 0.025]])
    b1 = s.add_body("one", mass=1.5, inertia=I1, position=(0.3, 0.0, 0.0))
    b2 = s.add_body("two", mass=0.7, inertia=I2, position=(0.8, 0.1, -0.05))
    s.add_joint(nc.Revolute(s.ground, b1, at=(0, 0, 0), axis=(0, 1, 0), name="hinge", drive=drive))
    s.add_joint(nc.Fixed(b1, b2, at=(0.6, 0, 0), name="weld"))
    return s, I2


def test_weld_transmits_the_static_wrench():
    """Held still by a driven hinge: the weld carries body 2's weight, f = −m₂ g, with the
    moment −(r_G2 − P) × m₂ g about the weld point P."""
    s, _ = welded_pair(drive="0.0")
    model = s.build()
    assert model.sharing.eliminated["weld"] == "merged"
    _, lam = nc.forward_dynamics(model, model.q0, model.v0)
    r = nc.joint_reactions(model, model.q0, lam, v=model.v0)["weld"]
    g, m2 = np.array([0, 0, -G]), 0.7
    close(r.point, [0.6, 0, 0], 1e-12)
    close(r.force, -m2 * g, 1e-11)
    close(r.moment, -np.cross(np.array([0.8, 0.1, -0.05]) - [0.6, 0, 0], m2 * g), 1e-11)
    assert r.member == "two"
    eq = nc.equilibrium(model)                                        # statics report it too
    rows = {(j, mem): (f, mo) for j, mem, f, mo in eq.joint_reactions()}
    close(rows[("weld", "two")][0], -m2 * g, 1e-9)
    assert "hinge" in model.sharing.partial                           # point and axis shared, drive kept
    close(rows[("hinge", "one")][0], -(1.5 + m2) * g, 1e-9)           # the whole reaction, not the drive's


def test_equilibrium_table_says_when_the_unshared_form_fails():
    s, _ = welded_pair(drive="0.0")
    model = s.build()

    def fail():
        raise ModelError("made to fail")
    model.unshared.build = fail
    eq = nc.equilibrium(model)
    with pytest.raises(ModelError, match="made to fail"):
        eq.joint_reactions()
    assert "not shown: the reactions of joints eliminated by coordinate sharing need" in eq.table()


def test_weld_wrench_in_motion_obeys_newton_euler():
    """Compound pendulum about y: θ̈ from the moment of gravity about the axis, then on body 2
    f = m₂ a_G − m₂ g and M_P = I_G α + ω × I_G ω + (r_G − P) × f."""
    s, I2 = welded_pair()
    model = s.build()
    q, v = model.from_joint_space([0.6], [1.7])
    _, lam = nc.forward_dynamics(model, q, v)
    R, p = model.poses(q)
    y, g = np.array([0, 1.0, 0]), np.array([0, 0, -G])
    masses, inertias = [1.5, 0.7], [np.diag([0.05, 0.08, 0.06]), I2]
    I_O = sum(R[k] @ inertias[k] @ R[k].T + masses[k] * (p[k] @ p[k] * np.eye(3) - np.outer(p[k], p[k]))
              for k in range(2))
    alpha = sum(np.cross(p[k], masses[k] * g) for k in range(2))[1] / I_O[1, 1]
    w, al = 1.7 * y, alpha * y
    rG = p[1]
    a_G = np.cross(al, rG) + np.cross(w, np.cross(w, rG))
    f = 0.7 * a_G - 0.7 * g
    IG = R[1] @ I2 @ R[1].T
    r = nc.joint_reactions(model, q, lam, v=v)["weld"]
    close(r.force, f, 1e-10)
    close(r.moment, IG @ al + np.cross(w, IG @ w) + np.cross(rG - r.point, f), 1e-10)


# ----------------------------------------------------------------------------- against share=False
@pytest.mark.parametrize("make", [fourbar, robot, bar_chain])
def test_shared_reactions_equal_share_false(make):
    shared, explicit = make().build(), make().build(share=False)
    names = [*shared.sharing.eliminated, *shared.sharing.partial]
    assert names
    rng = np.random.default_rng(5)
    S, c = shared.unshared.coordinate_map(shared)
    for _ in range(3):                                 # random consistent states near the initial one
        q = nc.assemble(shared, shared.q0 + 0.05 * rng.standard_normal(shared.nq))
        v = nc.project_velocity(shared, q, rng.standard_normal(shared.nq))
        qu, vu = explicit_state(shared, explicit, q, v)
        close(S @ q + c, qu, 1e-10)
        close(S @ v, vu, 1e-10)
        _, lam = nc.forward_dynamics(shared, q, v)
        _, lam_u = nc.forward_dynamics(explicit, qu, vu)
        rs = nc.joint_reactions(shared, q, lam, v=v)
        ru = nc.joint_reactions(explicit, qu, lam_u, v=vu)
        assert set(rs) == set(ru) >= set(names)
        scale = max(np.abs(r.force).max() for r in ru.values())
        for name in rs:
            assert rs[name].member == ru[name].member
            np.testing.assert_allclose(rs[name].point, ru[name].point, atol=1e-10)
            np.testing.assert_allclose(rs[name].force, ru[name].force, atol=1e-8 * scale)
            np.testing.assert_allclose(rs[name].moment, ru[name].moment, atol=1e-8 * scale)


def test_trajectory_and_drive_of_a_partly_shared_joint():
    """A driven hinge keeps its drive equation and shares its point: its reaction and effort
    (τ = m g (L/2) cos θ for a bar turned at constant rate) along a run."""
    L, m = 1.2, 2.0
    s = nc.System("crank", gravity=(0, -G))
    bar = s.add_bar("bar", mass=m, ends=[(0, 0), (L, 0)])
    s.add_joint(nc.Revolute(s.ground, bar, at=(0, 0), name="motor", drive="2*t"))
    model = s.build()
    assert "motor" in model.sharing.partial
    traj = nc.simulate(model, 0.5, 0.05, rtol=1e-10, atol=1e-10)
    force, moment, effort = traj.reaction("motor")
    th = 2 * traj.t
    np.testing.assert_allclose(effort, m * G * L / 2 * np.cos(th), atol=1e-6)
    e = np.stack([np.cos(th), np.sin(th)], 1)
    np.testing.assert_allclose(force, m * (-(L / 2) * 4 * e) - m * np.array([0, -G]), atol=1e-6)


def test_missing_velocities_are_refused_when_forces_need_them():
    model = double_pendulum().build()
    q, v = model.from_joint_space([0.3, 0.2], [1.0, -1.0])
    _, lam = nc.forward_dynamics(model, q, v)
    assert set(nc.joint_reactions(model, q, lam)) == {"shoulder", "elbow"}     # no force depends on v
    s = double_pendulum()
    s.add_force(nc.Spring(s.members["upper"], (0, 0), s.members["lower"], (0.35, 0), k=10.0,
                          rest_length=1.0, damping=2.0))
    damped = s.build()
    q, v = damped.from_joint_space([0.3, 0.2], [1.0, -1.0])
    _, lam = nc.forward_dynamics(damped, q, v)
    with pytest.raises(ModelError, match="need the velocities"):
        nc.joint_reactions(damped, q, lam, joints=["elbow"])
    assert "elbow" in nc.joint_reactions(damped, q, lam, v=v)


def test_a_wrong_coordinate_map_is_caught_by_the_balance_check():
    """The unshared equations of motion are checked after the multipliers are solved: a map
    that does not carry the motion (here scaled by 1.01) raises instead of giving numbers."""
    model = robot().build()
    q, v = model.q0, model.v0
    _, lam = nc.forward_dynamics(model, q, v)
    S, c = model.unshared.coordinate_map(model)
    model.data.unshared_map = (1.01 * S, c)
    with pytest.raises(ModelError, match="leave a residual"):
        nc.joint_reactions(model, q, lam, v=v, joints=["elbow"])
