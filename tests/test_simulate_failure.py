"""A failing integration raises SimulationError naming the time and cause and keeps the
trajectory up to that time; the diagnosis recognises singular constraint Jacobians."""
import casadi as ca
import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import NcgenError, SimulationError
from ncgen.runtime import simulate
from ncgen.runtime.dae import load_dae
from ncgen.runtime.diagnose import explain, shift_time

M = 2.0


def blow_up():
    """A point pushed by F = 1/(0.5 − t)² (N): x = (−ln(1 − 2t) − 2t)/M, infinite at t = 0.5 s."""
    s = nc.System("blowup", gravity=(0, 0, 0))
    pt = s.add_point("pt", mass=M, position=(0, 0, 0))
    s.add_force(nc.PointForce(pt, (0, 0, 0), force=lambda t: ca.vertcat(1 / (0.5 - t) ** 2, 0, 0)))
    return s.build()


def test_failure_names_the_time_and_keeps_the_trajectory():
    with pytest.raises(SimulationError) as info:
        simulate(blow_up(), 1.0, 0.01, rtol=1e-10, atol=1e-12)
    e = info.value
    assert isinstance(e, NcgenError)
    assert e.time == pytest.approx(0.49)
    msg = str(e)
    assert "failed between t = 0.49 s and the next output time 0.5 s" in msg
    assert "max_steps" in msg and ".trajectory" in msg
    traj = e.trajectory
    assert not traj.complete and len(traj) == 50 and traj.t[-1] == pytest.approx(0.49)
    assert "INCOMPLETE" in traj.summary() and traj.info["message"] == msg
    t = traj.t                       # the states kept are right: x = (−ln(1 − 2t) − 2t)/M
    exact = (-np.log(1 - 2 * t) - 2 * t) / M
    np.testing.assert_allclose(traj.q[:, 0], exact, rtol=1e-6, atol=1e-12)


def parallelogram():
    """Planar parallelogram four-bar (crank, coupler, rocker) at 30°."""
    s = nc.System("para", gravity=(0, -9.81))
    c, sn = np.cos(np.pi / 6), np.sin(np.pi / 6)
    crank = s.add_bar("crank", mass=1.0, ends=[s.ground.point((0, 0)), (0.5 * c, 0.5 * sn)])
    coupler = s.add_bar("coupler", mass=1.0, ends=[crank.end(1), (1 + 0.5 * c, 0.5 * sn)])
    s.add_bar("rocker", mass=1.0, ends=[s.ground.point((1, 0)), coupler.end(1)])
    return s.build()


def test_diagnosis_of_a_singular_configuration():
    """Flattened parallelogram: all bars on one line, A loses rank; the cause names it."""
    model = parallelogram()
    dae, _ = load_dae(model, "vm")
    q = np.array([0.5, 0.0, 1.5, 0.0])                      # crank.r_j, coupler.r_j on the x axis
    text = explain(model, "IDA_CONV_FAIL", 0.0, q, np.zeros(4), np.zeros(model.nc), np.zeros(0),
                   model.p0, dae)
    assert "Newton iteration failed" in text and "nearly singular" in text
    assert "crank.rigid.uu" in text or "rocker.rigid.uu" in text
    regular = explain(model, "IDA_CONV_FAIL", 0.0, model.q0, np.zeros(4), model.lam0, np.zeros(0),
                      model.p0, dae)
    assert "nearly singular" not in regular


def test_idas_time_is_made_absolute():
    msg, t = shift_time("At t = 0.01 and h = 1e-12, the error test failed repeatedly.", 2.5)
    assert t == pytest.approx(2.51) and msg.startswith("At t = 2.51 and h = 1e-12")
    assert shift_time("no time here", 1.0) == ("no time here", None)


def test_redundant_constraints_kept_cannot_start():
    """build(redundant="keep") with a joint repeating a shared point: the KKT system is
    singular at t0, and the error names the redundant joint."""
    s = nc.System("redundant")
    b1 = s.add_bar("b1", mass=1.0, ends=[s.ground.point((0, 0, 0)), (0, 1.0, 0.0)])
    b2 = s.add_bar("b2", mass=1.0, ends=[b1.end(1), (0, 1.0, -1.0)])
    s.add_joint(nc.Spherical(b1, b2, at=(0, 1.0, 0)))
    model = s.build(redundant="keep", share=False)     # sharing would recognise the joint as implied
    assert model.redundant
    with pytest.raises(SimulationError, match="cannot start.*singular at t0 = 0 s.*spherical_0") as info:
        simulate(model, 1.0, 0.1)
    assert info.value.time == 0.0 and info.value.trajectory is None
