"""Joint space: joint coordinates of every joint type, the round trip q ↔ q_j, rates and
accelerations against finite differences, closed loops, actuators against closed forms."""
from __future__ import annotations

import numpy as np
import pytest

import ncgen as nc
from ncgen.assembly.joint_tree import quaternion_matrix

G = 9.81


def body(s, name, pos, m=1.0):
    return s.add_body(name, mass=m, inertia=np.diag([0.1, 0.2, 0.25]) * m, position=pos)


@pytest.fixture(scope="module")
def chain():
    """Every 3D joint type with coordinates, in one tree."""
    s = nc.System("chain")
    b = [body(s, f"b{k}", (k + 0.5, 0.1 * k, 0)) for k in range(7)]
    s.add_joint(nc.Free(s.ground, b[0], at=(0.5, 0, 0), rotation=np.eye(3), name="root"))
    s.add_joint(nc.Revolute(b[0], b[1], at=(1, 0, 0), axis=(0, 0, 1), name="hinge"))
    s.add_joint(nc.Prismatic(b[1], b[2], at=(2, 0.1, 0), axis=(1, 0, 0), name="slider"))
    s.add_joint(nc.Cylindrical(b[2], b[3], at=(3, 0.2, 0), axis=(1, 0, 0), name="cyl"))
    s.add_joint(nc.Universal(b[3], b[4], at=(4, 0.3, 0), axis_a=(0, 1, 0), axis_b=(0, 0, 1), name="hooke"))
    s.add_joint(nc.Spherical(b[4], b[5], at=(5, 0.4, 0), name="ball"))
    s.add_joint(nc.Planar(b[5], b[6], at=(6, 0.5, 0), normal=(0, 1, 0), name="plane"))
    return s.build()


def random_joint_state(model, rng):
    js = model.joint_space
    qj = rng.uniform(-1, 1, js.nq)
    for name, sl in js.slices().items():
        if js.nq_joint[name] in (4, 7):
            quat = rng.normal(size=4)
            quat *= np.sign(quat[3]) / np.linalg.norm(quat)
            qj[sl][-4:] = quat
    return qj, rng.normal(size=js.nv)


def test_names_and_zero_at_the_initial_configuration(chain):
    js = chain.joint_space
    assert chain.joint_names == ["root", "hinge", "slider", "cyl", "hooke", "ball", "plane"]
    assert js.position_names[7:] == ["hinge", "slider", "cyl.s", "cyl.theta", "hooke.theta_a", "hooke.theta_b",
                                     "ball.qx", "ball.qy", "ball.qz", "ball.qw", "plane.x", "plane.y",
                                     "plane.theta"]
    qj0, vj0 = chain.to_joint_space(chain.q0, chain.v0)
    expected = np.zeros(js.nq)
    expected[:7] = [0.5, 0, 0, 0, 0, 0, 1]          # the root: absolute pose of its frame
    expected[js.slices()["ball"]] = [0, 0, 0, 1]
    np.testing.assert_allclose(qj0, expected, atol=1e-15)
    np.testing.assert_allclose(vj0, 0, atol=1e-15)


def test_round_trip_is_exact(chain):
    rng = np.random.default_rng(0)
    for _ in range(5):
        qj, vj = random_joint_state(chain, rng)
        q, v = chain.from_joint_space(qj, vj)
        assert np.max(np.abs(chain.phi(q))) < 1e-13
        assert np.max(np.abs(chain.A(q) @ v)) < 1e-13
        qj2, vj2 = chain.to_joint_space(q, v)
        np.testing.assert_allclose(qj2, qj, atol=1e-12)
        np.testing.assert_allclose(vj2, vj, atol=1e-12)


def _omega_fd(Rm, Rp, h):
    S = Rm.T @ Rp
    W = 0.5 * (S - S.T)
    return np.array([W[2, 1], W[0, 2], W[1, 0]]) / (2 * h)


def test_rates_and_accelerations_against_finite_differences(chain):
    js = chain.joint_space
    rng = np.random.default_rng(1)
    qj, vj = random_joint_state(chain, rng)
    q, v = chain.from_joint_space(qj, vj)
    a = rng.normal(size=chain.nq)
    h = 1e-6
    qm, qp = chain.to_joint_space(q - h * v), chain.to_joint_space(q + h * v)
    _, vj_, aj = chain.to_joint_space(q, v, a)
    sq, sv = js.slices(), js.slices(rates=True)
    for name in chain.joint_names:
        xm, xp, rate = qm[sq[name]], qp[sq[name]], vj_[sv[name]]
        if name == "root":
            R = quaternion_matrix(qj[sq[name]][3:])
            np.testing.assert_allclose(rate[:3], R.T @ (xp[:3] - xm[:3]) / (2 * h), atol=1e-7)
            np.testing.assert_allclose(rate[3:], _omega_fd(quaternion_matrix(xm[3:]), quaternion_matrix(xp[3:]), h),
                                       atol=1e-7)
        elif name == "ball":
            np.testing.assert_allclose(rate, _omega_fd(quaternion_matrix(xm), quaternion_matrix(xp), h), atol=1e-7)
        else:
            np.testing.assert_allclose(rate, (xp - xm) / (2 * h), atol=1e-7, err_msg=name)
    vm = chain.to_joint_space(q - h * v, v - h * a)[1]
    vp = chain.to_joint_space(q + h * v, v + h * a)[1]
    np.testing.assert_allclose(aj, (vp - vm) / (2 * h), atol=1e-6)


def test_spherical_and_free_rates_are_in_the_moving_frame():
    """A ball joint's rate is ω of B relative to A in B's joint-frame axes: world ω = R ω_j."""
    s = nc.System("top")
    R = quaternion_matrix([0.3, -0.2, 0.1, 0.9])
    w = np.array([0.3, -1.0, 2.0])
    b = s.add_body("b", mass=1.0, inertia=np.diag([0.1, 0.2, 0.25]), position=(0, 0, 0), rotation=R,
                   angular_velocity=w)
    s.add_joint(nc.Spherical(s.ground, b, at=(0, 0, 0), name="ball"))
    m = s.build(share=False)            # the body's own coordinates are then the system's
    _, vj = m.to_joint_space(m.q0, m.v0)
    np.testing.assert_allclose(vj, w, atol=1e-14)      # the joint frames have world axes initially
    qj, vj = m.to_joint_space(*m.from_joint_space([0.3, -0.2, 0.1, 0.9], [0.1, 0.2, 0.3]))
    Rj = quaternion_matrix([0.3, -0.2, 0.1, 0.9])
    _, v_world = m.from_joint_space([0.3, -0.2, 0.1, 0.9], [0.1, 0.2, 0.3])
    np.testing.assert_allclose(m.member("b").rigid.twist(m.from_joint_space([0.3, -0.2, 0.1, 0.9])[0],
                                                          v_world)[0], Rj @ [0.1, 0.2, 0.3], atol=1e-12)
    q, v = m.from_joint_space([0.3, -0.2, 0.1, 0.9], [0.1, 0.2, 0.3])
    Rb, _ = m.poses(q)
    np.testing.assert_allclose(Rb[0], quaternion_matrix([0.3, -0.2, 0.1, 0.9]) @ R, atol=1e-12)


def planar_models():
    s = nc.System("planar2d", gravity=(0, -G))
    a = s.add_bar("a", mass=1.0, ends=[(0, 0), (1, 0)])
    b = s.add_body("b", "ruv", mass=2.0, inertia=0.3, position=(1.5, 0.2))
    c = s.add_body("c", "ruv", mass=1.0, inertia=0.1, position=(3, 0.2))
    s.add_joint(nc.Revolute(s.ground, a, at=(0, 0), name="shoulder"))
    s.add_joint(nc.Prismatic(a, b, at=(1, 0), axis=(1, 0), name="slide"))
    s.add_joint(nc.Free(b, c, at=(3, 0.2), name="float"))
    return s.build()


def test_planar_joints():
    m = planar_models()
    assert m.joint_names == ["shoulder", "slide", "float"]
    assert m.joint_space.position_names == ["shoulder", "slide", "float.x", "float.y", "float.theta"]
    qj = np.array([0.4, 0.2, 0.1, -0.3, 1.2])
    vj = np.array([0.5, -0.1, 0.3, 0.2, -0.7])
    q, v = m.from_joint_space(qj, vj)
    qj2, vj2 = m.to_joint_space(q, v)
    np.testing.assert_allclose(qj2, qj, atol=1e-12)
    # the free joint's frame on c starts at (3, 0.2), 1.5 m along b's x from b's frame origin
    np.testing.assert_allclose(m.to_joint_space(m.q0), [0, 0, 1.5, 0, 0], atol=1e-14)
    np.testing.assert_allclose(vj2, vj, atol=1e-12)
    R, p = m.poses(q)
    assert abs(np.arctan2(R[0][1, 0], R[0][0, 0]) - 0.4) < 1e-12


@pytest.fixture(scope="module")
def four_bar():
    s = nc.System("fourbar", gravity=(0, -G))
    crank = s.add_bar("crank", mass=1.0, ends=[(0, 0), (0, 1)])
    coupler = s.add_bar("coupler", mass=1.0, ends=[(0, 1), (2, 1)])
    rocker = s.add_bar("rocker", mass=1.0, ends=[(2, 0), (2, 1)])
    s.add_joint(nc.Revolute(s.ground, crank, at=(0, 0), name="j0"))
    s.add_joint(nc.Revolute(crank, coupler, at=(0, 1), name="j1"))
    s.add_joint(nc.Revolute(coupler, rocker, at=(2, 1), name="j2"))
    s.add_joint(nc.Revolute(s.ground, rocker, at=(2, 0), name="j3"))
    return s.build()


def test_closed_loop_from_independent_coordinates(four_bar):
    m = four_bar
    q, v = m.from_joint_space({"j0": -0.3}, {"j0": 1.5})
    assert np.max(np.abs(m.phi(q))) < 1e-12
    qj, vj = m.to_joint_space(q, v)
    assert abs(qj[0] + 0.3) < 1e-12 and abs(vj[0] - 1.5) < 1e-12
    # a parallelogram: every joint turns by the crank angle, the rocker follows the crank
    np.testing.assert_allclose(qj, [-0.3, 0.3, -0.3, -0.3], atol=1e-10)
    np.testing.assert_allclose(vj, [1.5, -1.5, 1.5, 1.5], atol=1e-10)


def test_closed_loop_contradiction_is_a_clear_error(four_bar):
    with pytest.raises(nc.ModelError, match="no configuration has these joint coordinates"):
        four_bar.from_joint_space({"j0": 0.3, "j3": -0.5})
    with pytest.raises(nc.ModelError, match="no joint with coordinates named 'elbow'"):
        four_bar.from_joint_space({"elbow": 0.3})
    with pytest.raises(nc.ModelError, match="do not determine the velocity"):
        four_bar.from_joint_space({"j0": 0.3}, {"j0": 1.0, "j3": 0.5})


def pendulum(L=1.2, m=2.0):
    s = nc.System("pendulum", gravity=(0, -G))
    tau = s.add_input("tau")
    bar = s.add_bar("bar", mass=m, ends=[(0, 0), (L, 0)])
    s.add_joint(nc.Revolute(s.ground, bar, at=(0, 0), name="pivot", effort=tau))
    return s.build()


def test_actuated_pendulum_closed_form():
    """θ̈ = (τ − m g (L/2) cos θ) / (m L²/3) for a uniform bar hinged at one end."""
    L, mass = 1.2, 2.0
    model = pendulum(L, mass)
    assert model.actuated_joints == ["pivot"]
    th, om, tau = 0.4, 1.3, 3.0
    q, v = model.from_joint_space([th], [om])
    a, _ = nc.forward_dynamics(model, q, v, u=[tau])
    _, vj, aj = model.to_joint_space(q, v, a)
    expected = (tau - mass * G * L / 2 * np.cos(th)) / (mass * L**2 / 3)
    assert abs(aj[0] - expected) < 1e-12 * max(1, abs(expected))
    tau_back = nc.inverse_dynamics(model, [th], [om], aj)
    np.testing.assert_allclose(tau_back, [tau], rtol=1e-12)


def test_inverse_dynamics_needs_actuators(four_bar):
    with pytest.raises(nc.ModelError, match="no actuated joints"):
        nc.inverse_dynamics(four_bar, {"j0": 0.1}, {"j0": 0.0}, [0.0, 0.0, 0.0, 0.0])


def test_mimic_joint_holds():
    s = nc.System("gripper")
    b1 = body(s, "b1", (0.5, 0, 0))
    b2 = body(s, "b2", (0.5, 1, 0))
    j1 = s.add_joint(nc.Prismatic(s.ground, b1, at=(0.5, 0, 0), axis=(1, 0, 0), name="f1"))
    j2 = s.add_joint(nc.Prismatic(s.ground, b2, at=(0.5, 1, 0), axis=(1, 0, 0), name="f2"))
    s.add_joint(nc.Mimic(j1, j2, multiplier=-2.0, name="link"))
    m = s.build()
    assert m.dof == 1
    q, _ = m.from_joint_space({"f1": 0.1})
    np.testing.assert_allclose(m.to_joint_space(q), [0.1, -0.2], atol=1e-12)


def test_joint_without_coordinates_is_listed_as_skipped():
    """A ball joint between two bars has nothing measurable but the angle between them (tests
    of the joints to one bar: tests/test_joint_space_bars.py)."""
    s = nc.System("bars")
    a = s.add_bar("a", mass=1.0, ends=[(0, 0, 0), (1, 0, 0)])
    b = s.add_bar("b", mass=1.0, ends=[(1, 0, 0), (2, 0, 0)])
    s.add_joint(nc.Spherical(s.ground, a, at=(0, 0, 0), name="ball"))
    s.add_joint(nc.Spherical(a, b, at=(1, 0, 0), name="elbow"))
    m = s.build()
    assert m.joint_names == ["ball"]
    assert "two bars" in m.joint_space.skipped["elbow"]
    with pytest.raises(nc.ModelError, match="between two bars"):
        m.from_joint_space({"elbow": [0, 0, 0, 1]})


PENDULUM_TOML = """
[system]
name = "pend"
gravity = [0.0, -9.81]

[[members]]
name = "bar"
kind = "bar"
mass = 1.0
ends = [[0.0, 0.0], [1.0, 0.0]]

[[joints]]
type = "Revolute"
name = "pivot"
between = ["ground", "bar"]
at = [0.0, 0.0]

[initial]
pivot = -0.5

[initial_rates]
pivot = 1.0
"""


def test_toml_initial_state_in_joint_space_and_trajectory_outputs(tmp_path):
    s = nc.System.from_toml(PENDULUM_TOML)
    assert s.initial_joints == {"pivot": -0.5} and s.initial_joint_rates == {"pivot": 1.0}
    assert nc.System.from_toml(s.to_toml()).initial_joints == {"pivot": -0.5}
    m = s.build()
    qj, vj = m.to_joint_space(m.q0, m.v0)
    np.testing.assert_allclose([qj[0], vj[0]], [-0.5, 1.0], atol=1e-12)
    traj = nc.simulate(m, 0.2, 0.1)
    th, om = traj.joint("pivot")
    assert th.shape == (3,) and abs(th[0] + 0.5) < 1e-12 and abs(om[0] - 1.0) < 1e-12
    # energy of the pendulum from the joint-space outputs: T = ½ (m L²/3) ω², V = m g (L/2) sin θ
    E = 0.5 * (1 / 3) * om**2 + G * 0.5 * np.sin(th)
    np.testing.assert_allclose(E, traj.energy, atol=1e-6)
    traj.save(tmp_path / "p.csv")
    header = (tmp_path / "p.csv").read_text().splitlines()[0].split(",")
    assert "qj.pivot [rad]" in header and "vj.pivot [rad/s or m/s]" in header
    traj.save(tmp_path / "p.npz")
    back = nc.Trajectory.load(tmp_path / "p.npz")
    np.testing.assert_allclose(back.joint("pivot")[0], th)
    with pytest.raises(nc.NcgenError, match="no joint with coordinates named 'elbow'"):
        traj.joint("elbow")


def test_toml_initial_names_a_joint():
    with pytest.raises(nc.ModelError, match="initial.pivto: no joint named 'pivto'"):
        nc.System.from_toml(PENDULUM_TOML.replace("pivot = -0.5", "pivto = -0.5"))


def test_toml_round_trip_of_actuators_and_free_joints():
    s = nc.System("p", gravity=(0, -G))
    tau = s.add_input("tau")
    bar = s.add_bar("bar", mass=1.0, ends=[(0, 0), (1, 0)])
    b = s.add_body("b", "ruv", mass=1.0, inertia=0.1, position=(2, 0))
    s.add_joint(nc.Revolute(s.ground, bar, at=(0, 0), name="pivot", effort=tau))
    s.add_joint(nc.Free(bar, b, at=(2, 0), rotation=0.3, name="fly"))
    back = nc.System.from_toml(s.to_toml()).build()
    m = s.build()
    assert back.joint_names == ["pivot", "fly"] and back.actuated_joints == ["pivot"]
    np.testing.assert_allclose(back.to_joint_space(back.q0), m.to_joint_space(m.q0), atol=1e-15)
    q, v = m.from_joint_space([0.2, 0.1, 0.2, 0.3], [0.0, 0.1, 0.0, 0.0])
    np.testing.assert_allclose(nc.forward_dynamics(back, q, v, u=[1.5])[0], nc.forward_dynamics(m, q, v, u=[1.5])[0],
                               atol=1e-12)
