"""nc.simulate against closed-form solutions: pendulum periods, energy conservation,
constraint drift, inputs, parameters and initial states."""
import casadi as ca
import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import NcgenError
from ncgen.runtime import Trajectory, simulate

G = 9.81


def pendulum(dim: int, angle: float, L: float = 0.8, m: float = 1.3) -> nc.Model:
    """A uniform bar pinned at one end to the ground, ``angle`` (rad) from the downward vertical."""
    if dim == 2:
        s = nc.System(f"pend{dim}", gravity=(0, -G))
        ends = [s.ground.point((0, 0)), (L * np.sin(angle), -L * np.cos(angle))]
    else:
        s = nc.System(f"pend{dim}", gravity=(0, 0, -G))
        ends = [s.ground.point((0, 0, 0)), (L * np.sin(angle), 0.0, -L * np.cos(angle))]
    b = s.add_bar("b", mass=m, ends=ends)
    b.add_marker("tip", (L / 2,) + (0.0,) * (dim - 1))
    return s.build()


def crossing_times(t, x):
    """Times where x crosses zero upwards (linear interpolation)."""
    i = np.flatnonzero((x[:-1] < 0) & (x[1:] >= 0))
    return t[i] - x[i] * (t[i + 1] - t[i]) / (x[i + 1] - x[i])


@pytest.mark.parametrize("dim", [2, 3])
def test_small_angle_period(dim):
    """Compound pendulum: T = 2π √(I/(m g d)), I = m L²/3 about the pivot, d = L/2; the
    amplitude (1°) changes the period by (1 + θ0²/16) ≈ 1 + 2e-5."""
    L, m, theta0 = 0.8, 1.3, np.deg2rad(1.0)
    model = pendulum(dim, theta0, L, m)
    traj = simulate(model, 6.0, 1e-3, rtol=1e-10, atol=1e-12)
    x = traj.marker("b.tip")[:, 0]
    periods = np.diff(crossing_times(traj.t, x))
    T = 2 * np.pi * np.sqrt((m * L**2 / 3) / (m * G * L / 2)) * (1 + theta0**2 / 16)
    assert len(periods) >= 2
    np.testing.assert_allclose(periods, T, rtol=2e-6)


def double_pendulum() -> nc.Model:
    """Two rr bars sharing a point, the first pinned to the ground: a chaotic 3D double pendulum."""
    s = nc.System("double")
    b1 = s.add_bar("b1", mass=1.0, ends=[s.ground.point((0, 0, 0)), (0.6, 0.2, 0.3)])
    ri, rj, w = np.array([0.6, 0.2, 0.3]), np.array([1.1, -0.3, 0.5]), np.array([0.0, 1.0, 2.0])
    b2 = s.add_bar("b2", mass=0.7, ends=[b1.end(1), rj], angular_velocity=w,
                   velocity=np.cross(w, (rj - ri) / 2))         # spinning about its shared end
    b2.add_marker("tip", (b2.rigid.Xbar[0, 0] / 2, 0, 0))
    return s.build()


def test_energy_and_constraints_conserved():
    """Conservative chaotic system, 20 s at rtol 1e-10 (speeds up to 11 m/s): relative energy
    drift < 1e-6 (measured 5e-8), |Φ| < 1e-7 m² and |A v| < 1e-6 m²/s (measured 1.4e-8, 7e-8)."""
    traj = simulate(double_pendulum(), 20.0, 0.01, rtol=1e-10, atol=1e-12)
    assert traj.complete and traj.t[-1] == 20.0 and len(traj) == 2001
    assert traj.energy_drift / traj.energy_scale < 1e-6
    assert np.max(traj.constraint_residual) < 1e-7
    assert np.max(traj.velocity_residual) < 1e-6
    assert np.ptp(traj.kinetic) > 1.0          # it really moves
    np.testing.assert_allclose(traj.energy, traj.kinetic + traj.potential)


def test_default_tolerances_bound_the_drift():
    traj = simulate(double_pendulum(), 5.0, 0.01)
    assert traj.energy_drift / traj.energy_scale < 1e-4
    assert np.max(traj.constraint_residual) < 1e-6


def test_initial_state_from_q0_and_parameters_of_the_model():
    """q0 of a 1° pendulum given to a model built at 30°: the period is the 1° one; the
    state is made consistent (λ0 from the KKT system) and the energy conserved."""
    L, m, theta0 = 0.8, 1.3, np.deg2rad(1.0)
    small = pendulum(3, theta0, L, m)
    big = pendulum(3, np.deg2rad(30.0), L, m)
    q0 = small.q0 * (1 + 1e-9)                     # slightly off the constraint: projected
    traj = simulate(big, 3.0, 1e-3, q0=q0, v0=np.zeros(3), rtol=1e-10, atol=1e-12)
    # Newton from 1e-9 off converges quadratically to round-off (|Φ| ~ 1e-16 for unit-size
    # bars, whatever the CPU); 1e-14 is 100× that, tighter than Newton's stopping bound
    # (1e-13 · size², met after one more iteration), so it checks that the projection converged
    assert traj.constraint_residual[0] < 1e-14
    np.testing.assert_allclose(traj.lam[0], small.lam0, rtol=1e-6)
    periods = np.diff(crossing_times(traj.t, traj.marker("b.tip")[:, 0]))
    T = 2 * np.pi * np.sqrt(2 * L / (3 * G)) * (1 + theta0**2 / 16)
    np.testing.assert_allclose(periods, T, rtol=2e-6)


def test_bad_initial_state_is_an_error():
    model = pendulum(3, 0.3)
    with pytest.raises(nc.ModelError, match="initial state"):
        simulate(model, 1.0, 0.1, q0=model.q0 * 1.5)
    with pytest.raises(NcgenError, match="q0"):
        simulate(model, 1.0, 0.1, q0=[1.0, 2.0])


# --------------------------------------------------------------------------- inputs
def pushed_point(m: float = 2.0):
    s = nc.System("pushed", gravity=(0, 0, 0))
    pt = s.add_point("pt", mass=m, position=(0.1, 0.0, 0.0), velocity=(0.0, 0.3, 0.0))
    u = s.add_input("push", 3)
    s.add_force(nc.PointForce(pt, (0, 0, 0), force=u))
    return s.build()


def test_constant_input_force():
    """x(t) = x0 + v0 t + F t² / 2m, for the input as a callable and as samples."""
    m, F = 2.0, np.array([3.0, -1.0, 0.5])
    model = pushed_point(m)
    expected = lambda t: (np.array([0.1, 0, 0]) + np.outer(t, [0, 0.3, 0]) + np.outer(t**2, F / (2 * m)))
    by_callable = simulate(model, 1.5, 0.05, u=lambda t: F, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(by_callable.q, expected(by_callable.t), atol=1e-9)
    samples = np.tile(F, (len(by_callable.t), 1))
    by_samples = simulate(model, 1.5, 0.05, u=samples, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(by_samples.q, by_callable.q, atol=1e-12)
    np.testing.assert_allclose(by_samples.u, samples)


def test_ramp_input_holds():
    """u = c t: a linear hold reproduces x = c t³/6m exactly; a zero-order hold applies
    c t_k on [t_k, t_k+1), whose exact response is known in closed form too."""
    m, c, h = 2.0, 4.0, 0.1
    model = pushed_point(m)
    ramp = lambda t: [c * t, 0.0, 0.0]
    lin = simulate(model, 1.0, h, u=ramp, hold="linear", rtol=1e-10, atol=1e-12)
    t = lin.t
    np.testing.assert_allclose(lin.q[:, 0], 0.1 + c * t**3 / (6 * m), atol=1e-10)
    zoh = simulate(model, 1.0, h, u=ramp, hold="zoh", rtol=1e-10, atol=1e-12)
    a = c * t[:-1] / m                                       # acceleration on each interval
    v = np.concatenate([[0.0], np.cumsum(a * h)])
    x = 0.1 + np.concatenate([[0.0], np.cumsum(v[:-1] * h + a * h**2 / 2)])
    np.testing.assert_allclose(zoh.q[:, 0], x, atol=1e-10)
    assert np.max(np.abs(zoh.q[:, 0] - lin.q[:, 0])) > 1e-3


@pytest.mark.parametrize("u, match", [
    (np.zeros((3, 3)), "expected samples of shape"),
    (lambda t: [1.0, 2.0], "returned 2 value"),
    (lambda t: [np.nan, 0, 0], "non-finite input"),
])
def test_bad_inputs(u, match):
    with pytest.raises(NcgenError, match=match):
        simulate(pushed_point(), 1.0, 0.1, u=u)


def test_parameters_change_the_physics():
    """Mass on a linear spring of stiffness parameter k: period 2π √(m/k), by array or by name."""
    s = nc.System("osc", gravity=(0, 0, 0))
    m = 0.5
    pt = s.add_point("pt", mass=m, position=(1.2, 0.0, 0.0))
    k = s.add_parameter("k", 20.0)
    s.add_force(nc.Spring(s.ground, (0, 0, 0), pt, (0, 0, 0), k=k, rest_length=1.0))
    model = s.build()
    for p, kval in ((None, 20.0), ({"k": 80.0}, 80.0), ([5.0], 5.0)):
        traj = simulate(model, 6.0, 1e-3, p=p, rtol=1e-10, atol=1e-12)
        periods = np.diff(crossing_times(traj.t, traj.q[:, 0] - 1.0))
        np.testing.assert_allclose(periods, 2 * np.pi * np.sqrt(m / kval), rtol=1e-6)
        np.testing.assert_array_equal(traj.p, [kval])
    with pytest.raises(NcgenError, match="unknown parameter"):
        simulate(model, 1.0, 0.1, p={"stiffness": 1.0})


# ---------------------------------------------------------------------- arguments
def test_grid_ends_at_t_end():
    traj = simulate(pushed_point(), 1.0, 0.3)
    np.testing.assert_allclose(traj.t, np.linspace(0, 1, 5))
    assert isinstance(traj, Trajectory)


@pytest.mark.parametrize("kwargs, match", [
    ({"dt": 0.0}, "dt"), ({"t_end": -1.0}, "t_end"), ({"method": "euler"}, "method"),
    ({"backend": "gpu"}, "backend"), ({"rtol": -1.0}, "rtol"), ({"hold": "cubic"}, "hold"),
])
def test_bad_arguments(kwargs, match):
    args = {"t_end": 1.0, "dt": 0.1, **kwargs}
    with pytest.raises(NcgenError, match=match):
        simulate(pushed_point(), **args)


def test_progress_bar(capsys):
    simulate(pushed_point(), 1.0, 0.01, progress=True)
    err = capsys.readouterr().err
    assert "simulating pushed:" in err and err.endswith("\r")     # shown, then cleared (ncgen.progress)
    simulate(pushed_point(), 1.0, 0.01)                 # auto: stderr is not a terminal here
    assert capsys.readouterr().err == ""


def test_casadi_force_of_time():
    """A force given as a function of t (CasADi expression): F = sin(t) gives
    x = x0 + v0 t + (t − sin t)/m."""
    s = nc.System("sine", gravity=(0, 0, 0))
    pt = s.add_point("pt", mass=2.0, position=(0, 0, 0))
    s.add_force(nc.PointForce(pt, (0, 0, 0), force=lambda t: ca.vertcat(ca.sin(t), 0, 0)))
    traj = simulate(s.build(), 3.0, 0.1, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(traj.q[:, 0], (traj.t - np.sin(traj.t)) / 2.0, atol=1e-9)


def test_driven_coordinate_started_at_another_time():
    """x of a falling point prescribed as 0.3 sin 2t (a rheonomic constraint), started at
    t0 = 0.5 s: x and ẋ follow the drive, y falls freely, λ = −m ẍ; the model's state (built
    for t = 0) is only a guess there, hence ic_tolerance=None."""
    s = nc.System("driven", gravity=(0, -G))
    pt = s.add_point("pt", mass=1.5, position=(0.0, 1.0))
    s.add_joint(nc.CoordinateDriver(pt, "r_i", "x", value=lambda t: 0.3 * ca.sin(2 * t)))
    model = s.build()
    with pytest.raises(nc.ModelError, match="ic_tolerance=None"):
        simulate(model, 2.0, 0.1, t0=0.5)
    traj = simulate(model, 2.0, 0.1, t0=0.5, rtol=1e-10, atol=1e-12, ic_tolerance=None)
    t = traj.t
    assert t[0] == 0.5
    np.testing.assert_allclose(traj.q[:, 0], 0.3 * np.sin(2 * t), atol=1e-9)
    np.testing.assert_allclose(traj.v[:, 0], 0.6 * np.cos(2 * t), atol=1e-8)
    np.testing.assert_allclose(traj.q[:, 1], 1.0 - G * (t - 0.5) ** 2 / 2, atol=1e-7)
    np.testing.assert_allclose(traj.lam[:, 0], 1.5 * 1.2 * np.sin(2 * t), atol=1e-6)
