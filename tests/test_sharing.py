"""Coordinate sharing (build(share=True), ncgen.model.sharing): the same mechanism with fewer
coordinates and constraints.

Every mechanism is built twice, with the joints eliminated by sharing and with every joint's
equations (share=False), and simulated by IDAS at tight tolerance: the poses of every member
agree to 1e-8 over 1 s and the DOF is the same.  The two runs integrate different equations
in different coordinates, so the agreement checks the pass, not a copy of itself."""
import numpy as np
import pytest

import ncgen as nc


def chain(n=5):
    """3D chain of bars written with explicit Spherical joints, released horizontally."""
    s = nc.System("chain")
    prev = s.add_bar("b0", mass=1.0, ends=[s.ground.point((0, 0, 0)), (1.0, 0, 0)])
    for k in range(1, n):
        bar = s.add_bar(f"b{k}", mass=1.0, ends=[(k, 0, 0), (k + 1.0, 0, 0)])
        s.add_joint(nc.Spherical(prev, bar, at=(k, 0, 0), name=f"ball{k}"))
        prev = bar
    return s


def fourbar():
    """Planar crank-rocker with four explicit Revolute joints (two to the ground)."""
    s = nc.System("fourbar", gravity=(0, -9.81))
    B = np.array([0.5, 0.8660254037844386])
    C = np.array([3.0428529212959905, 2.4578479506333157])
    D = np.array([3.5, 0.0])
    crank = s.add_bar("crank", mass=0.5, ends=[(0, 0), B])
    coupler = s.add_bar("coupler", mass=1.5, ends=[B, C])
    rocker = s.add_bar("rocker", mass=1.2, ends=[C, D])
    s.add_joint(nc.Revolute(s.ground, crank, at=(0, 0), name="O"))
    s.add_joint(nc.Revolute(crank, coupler, at=B, name="B"))
    s.add_joint(nc.Revolute(coupler, rocker, at=C, name="C"))
    s.add_joint(nc.Revolute(rocker, s.ground, at=D, name="D"))
    return s


def slider_crank():
    """Planar slider-crank, crank driven at 2π rad/s, the slider a body on a Prismatic guide."""
    s = nc.System("slider_crank", gravity=(0, -9.81))
    crank = s.add_bar("crank", mass=0.5, ends=[(0, 0), (0.1, 0)])
    rod = s.add_bar("rod", mass=0.3, ends=[(0.1, 0), (0.4, 0)])
    slider = s.add_body("slider", coords="ruv", mass=1.0, inertia=0.002, position=(0.4, 0))
    s.add_joint(nc.Revolute(s.ground, crank, at=(0, 0), drive="6.283185307179586*t", name="motor"))
    s.add_joint(nc.Revolute(crank, rod, at=(0.1, 0), name="pin"))
    s.add_joint(nc.Revolute(rod, slider, at=(0.4, 0), name="wrist"))
    s.add_joint(nc.Prismatic(s.ground, slider, at=(0.4, 0), axis=(1, 0), name="guide"))
    return s


def robot():
    """3D arm of bodies: a base turning about z, two links about horizontal axes, a tool
    welded to the last link (Fixed), all written with explicit joints."""
    s = nc.System("robot")
    I = np.diag([0.02, 0.03, 0.04])
    base = s.add_body("base", mass=2.0, inertia=I, position=(0, 0, 0.1), angular_velocity=(0, 0, 1.0),
                      velocity=(0, 0, 0))
    l1 = s.add_body("link1", mass=1.0, inertia=I, position=(0.25, 0, 0.2), angular_velocity=(0, 0, 1.0),
                    velocity=np.cross([0, 0, 1.0], [0.25, 0, 0.2]))
    l2 = s.add_body("link2", mass=0.8, inertia=I, position=(0.75, 0, 0.2), angular_velocity=(0, 0, 1.0),
                    velocity=np.cross([0, 0, 1.0], [0.75, 0, 0.2]))
    tool = s.add_body("tool", mass=0.3, inertia=0.5 * I, position=(1.05, 0, 0.2), angular_velocity=(0, 0, 1.0),
                      velocity=np.cross([0, 0, 1.0], [1.05, 0, 0.2]))
    s.add_joint(nc.Revolute(s.ground, base, at=(0, 0, 0), axis=(0, 0, 1), name="yaw"))
    s.add_joint(nc.Revolute(base, l1, at=(0, 0, 0.2), axis=(0, 1, 0), name="shoulder"))
    s.add_joint(nc.Revolute(l1, l2, at=(0.5, 0, 0.2), axis=(0, 1, 0), name="elbow"))
    s.add_joint(nc.Fixed(l2, tool, at=(1.0, 0, 0.2), name="flange"))
    return s


def poses(model, traj):
    out = []
    for q in traj.q:
        R, p = model.poses(q)
        out.append(np.concatenate([R.reshape(-1), p.reshape(-1)]))
    return np.array(out)


@pytest.mark.parametrize("make, eliminated, nq_saved", [
    (chain, {"ball1", "ball2", "ball3", "ball4"}, 12),
    (fourbar, {"O", "B", "C", "D"}, 8),
    (slider_crank, {"pin", "wrist"}, 6),
    (robot, {"yaw", "shoulder", "elbow", "flange"}, 48 - 18),
])
def test_shared_and_explicit_forms_move_alike(make, eliminated, nq_saved):
    shared, explicit = make().build(), make().build(share=False)
    assert set(shared.sharing.eliminated) == eliminated
    assert explicit.sharing is None
    assert shared.dof == explicit.dof
    assert explicit.nq - shared.nq == nq_saved == shared.sharing.nq_before - shared.nq
    assert shared.nc + shared.sharing.nc_removed == explicit.nc
    a = nc.simulate(shared, 1.0, 0.05, rtol=1e-12, atol=1e-12)
    b = nc.simulate(explicit, 1.0, 0.05, rtol=1e-12, atol=1e-12)
    moved = np.max(np.abs(poses(shared, a) - poses(shared, a)[0]))
    assert moved > 0.1                                      # the mechanism really moves
    np.testing.assert_allclose(poses(shared, a), poses(explicit, b), atol=1e-8, rtol=0)


def test_explicit_chain_is_the_shared_point_chain():
    """The explicit-joint chain compiles to the chain written with shared points: same
    coordinates, constraints and initial state."""
    s = nc.System("chain")
    prev = s.add_bar("b0", mass=1.0, ends=[s.ground.point((0, 0, 0)), (1.0, 0, 0)])
    for k in range(1, 5):
        prev = s.add_bar(f"b{k}", mass=1.0, ends=[prev.end(1), (k + 1.0, 0, 0)])
    written = s.build()
    compiled = chain().build()
    assert compiled.coordinate_names == written.coordinate_names
    assert compiled.constraint_names == written.constraint_names
    np.testing.assert_array_equal(compiled.q0, written.q0)
    q = compiled.q0 + 0.01 * np.arange(compiled.nq)
    np.testing.assert_allclose(compiled.A(q), written.A(q), atol=1e-15)
    np.testing.assert_allclose(compiled.M, written.M, atol=1e-15)


def test_the_users_system_is_not_changed():
    s = robot()
    before = {n: m.ctype.name for n, m in s.members.items()}
    model = s.build()
    assert {n: m.ctype.name for n, m in s.members.items()} == before
    assert model.sharing.rebased                               # the bodies of the model were re-based
    again = s.build(share=False)
    assert again.nq == 4 * 12


def test_a_joint_off_the_basic_points_is_kept():
    """A ball joint in the middle of an 'rr' bar cannot be a shared point: it stays."""
    s = nc.System("mid")
    a = s.add_bar("a", mass=1.0, ends=[s.ground.point((0, 0, 0)), (2.0, 0, 0)])
    b = s.add_bar("b", mass=1.0, ends=[(1.0, 0, 0), (1.0, 1.0, 0)])
    s.add_joint(nc.Spherical(a, b, at=(1.0, 0, 0), name="mid"))
    model = s.build()
    assert "mid" not in model.sharing.eliminated
    assert any(n.startswith("mid.coincide") for n in model.constraint_names)


def test_bodies_welded_to_the_ground_and_to_each_other():
    """A Fixed weld to the ground leaves a body without coordinates; a weld between two
    bodies merges them (one set of nodes, the masses add); a CoordinateDriver's body is kept."""
    s = nc.System("welds", gravity=(0, -9.81))
    base = s.add_body("base", "ruv", mass=1.0, inertia=0.1, position=(0, 0))
    arm = s.add_body("arm", "ruv", mass=1.0, inertia=0.1, position=(0.5, 0))
    tip = s.add_body("tip", "ruv", mass=0.5, inertia=0.05, position=(1.0, 0))
    s.add_joint(nc.Fixed(s.ground, base, at=(0, 0), name="weld0"))
    s.add_joint(nc.Revolute(base, arm, at=(0.2, 0), name="pin"))
    s.add_joint(nc.Fixed(arm, tip, at=(0.8, 0), name="weld1"))
    shared, explicit = s.build(), s.build(share=False)
    assert set(shared.sharing.eliminated) == {"weld0", "pin", "weld1"}
    assert shared.dof == explicit.dof == 1
    assert shared.layout.member_indices("base") == [None] * 6
    assert shared.layout.member_indices("arm") == shared.layout.member_indices("tip")
    a = nc.simulate(shared, 0.5, 0.05, rtol=1e-12, atol=1e-12)
    b = nc.simulate(explicit, 0.5, 0.05, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(poses(shared, a), poses(explicit, b), atol=1e-8, rtol=0)
    assert np.max(np.abs(poses(shared, a) - poses(shared, a)[0])) > 0.1


def test_a_coordinate_driver_keeps_its_body_as_written():
    s = nc.System("driver", gravity=(0, -9.81))
    body = s.add_body("body", coords="rrv", mass=1.0, inertia=0.1, position=(0.5, 0))
    s.add_joint(nc.Revolute(s.ground, body, at=(0, 0), name="pin"))
    s.add_joint(nc.CoordinateDriver(body, "r_j", "y", "0.1*t", name="lift"))
    model = s.build()
    assert "body" not in model.sharing.rebased and "pin" not in model.sharing.eliminated
    assert model.dof == s.build(share=False).dof == 0


def test_a_joint_at_a_point_already_shared_is_implied():
    """A ball joint repeating a shared point adds nothing: it is eliminated as implied
    (without sharing it is a redundant constraint)."""
    s = nc.System("twice")
    b1 = s.add_bar("b1", mass=1.0, ends=[s.ground.point((0, 0, 0)), (0, 1.0, 0.0)])
    b2 = s.add_bar("b2", mass=1.0, ends=[b1.end(1), (0, 1.0, -1.0)])
    s.add_joint(nc.Spherical(b1, b2, at=(0, 1.0, 0), name="again"))
    model = s.build(redundant="error")
    assert model.sharing.eliminated == {"again": "implied: the point was already shared"}
    assert model.dof == 4 and not model.redundant
