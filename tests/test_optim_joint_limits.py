"""Joint limits as optimal-control bounds: a hinge driven to a new angle at minimum effort,
with a rate limit that the unconstrained optimum would exceed."""
from __future__ import annotations

import numpy as np
import pytest

import ncgen as nc


def hinge():
    s = nc.System("hinge", gravity=(0, -9.81))
    tau = s.add_input("tau")
    bar = s.add_bar("bar", mass=1.0, ends=[(0, 0), (1, 0)])
    j = s.add_joint(nc.Revolute(s.ground, bar, at=(0, 0), name="pivot", effort=tau))
    j.limits = {"lower": -0.1, "upper": 0.35, "velocity": 0.35, "effort": 40.0}
    return s.build()


def solve(limits: bool):
    model = hinge()
    ocp = nc.OptimalControl(model, N=20, t_final=1.0)
    q1, _ = model.from_joint_space([0.3])
    ocp.final(q=q1, v=0)
    ocp.minimize_effort(1.0)
    if limits:
        ocp.joint_limits()
    return model, ocp, ocp.solve()


def test_joint_limits_bound_the_motion():
    model, _, free = solve(False)
    th_free, om_free = (np.array([model.to_joint_space(q, v)[k][0] for q, v in zip(free.q, free.v)])
                        for k in (0, 1))
    assert om_free.max() > 0.4                        # without limits the rate overshoots 0.35
    model, ocp, sol = solve(True)
    assert sol.stats.success
    np.testing.assert_allclose(ocp.u_bounds[:, 0], [-40.0, 40.0])
    qj, vj = zip(*(model.to_joint_space(q, v) for q, v in zip(sol.q, sol.v)))
    th, om = np.concatenate(qj), np.concatenate(vj)
    assert om.max() <= 0.35 + 1e-6 and om.max() > 0.35 - 1e-3   # the rate limit is active
    assert th.min() >= -0.1 - 1e-6 and th.max() <= 0.35 + 1e-6
    assert abs(th[-1] - 0.3) < 1e-6


def test_bound_joint_errors():
    ocp = nc.OptimalControl(hinge(), N=4, t_final=1.0)
    with pytest.raises(nc.NcgenError, match="no joint with coordinates named 'elbow'"):
        ocp.bound_joint("elbow", 0, 1)
    with pytest.raises(nc.NcgenError, match="rate"):
        ocp.bound_joint("pivot", rate=-1.0)


def test_a_joint_range_beyond_pi_is_bounded_continuously():
    """Bounds 2.0 ≤ θ ≤ 3.6 rad (the Panda's joint 6 reaches 3.75 rad): the hinge turns from 2.5
    to 3.4 rad, through π where ``atan2`` jumps by 2π (the natural-coordinate forms measure θ so:
    GGL collocation, the contact-implicit transcription); the bound is measured about the range's
    middle, so the motion is feasible and stays within it (the angle unwrapped from the
    solution's natural coordinates)."""
    from ncgen.optim.nlp import continuous_angle
    for true in np.linspace(2.0, 3.6, 9):                  # the continuous angle is the true one
        wrapped = np.arctan2(np.sin(true), np.cos(true))
        assert float(continuous_angle(wrapped, 2.0, 3.6)) == pytest.approx(true, abs=1e-12)
    model = hinge()
    model.joint_limits["pivot"].update(lower=2.0, upper=3.6)
    q0, _ = model.from_joint_space([2.5])
    q1, _ = model.from_joint_space([3.4])
    ocp = nc.OptimalControl(model, N=20, t_final=1.0, form="ggl")   # angles measured by atan2 of q
    ocp.initial(q=q0, v=0)
    ocp.final(q=q1, v=0)
    ocp.minimize_effort(1.0)
    ocp.bound_joint("pivot", 2.0, 3.6)
    sol = ocp.solve()
    assert sol.stats.success
    th = np.unwrap([model.to_joint_space(q, np.zeros(model.nq))[0][0] for q in sol.q])
    th += 2 * np.pi * np.round((2.5 - th[0]) / (2 * np.pi))
    assert th[0] == pytest.approx(2.5, abs=1e-9) and th[-1] == pytest.approx(3.4, abs=1e-6)
    assert th.min() >= 2.0 - 1e-6 and th.max() <= 3.6 + 1e-6 and th.max() > np.pi
