"""build(assemble=True) with drives that must move the mechanism (ncgen.assembly.drive_assembly):
the drives are continued from the given poses before the redundancy checks, so a hinge a
quarter turn from its drive (a singular start for Newton) assembles, on the branch the drive
leads to; references are closed forms (circle intersections)."""
import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import ModelError


def driven_bar(drive: str):
    s = nc.System("driven_bar", gravity=(0, -9.81))
    bar = s.add_bar("bar", mass=1.0, ends=[s.ground.point((0, 0)), (1, 0)])
    s.add_joint(nc.Revolute(s.ground, bar, at=(0, 0), drive=drive))
    return s


def test_a_quarter_turn_drive_assembles_and_moves_as_driven():
    """The bar lies at angle 0 and the drive says π/2 + t: it starts upright (not at −π/2,
    which the drive equation also admits), turning at 1 rad/s."""
    with pytest.raises(ModelError, match="singular|cannot be satisfied"):      # without assembly: refused
        driven_bar("pi/2 + t").build()
    model = driven_bar("pi/2 + t").build(assemble=True)
    np.testing.assert_allclose(model.q0, [0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(model.v0, [-1.0, 0.0], atol=1e-9)
    traj = nc.simulate(model, 1.0, 0.1)
    angle = np.pi / 2 + traj.t
    np.testing.assert_allclose(traj.q, np.column_stack([np.cos(angle), np.sin(angle)]), atol=1e-6)


def test_three_quarter_turns_are_followed_through():
    model = driven_bar("3*pi/2").build(assemble=True)
    np.testing.assert_allclose(model.q0, [0.0, -1.0], atol=1e-12)


def test_a_driven_four_bar_assembles_on_the_branch_it_starts_on():
    """Ground pivots at (0, 0) and (3, 0), crank 1 m, coupler 3 m, rocker 2 m, given with the
    crank at 0 and the rocker tip above the ground line; the crank drive π/2 moves the
    crank tip to (0, 1) and the rocker tip to the upper intersection of its two circles."""
    s = nc.System("driven_fourbar", gravity=(0, -9.81))
    y = np.sqrt(4 - 0.25**2)
    crank = s.add_bar("crank", mass=1.0, ends=[s.ground.point((0, 0)), (1, 0)])
    rocker = s.add_bar("rocker", mass=1.0, ends=[s.ground.point((3, 0)), (3.25, y)])
    s.add_bar("coupler", mass=1.0, ends=[crank.end(1), rocker.end(1)])
    s.add_joint(nc.Revolute(s.ground, crank, at=(0, 0), drive="pi/2"))
    model = s.build(assemble=True)
    tip = np.array([0.0, 1.0])
    # rocker tip: |x − (3, 0)| = 2 and |x − tip| = 3, the upper solution
    d = np.linalg.norm(tip - [3, 0])
    a = (4 - 9 + d**2) / (2 * d)
    mid = np.array([3, 0]) + a * (tip - [3, 0]) / d
    h = np.sqrt(4 - a**2)
    normal = np.array([-(tip - [3, 0])[1], (tip - [3, 0])[0]]) / d
    upper = max(mid + h * normal, mid - h * normal, key=lambda x: x[1])
    q = dict(zip(model.coordinate_names, model.q0))
    np.testing.assert_allclose([q["crank.r_j.x"], q["crank.r_j.y"]], tip, atol=1e-10)
    np.testing.assert_allclose([q["rocker.r_j.x"], q["rocker.r_j.y"]], upper, atol=1e-10)
