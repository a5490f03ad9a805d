"""Joint coordinates of Spherical, Universal and Planar joints to a 3D bar (what is measurable:
no spin about the bar's axis) and the joints that have none (ncgen.assembly.joint_coordinates).

Checked: round trips to_joint_space ∘ from_joint_space, rates against central finite
differences of the positions (rates = d/dt positions), the meaning of the values against
independent geometry (scipy's rotation vectors, world positions), with and without sharing."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import ncgen as nc

I_BODY = np.diag([0.1, 0.2, 0.25])


def fd_rates(model, q, v, h=1e-6):
    """d/dt q_j along (q, v): central differences of the positions along v."""
    return (model.to_joint_space(q + h * v) - model.to_joint_space(q - h * v)) / (2 * h)


def round_trip(model, qj, vj):
    q, v = model.from_joint_space(qj, vj)
    assert np.abs(model.phi(q)).max() < 1e-10
    back_q, back_v = model.to_joint_space(q, v)
    np.testing.assert_allclose(back_q, qj, atol=1e-10)
    np.testing.assert_allclose(back_v, vj, atol=1e-10)
    np.testing.assert_allclose(fd_rates(model, q, v), vj, atol=1e-7)
    return q, v


def bar_on_ball(A_body: bool):
    """A bar from (0, 0, 1) to (1, 0.3, 1.2) on a ball joint at its first end, to the ground or
    to a body turning about z."""
    s = nc.System("ball_bar")
    A = s.ground
    if A_body:
        A = s.add_body("b", mass=1.0, inertia=I_BODY, position=(0, 0, 0.5))
        s.add_joint(nc.Revolute(s.ground, A, at=(0, 0, 0), axis=(0, 0, 1), name="yaw"))
    bar = s.add_bar("bar", mass=1.0, ends=[(0, 0, 1.0), (1.0, 0.3, 1.2)])
    s.add_joint(nc.Spherical(A, bar, at=(0, 0, 1.0), name="ball"))
    return s


@pytest.mark.parametrize("share", [True, False])
@pytest.mark.parametrize("A_body", [False, True])
def test_ball_joint_to_a_bar_gives_its_swing(A_body, share):
    model = bar_on_ball(A_body).build(share=share)
    names = ["yaw"] * A_body + ["ball.swing_1", "ball.swing_2"]
    assert model.joint_space.position_names == names
    np.testing.assert_allclose(model.to_joint_space(model.q0), 0, atol=1e-15)
    u0 = np.array([1.0, 0.3, 0.2]) / np.linalg.norm([1.0, 0.3, 0.2])
    e1, e2 = nc.reproducible.perpendicular_basis(u0)
    rng = np.random.default_rng(1)
    for k in range(4):
        swing = rng.uniform(-1.2, 1.2, 2) if k else np.array([3e-5, -2e-5])   # the series branch too
        yaw = rng.uniform(-1, 1, int(A_body))
        qj = np.concatenate([yaw, swing])
        vj = rng.uniform(-2, 2, qj.size)
        q, v = round_trip(model, qj, vj)
        R, _ = model.poses(q)
        u = R[model.member_names.index("bar")][:, 0]
        R_A = Rotation.from_rotvec([0, 0, yaw[0]]).as_matrix() if A_body else np.eye(3)
        expected = Rotation.from_rotvec(swing[0] * e1 + swing[1] * e2).apply(u0)   # the swing's meaning
        np.testing.assert_allclose(R_A.T @ u, expected, atol=1e-12)


def test_bar_written_first_is_measured_in_the_other_members_frame():
    s = nc.System("reversed")
    s.add_bar("bar", mass=1.0, ends=[(0, 0, 1.0), (1.0, 0.3, 1.2)])
    s.add_joint(nc.Spherical(s.members["bar"], s.ground, at=(0, 0, 1.0), name="ball"))
    model = s.build()
    q, _ = round_trip(model, np.array([0.3, -0.5]), np.array([0.2, 0.9]))
    u0 = np.array([1.0, 0.3, 0.2]) / np.linalg.norm([1.0, 0.3, 0.2])
    e1, e2 = nc.reproducible.perpendicular_basis(u0)
    R, _ = model.poses(q)
    np.testing.assert_allclose(R[0][:, 0], Rotation.from_rotvec(0.3 * e1 - 0.5 * e2).apply(u0), atol=1e-12)


def test_swing_rates_are_smooth_through_zero():
    """At the initial direction (swing 0, where the exact formula θ/sin θ is 0/0) the rates
    are finite, what was asked, and equal to finite differences."""
    model = bar_on_ball(False).build()
    q, v = model.from_joint_space([0.0, 0.0], [0.4, -0.9])
    _, vj = model.to_joint_space(q, v)
    assert np.all(np.isfinite(vj))
    np.testing.assert_allclose(vj, [0.4, -0.9], atol=1e-12)
    np.testing.assert_allclose(fd_rates(model, q, v), vj, atol=1e-8)


@pytest.mark.parametrize("bar_is_B", [True, False])
def test_universal_to_a_bar_has_one_angle(bar_is_B):
    """Hooke joint with the bar's own axis as one of its axes: the other angle is measurable,
    the bar's spin is not."""
    s = nc.System("hooke")
    if bar_is_B:
        bar = s.add_bar("bar", mass=1.0, ends=[(0, 0, 0), (0, 0, -1.0)])
        s.add_joint(nc.Universal(s.ground, bar, at=(0, 0, 0), axis_a=(1, 0, 0), axis_b=(0, 0, -1), name="hooke"))
        name, axis = "hooke.theta_a", np.array([1.0, 0, 0])
    else:
        bar = s.add_bar("bar", mass=1.0, ends=[(0, 0, -1.0), (0, 0, 0)])
        s.add_joint(nc.Universal(bar, s.ground, at=(0, 0, 0), axis_a=(0, 0, 1), axis_b=(1, 0, 0), name="hooke"))
        name, axis = "hooke.theta_b", np.array([-1.0, 0, 0])    # the bar turns by −θ_b about b
    model = s.build()
    assert model.joint_space.position_names == [name]
    for th, w in ((0.4, 0.7), (-1.1, 0.2)):
        q, v = round_trip(model, np.array([th]), np.array([w]))
        R, _ = model.poses(q)
        u = R[0][:, 0]
        u0 = np.array([0, 0, -1.0]) if bar_is_B else np.array([0, 0, 1.0])
        np.testing.assert_allclose(u, Rotation.from_rotvec(th * axis).apply(u0), atol=1e-12)


@pytest.mark.parametrize("across", [False, True])
def test_planar_joint_to_a_bar(across):
    """Along the normal: the bar's point offsets [x, y] in the plane; across it: and its angle
    about the normal."""
    s = nc.System("planar")
    end = (1.2, 0.1, 0.3) if across else (0.2, 0.1, 1.0)
    s.add_bar("bar", mass=1.0, ends=[(0.2, 0.1, 0), end])
    s.add_joint(nc.Planar(s.ground, s.members["bar"], at=(0.2, 0.1, 0), normal=(0, 0, 1), name="slide"))
    model = s.build()
    names = ["slide.x", "slide.y"] + ["slide.theta"] * across
    assert model.joint_space.position_names == names
    e1, e2 = nc.reproducible.perpendicular_basis([0, 0, 1.0])
    qj = np.array([0.4, -0.2, 0.5][:len(names)])
    q, v = round_trip(model, qj, np.array([0.7, 0.1, -0.4][:len(names)]))
    r_i = q[model.layout.member_indices("bar")[:3]]                   # the bar's first end, at ``at``
    np.testing.assert_allclose(r_i, np.array([0.2, 0.1, 0]) + qj[0] * e1 + qj[1] * e2, atol=1e-12)
    if across:
        R, _ = model.poses(q)
        u, u0 = R[0][:, 0], np.array([1.0, 0, 0.3]) / np.linalg.norm([1.0, 0, 0.3])
        np.testing.assert_allclose(u, Rotation.from_rotvec([0, 0, qj[2]]).apply(u0), atol=1e-12)


def test_joints_with_nothing_measurable_say_why():
    s = nc.System("undefined")
    a = s.add_bar("a", mass=1.0, ends=[(0, 0, 0), (1, 0, 0)])
    b = s.add_bar("b", mass=1.0, ends=[(1, 0, 0), (2, 0, 0)])
    p = s.add_point("p", mass=1.0, position=(2, 0, 0))
    s.add_joint(nc.Spherical(s.ground, a, at=(0, 0, 0), name="root_ball"))
    s.add_joint(nc.Spherical(a, b, at=(1, 0, 0), name="bars"))
    s.add_joint(nc.Spherical(b, p, at=(2, 0, 0), name="tip"))
    model = s.build(share=False)
    assert model.joint_names == ["root_ball"]
    assert "two bars" in model.joint_space.skipped["bars"]
    assert "point member" in model.joint_space.skipped["tip"]
    with pytest.raises(nc.ModelError, match="no joint with coordinates named 'tip'.*point member"):
        model.from_joint_space({"tip": [0.0]})
    traj = nc.simulate(model, 0.02, 0.01)
    with pytest.raises(nc.NcgenError, match="between two bars"):
        traj.joint("bars")
    positions, rates = traj.joint("root_ball")
    assert positions.shape == (3, 2) and np.all(np.isfinite(rates))
