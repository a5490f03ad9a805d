"""Velocity-level helpers on models with rolling elements: ``nc.project_velocity`` keeps the
rolling rows ``B(q) v = c(q, t)`` (and the heights), ``nc.assemble`` the heights, and
``nc.dof_report`` counts the velocity degrees of freedom ``nq − rank Â``.

References: the contact point's material velocity computed here from the body's pose
(``ṗ + Ṙ ℓ``, by differencing the pose, linear in the natural coordinates), the least-change
projection by a KKT system solved here, the disc's height ``ρ cos β`` at the tilt ``β``,
and the degrees of freedom counted by hand."""
import numpy as np
import pytest

import ncgen as nc

RHO, BETA = 0.1, 0.3


def _disc(**velocity):
    s = nc.System("disc", gravity=(0.0, 0.0, -9.81))
    s.add_body("disc", mass=1.2, inertia=np.diag([0.003, 0.006, 0.003]), position=(0.0, 0.0, RHO), **velocity)
    s.add_rolling(nc.RollingDisc("disc", radius=RHO, axle=(0.0, 1.0, 0.0)))
    return s


def _tilted_q(height: float) -> np.ndarray:
    """The disc's natural coordinates ``[p, u, v, w]`` leaning by ``BETA`` about x (axle
    ``(0, cos β, sin β)``), its centre at ``height``."""
    c, s = np.cos(BETA), np.sin(BETA)
    R = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    return np.concatenate([[0.0, 0.0, height], R[:, 0], R[:, 1], R[:, 2]])


def _contact_velocity(model, q, v, eps: float = 1e-3) -> np.ndarray:
    """World velocity of the disc's material point at its lowest point, from the pose:
    ``P = p − ρ d/|d|``, ``ℓ = Rᵀ(P − p)`` held, ``v_P = d/dε [p + R ℓ](q + ε v)``."""
    def pose(x):
        R, p = model.functions["poses"](x)
        return np.asarray(R)[:, :3], np.asarray(p)[:, 0]
    R, p = pose(q)
    a = R[:, 1]
    d = np.array([0.0, 0.0, 1.0]) - a[2] * a
    ell = R.T @ (-RHO * d / np.linalg.norm(d))
    moved = [Rx @ ell + px for Rx, px in (pose(q + eps * v), pose(q - eps * v))]
    return (moved[0] - moved[1]) / (2 * eps)


@pytest.fixture(scope="module")
def disc():
    return _disc().build()


def test_assemble_puts_the_disc_on_the_plane(disc):
    q = nc.assemble(disc, _tilted_q(0.13), fix=["disc.u", "disc.v", "disc.w", "disc.r_i.x", "disc.r_i.y"])
    assert q[2] == pytest.approx(RHO * np.cos(BETA), abs=1e-13)


def test_projected_velocity_rolls_and_is_the_least_change(disc):
    q = nc.assemble(disc, _tilted_q(RHO * np.cos(BETA)))
    rng = np.random.default_rng(42)
    v_bar = rng.normal(size=disc.nq)
    v = nc.project_velocity(disc, q, v_bar)
    v_P = _contact_velocity(disc, q, v)
    assert np.abs(v_P[:2]).max() < 1e-12                       # rolling: no slip along the plane
    assert abs(v_P[2]) < 1e-12                                   # the height's rate
    assert np.abs(disc.A(q) @ v).max() < 1e-12                   # the body stays rigid
    from ncgen.assembly.nonholonomic import rolling_system
    A_hat = np.asarray(rolling_system(disc).A(q))
    n, m = disc.nq, A_hat.shape[0]
    K = np.block([[disc.M, A_hat.T], [A_hat, np.zeros((m, m))]])
    w = np.linalg.solve(K, np.concatenate([disc.M @ v_bar, np.zeros(m)]))[:n]
    assert np.abs(v - w).max() < 1e-12 * max(1.0, np.abs(w).max())
    assert np.abs(_contact_velocity(disc, q, v_bar)[:2]).max() > 1e-2   # the projection had work to do


def test_projected_velocity_with_a_rate_set(disc):
    q = nc.assemble(disc, _tilted_q(RHO * np.cos(BETA)))
    v = nc.project_velocity(disc, q, np.zeros(disc.nq), values={"disc.r_i.x": 0.4})
    assert v[0] == 0.4
    assert np.abs(_contact_velocity(disc, q, v)).max() < 1e-12
    assert np.linalg.norm(v[3:]) > 0.1                           # it rolls: the frame turns


def test_build_projects_initial_rates_onto_the_rolling_rows():
    s = _disc(velocity=(0.5, 0.0, 0.0), angular_velocity=(0.0, 1.0, 0.0))
    s.initial_coordinate_rates = {"disc.r_i.x": 0.3}
    model = s.build()
    assert model.v0[0] == pytest.approx(0.3, abs=1e-14)
    v_P = _contact_velocity(model, model.q0, model.v0)
    assert np.abs(v_P).max() < 1e-12
    # rolling upright along x at 0.3 m/s: spin ω_y = 0.3/ρ, so u̇ = ω × u = (0, 0, −3)
    assert model.v0[3:6] == pytest.approx([0.0, 0.0, -0.3 / RHO], abs=1e-12)


def _ball():
    s = nc.System("ball", gravity=(0.0, 0.0, -9.81))
    s.add_body("ball", mass=1.0, inertia=0.004 * np.eye(3), position=(0, 0, 0.1))
    s.add_rolling(nc.RollingSphere("ball", radius=0.1))
    return s.build()


def _sleigh():
    s = nc.System("sleigh", gravity=(0.0, 0.0, -9.81))
    body = s.add_body("sleigh", mass=2.0, inertia=np.diag([0.02, 0.04, 0.05]), position=(0, 0, 0.1))
    s.add_joint(nc.Planar(s.ground, body, at=(0, 0, 0.1), normal=(0, 0, 1)))
    s.add_rolling(nc.KnifeEdge(body, at=(-0.3, 0, 0), blade=(1, 0, 0)))
    return s.build()


@pytest.mark.parametrize("make, dof, velocity_dof, heights, rows", [
    # a free body has 6 DOF; the height leaves 5 (x, y, heading, tilt, spin), the two
    # no-slip rows 3 velocities (spin, tilt rate, heading rate)
    (lambda: _disc().build(), 5, 3, 1, 2),
    # a ball: 5 (x, y and three angles), no slip leaves its three angular velocities
    (_ball, 5, 3, 1, 2),
    # the Chaplygin sleigh: planar (x, y, heading), the blade leaves 2 (speed along it, turning)
    (_sleigh, 3, 2, 0, 1),
])
def test_dof_counts(make, dof, velocity_dof, heights, rows):
    report = nc.dof_report(make())
    assert (report.dof, report.velocity_dof) == (dof, velocity_dof)
    assert (len(report.heights), len(report.rolling)) == (heights, rows)
    assert report.dependent == []
    assert f"velocity DOF = {velocity_dof}" in str(report)


def test_dof_report_without_rolling_unchanged():
    s = nc.System("free", gravity=(0.0, 0.0, -9.81))
    s.add_body("b", mass=1.0, inertia=np.eye(3), position=(0, 0, 0.1))
    report = nc.dof_report(s.build())
    assert (report.dof, report.velocity_dof, report.rolling, report.heights) == (6, 6, [], [])
    assert "rolling" not in str(report)


def test_projected_velocity_on_a_moving_plane():
    """A ball on a plane moving at ``w(t) = (0.5 t, 0)``: at ``t = 2 s`` its contact point
    moves with the plane, ``(1, 0, 0)`` m/s."""
    s = nc.System("treadmill", gravity=(0.0, 0.0, -9.81))
    s.add_body("ball", mass=1.0, inertia=0.004 * np.eye(3), position=(0, 0, 0.1))
    s.add_rolling(nc.RollingSphere("ball", radius=0.1, plane_velocity=("0.5*t", 0.0)))
    model = s.build()
    v = nc.project_velocity(model, model.q0, np.zeros(model.nq), t=2.0)
    eps, ell = 1e-3, np.array([0.0, 0.0, -0.1])
    ends = []
    for x in (model.q0 + eps * v, model.q0 - eps * v):
        R, p = model.functions["poses"](x)
        ends.append(np.asarray(R)[:, :3] @ ell + np.asarray(p)[:, 0])
    assert (ends[0] - ends[1]) / (2 * eps) == pytest.approx([1.0, 0.0, 0.0], abs=1e-12)


def test_reports_show_the_velocity_dof():
    """``ncgen check``'s report, the notebook's model table and the model's repr tell a
    rolling model's degrees of freedom from the model's own constraints'."""
    from ncgen.assembly.check import check_system
    from ncgen.viz.notebook import model_table
    system = _disc()
    text = check_system(system).render()
    assert "rank A = 7, DOF = 5" in text and "velocity DOF = 3" in text
    table = model_table(system.build())
    assert "<th style='text-align:left'>velocity degrees of freedom</th><td style='text-align:left'>3</td>" in table
    assert "<th style='text-align:left'>degrees of freedom</th><td style='text-align:left'>5</td>" in table
    assert "rolling elements=1 (nc.dof_report)" in repr(system.build())
