"""Coordinates as written keep resolving after coordinate sharing re-bases their member:
``model.coordinate`` and ``traj.coordinate`` give the value of the unshared coordinate
(checked against a ``share=False`` run of the same system and against the body's geometry);
unknown names and optimal-control targets on re-based names say what to use."""
from __future__ import annotations

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import OptimizationError


def arm():
    s = nc.System("arm")
    up = s.add_body("upper", mass=1.0, inertia=np.diag([0.01, 0.02, 0.02]), position=(0.5, 0, 0))
    lo = s.add_body("lower", mass=1.0, inertia=np.diag([0.01, 0.02, 0.02]), position=(1.5, 0, 0))
    s.add_joint(nc.Revolute(s.ground, up, at=(0, 0, 0), axis=(0, 1, 0), name="shoulder"))
    s.add_joint(nc.Spherical(up, lo, at=(1, 0, 0), name="elbow"))
    return s


def test_names_as_written_resolve_after_sharing():
    shared, written = arm().build(), arm().build(share=False)
    assert "upper.r_i.x" not in shared.coordinate_names and "upper.r_i.x" in written.coordinate_names
    b = nc.simulate(written, 0.6, 0.05, rtol=1e-10, atol=1e-10)
    a = nc.simulate(shared, 0.6, 0.05, rtol=1e-10, atol=1e-10)
    for name in ("upper.r_i.x", "upper.r_i.z", "upper.u.z", "upper.w.x", "lower.r_i.y", "lower.v.z"):
        x, xd = a.coordinate(name)
        i = written.coordinate_names.index(name)
        np.testing.assert_allclose(x, b.q[:, i], atol=1e-6)
        np.testing.assert_allclose(xd, b.v[:, i], atol=1e-5)
    # the body's centre of mass is its r_i as written (position=...): check against the pose
    R, p = shared.poses(a.q[-1])
    s, c = shared.coordinate("upper.r_i.x")
    assert s @ a.q[-1] + c == pytest.approx(p[shared.member_names.index("upper")][0], abs=1e-12)
    # names of the shared model resolve as themselves
    s, c = shared.coordinate(shared.coordinate_names[3])
    assert s[3] == 1.0 and s.sum() == 1.0 and c == 0.0


def test_unknown_names_and_ocp_targets_on_rebased_names_are_explained():
    shared = arm().build()
    with pytest.raises(nc.ModelError, match=r"no coordinate named 'upper\.r_k\.x'.*coordinates as written"):
        shared.coordinate("upper.r_k.x")
    ocp = nc.OptimalControl(shared, N=4, t_final=0.5)
    with pytest.raises(OptimizationError, match=r"'upper\.r_i\.x' is one as written that coordinate sharing re-based"):
        ocp.bound_coordinate("upper.r_i.x", -1, 1)
