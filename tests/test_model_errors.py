"""Bad input to the modeling API: each mistake gives one clear message."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

import ncgen as nc


def _bar_system(name="s"):
    s = nc.System(name)
    bar = s.add_bar("bar", mass=1.0, ends=[(0, 0, 0), (1, 0, 0)])
    return s, bar


def test_duplicate_names():
    s, bar = _bar_system()
    with pytest.raises(nc.ModelError, match="point 'bar': the name is already used in system 's'"):
        s.add_point("bar", mass=1.0, position=(0, 0, 1))
    s.add_joint(nc.Spherical(s.ground, bar, at=(0, 0, 0), name="pin"))
    with pytest.raises(nc.ModelError, match="joint 'pin' .*: the name is already used by another joint"):
        s.add_joint(nc.Distance(s.ground, bar, at=((0, 0, 1), (1, 0, 0)), name="pin"))
    s.add_force(nc.Torque(bar, (0, 0, 1), name="push"))
    with pytest.raises(nc.ModelError, match="force 'push' .*: the name is already used by another force"):
        s.add_force(nc.PointForce(bar, (0, 0, 0), (0, 0, 1), name="push"))
    with pytest.raises(nc.ModelError, match="parameter 'bar': the name is already used"):
        s.add_parameter("bar", 1.0)
    with pytest.raises(nc.ModelError, match="parameter 'sin': the name is reserved in expressions"):
        s.add_parameter("sin", 1.0)
    with pytest.raises(nc.ModelError, match="input name: expected an identifier"):
        s.add_input("two words")


def test_references_to_missing_or_foreign_members():
    s, bar = _bar_system()
    other, stranger = _bar_system("other")
    with pytest.raises(nc.ModelError, match=r"no member named 'bra' in system 's' \(members: bar\)"):
        s.member("bra")
    with pytest.raises(nc.ModelError, match="Spherical joint 'spherical_0': the second member 'bar' is not a "
                                            "member of system 's'"):
        s.add_joint(nc.Spherical(bar, stranger, at=(0, 0, 0)))
    with pytest.raises(nc.ModelError, match="the first member: expected a member of system 's'"):
        s.add_joint(nc.Spherical("bar", s.ground, at=(0, 0, 0)))
    planar = nc.System("flat", gravity=(0, -9.81))
    with pytest.raises(nc.ModelError, match="the first member is the ground of a 2D system, but system 's' is 3D"):
        s.add_joint(nc.Spherical(planar.ground, bar, at=(0, 0, 0)))
    with pytest.raises(nc.ModelError, match="shared slot r_i: a ground point of a 2D system in the 3D system 's'"):
        s.add_body("b3", mass=1.0, inertia=np.eye(3), share={"r_i": planar.ground.point((0, 0))})
    with pytest.raises(nc.ModelError, match="shares a point with 'bar', which is not a member of system 's'"):
        s.add_bar("b2", mass=1.0, ends=[stranger.end(1), (2, 0, 0)])
    with pytest.raises(nc.ModelError, match="force 'torque_0' .*: the member 'bar' is not a member of system 's'"):
        s.add_force(nc.Torque(stranger, (0, 0, 1)))
    j = s.add_joint(nc.Spherical(s.ground, bar, at=(0, 0, 0)))
    with pytest.raises(nc.ModelError, match="already added to system 's'"):
        other.add_joint(j)


def test_zero_axis_and_bad_shapes():
    s = nc.System("axes")
    body = s.add_body("body", mass=1.0, inertia=np.eye(3) * 0.1)
    with pytest.raises(nc.ModelError, match=r"normal: expected a non-zero direction, got \[0.0, 0.0, 0.0\]"):
        s.add_joint(nc.Planar(s.ground, body, at=(0, 0, 0), normal=(0, 0, 0)))
    with pytest.raises(nc.NcgenError, match=r"axis: expected 3 numbers, got 2"):
        s.add_joint(nc.Prismatic(s.ground, body, at=(0, 0, 0), axis=(1, 0)))
    with pytest.raises(nc.ModelError, match=r"at: expected two points \(one on each member\)"):
        s.add_joint(nc.Distance(s.ground, body, at=(0, 0, 1)))


def test_inconsistent_initial_state_says_by_how_much_and_where():
    s, bar = _bar_system()
    s.add_joint(nc.Spherical(s.ground, bar, at=(0, 0, 0)))
    s.add_joint(nc.CoordinateDriver(bar, "r_j", "z", 0.01))
    with pytest.raises(nc.ModelError) as err:
        s.build()
    msg = str(err.value)
    assert "inconsistent initial configuration" in msg and "coordinatedriver_1.coordinate = -0.01" in msg
    assert "moves bar.r_j.z by 0.01 m" in msg and "tolerance 1e-06" in msg
    s2 = nc.System("v")
    s2.add_bar("bar", mass=1.0, ends=[s2.ground.point((0, 0, 0)), (1, 0, 0)], velocity=(0.5, 0, 0))
    with pytest.raises(nc.ModelError, match=r"inconsistent initial velocities: making them satisfy the constraints "
                                            r"changes bar.r_j.x by 0.5 m/s"):
        s2.build()


def test_bad_values():
    s, bar = _bar_system()
    s.add_parameter("k", 1.0)
    s.add_force(nc.Torque(bar, lambda t: ca.MX.sym("m", 3)))
    with pytest.raises(nc.ModelError, match="torque: MX expressions are not supported; use SX symbols"):
        s.build()
    s.forces.clear()
    s.add_force(nc.PointForce(bar, (0.5, 0, 0), force="k"))
    with pytest.raises(nc.ModelError, match=r"force: expected 3 components, got 1"):
        s.build()
    s.forces.clear()
    s.add_joint(nc.Spherical(s.ground, bar, at=(0, 0, 0)))
    s.add_joint(nc.Revolute(s.ground, s.add_body("b", mass=1, inertia=np.eye(3) * 0.1, position=(0, 0, 2)),
                            at=(0, 0, 2), axis=(0, 0, 1), drive=lambda t: ca.SX.sym("x") * t))
    with pytest.raises(nc.ModelError, match=r"drive \(rotation angle .*\): depends on the symbol 'x', which is not one "
                                            r"of the names usable here \(t, k\)"):
        s.build()


def test_marker_off_a_bar():
    s, bar = _bar_system()
    with pytest.raises(nc.ModelError, match=r"marker bar.tip \(rr bar\): local point \[0.5, 0.1, 0.0\] is 0.1 m off "
                                            r"the bar's axis"):
        bar.add_marker("tip", (0.5, 0.1, 0))
    with pytest.raises(nc.ModelError, match="bar: marker tip already|marker name: expected an identifier"):
        bar.add_marker("a tip", (0.5, 0, 0))


@pytest.mark.parametrize("share", [True, False])
def test_a_point_fixed_to_the_ground_must_start_at_rest(share):
    """A bar hinged at its first end, spun about its centre: the hinge would have to move at
    1.5 m/s.  Dropping that silently (the tip then moves at 1.5 m/s, not 3) is refused."""
    s = nc.System("spun", gravity=(0, -9.81))
    bar = s.add_bar("bar", mass=1.0, ends=[(0, 0), (3, 0)], angular_velocity=1.0)
    s.add_joint(nc.Revolute(s.ground, bar, at=(0, 0)))
    with pytest.raises(nc.ModelError, match="inconsistent initial velocities"):
        s.build(share=share)
    ok = nc.System("spun_ok", gravity=(0, -9.81))
    bar = ok.add_bar("bar", mass=1.0, ends=[(0, 0), (3, 0)], angular_velocity=1.0, velocity=(0, 1.5))
    ok.add_joint(nc.Revolute(ok.ground, bar, at=(0, 0)))
    model = ok.build(share=share)
    i = model.coordinate_names.index("bar.r_j.y")
    assert model.v0[i] == pytest.approx(3.0)                 # the tip: ω × 3 m
