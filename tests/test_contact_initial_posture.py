"""Contact gaps are checked where a run starts: a URDF robot whose zero pose reaches below the
ground but whose initial joints (``System.initial_joints``) hold it clear builds, and one whose
initial posture penetrates is refused, naming the contact and its depth.

The arm of tests/data/hanging_arm.urdf (own): the shoulder at 0.5 m turns about y, the tip
sphere of radius 0.05 m is 0.6 m from it, so the sphere's gap to the ground z = 0 at the
shoulder angle θ is ``0.5 − 0.6 cos θ − 0.05`` m (closed form): −0.15 m in the zero pose."""
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import ModelError

ARM = Path(__file__).resolve().parent / "data" / "hanging_arm.urdf"


def gap(theta: float) -> float:
    return 0.5 - 0.6 * np.cos(theta) - 0.05


def arm(theta: float | None = None):
    s = nc.System.from_urdf(str(ARM), collisions=True)
    if theta is not None:
        s.initial_joints = {"shoulder": theta}
    return s


@pytest.mark.parametrize("contacts", ["nonsmooth", "smooth"])
def test_a_zero_pose_below_the_ground_builds_from_a_clear_posture(contacts):
    with pytest.raises(ModelError, match=r"tip_collision0.*penetrates by 0.15 m"):
        arm().build(contacts=contacts)                       # the zero pose is where this run starts
    model = arm(np.pi / 2).build(contacts=contacts)          # the link horizontal: the tip 0.45 m clear
    g = np.asarray(model.functions["gap"](model.q0, model.p0), float).ravel()
    np.testing.assert_allclose(g, [gap(np.pi / 2)], atol=1e-12)
    assert model.to_joint_space(model.q0, model.v0)[0][0] == pytest.approx(np.pi / 2, abs=1e-12)


@pytest.mark.parametrize("contacts", ["nonsmooth", "smooth"])
def test_an_initial_posture_that_penetrates_is_refused_by_name(contacts):
    with pytest.raises(ModelError, match=rf"'tip_collision0' \(SpherePlane\): the initial configuration "
                                         rf"penetrates by {-gap(0.3):.6g} m"):
        arm(0.3).build(contacts=contacts)
