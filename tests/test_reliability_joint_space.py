"""``to_joint_space`` refuses a state off the constraints (joint angles of it mean nothing),
accepts an integrator's drift, and checks rates against ``A v + Φ_t`` at the given time."""
from __future__ import annotations

import numpy as np
import pytest

import ncgen as nc


@pytest.fixture(scope="module")
def arm():
    s = nc.System("arm2")
    a = s.add_body("a", mass=1.0, inertia=np.diag([0.01, 0.02, 0.02]), position=(0.5, 0, 0))
    b = s.add_body("b", mass=0.7, inertia=np.diag([0.01, 0.02, 0.02]), position=(1.5, 0, 0))
    s.add_joint(nc.Revolute(s.ground, a, at=(0, 0, 0), axis=(0, 1, 0), name="shoulder"))
    s.add_joint(nc.Revolute(a, b, at=(1, 0, 0), axis=(0, 1, 0), name="elbow"))
    return s.build()


def test_off_constraint_states_are_refused(arm):
    q, v = arm.from_joint_space([0.4, -0.3], [0.2, 0.1])
    qj, vj = arm.to_joint_space(q, v)
    np.testing.assert_allclose(qj, [0.4, -0.3], atol=1e-12)
    drift = 1e-7 * np.sin(np.arange(arm.nq))          # an integrator's drift is accepted
    np.testing.assert_allclose(arm.to_joint_space(q + drift), [0.4, -0.3], atol=1e-5)
    with pytest.raises(nc.ModelError, match=r"to_joint_space: q is off the constraints: max \|Φ\(q\)\| = 0\.\d+ m²"):
        arm.to_joint_space(q + 0.3 * np.cos(np.arange(arm.nq)))
    with pytest.raises(nc.ModelError, match=r"to_joint_space: v is off the constraints"):
        arm.to_joint_space(q, v + 0.5 * np.cos(np.arange(arm.nq)))


def test_a_driven_joint_is_checked_at_the_given_time():
    s = nc.System("driven")
    a = s.add_body("a", mass=1.0, inertia=np.diag([0.01, 0.02, 0.02]), position=(0.5, 0, 0))
    s.add_joint(nc.Revolute(s.ground, a, at=(0, 0, 0), axis=(0, 1, 0), name="hinge", drive="2*t"))
    model = s.build()
    traj = nc.simulate(model, 0.5, 0.05)
    k = len(traj.t) - 1
    qj, vj = model.to_joint_space(traj.q[k], traj.v[k], t=traj.t[k])
    assert qj[0] == pytest.approx(2 * traj.t[k], abs=1e-6) and vj[0] == pytest.approx(2.0, abs=1e-6)
    with pytest.raises(nc.ModelError, match="off the constraints"):
        model.to_joint_space(traj.q[k])                # at t0 the drive puts the body elsewhere
