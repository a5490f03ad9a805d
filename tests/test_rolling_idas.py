"""IDAS on models with nonholonomic elements (``nc.simulate(model, method="idas")``,
ncgen/runtime/rolling_idas.py, the DAE of ncgen/assembly/rolling_dae.py) against closed forms:
the rolling disc's steady precession, energy conservation, the Chaplygin sleigh's decay, a
ball on an accelerating plane and a pushed ball; against the projected Runge–Kutta integrator
(``method="rolling"``) on the same run; the issue's target (10 s at rtol 1e-8, both constraint
levels within 1e-10); what it refuses, by name."""
import numpy as np
import pytest

import ncgen as nc
from ncgen.assembly.rolling_dae import rolling_dae
from ncgen.assembly.nonholonomic import rolling_system
from ncgen.errors import NcgenError
from test_rolling import g, steady_precession
from test_rolling_drives import A_P, M, R, ball_on_treadmill
from test_rolling_forces import multipliers, pushed_ball
from test_rolling_system import BETA, W3, disc_toml


@pytest.fixture(scope="module")
def model():
    return nc.System.from_toml(disc_toml()).build()


def axle(model, q):
    return q[:, model.layout.member_indices("disc")[6:9]]


def test_steady_precession_rate_and_multipliers(model):
    """The tilted disc precesses at the closed-form rate (1e-7) with its tilt kept (1e-8 rad);
    the contact carries m g; both constraint levels hold to round-off at the outputs."""
    tr = nc.simulate(model, 2.0, 0.05, method="idas", rtol=1e-10, atol=1e-12)
    assert tr.info["method"] == "idas" and tr.info["rolling_names"] == ["disc.rolling"]
    k = axle(model, tr.q)
    assert np.max(np.abs(np.arcsin(k[:, 2]) - BETA)) < 1e-8
    heading = np.unwrap(np.arctan2(-k[:, 0], k[:, 1]))
    assert abs(np.polyfit(tr.t, heading, 1)[0] / steady_precession(BETA, W3) - 1) < 1e-7
    assert max(tr.constraint_residual.max(), tr.velocity_residual.max()) < 1e-12
    assert tr.constraint_names[model.nc:] == ["disc.rolling.height", "disc.rolling.x", "disc.rolling.y"]
    np.testing.assert_allclose(-tr.lam[:, model.nc], 1.0 * g, rtol=1e-9)


@pytest.mark.slow      # IDAS at 1e-10 and DOPRI5 at 1e-12 on a second model; fast:
#                       test_steady_precession_rate_and_multipliers,
#                       test_the_dae_residual_vanishes_on_the_exact_accelerations
def test_energy_kept_and_the_same_motion_as_the_rolling_integrator():
    """A wobbling disc (no steady motion): IDAS at rtol 1e-10 keeps the energy to 1e-8 of
    itself and follows the projected DOPRI5 run (rtol 1e-12) to 1e-7."""
    wobbly = nc.System.from_toml(disc_toml(0.3, 25.0, 0.0, wobble=1.0)).build()
    tr = nc.simulate(wobbly, 1.0, 0.02, method="idas", rtol=1e-10, atol=1e-12)
    ref = nc.simulate(wobbly, 1.0, 0.02, method="rolling", rtol=1e-12, atol=1e-14)
    assert np.ptp(np.arcsin(axle(wobbly, tr.q)[:, 2])) > 0.01          # it does wobble
    assert np.ptp(tr.energy) <= 1e-8 * np.max(np.abs(tr.energy))
    assert np.max(np.abs(tr.q - ref.q)) < 1e-7 and np.max(np.abs(tr.v - ref.v)) < 1e-6
    np.testing.assert_allclose(tr.lam, ref.lam, rtol=0, atol=1e-5)


def test_ten_seconds_at_rtol_1e_8(model):
    """The issue's target: 10 s of the precessing disc at rtol 1e-8, atol 1e-10: both
    constraint levels within 1e-10 at every output (measured 1.2e-13 and 1.1e-14; IDAS's own
    states drift to 2.8e-6 before the outputs' projection, ``info["stats"]["drift"]``); the
    energy within 1e-5 of itself (measured 4.5e-6) and the precession rate within 1e-5
    (measured 2.2e-6)."""
    tr = nc.simulate(model, 10.0, 0.05, method="idas", rtol=1e-8, atol=1e-10)
    assert tr.constraint_residual.max() <= 1e-10 and tr.velocity_residual.max() <= 1e-10
    assert 0 < tr.info["stats"]["drift"] < 1e-4
    assert np.ptp(tr.energy) <= 1e-5 * np.max(np.abs(tr.energy))
    heading = np.unwrap(np.arctan2(-axle(model, tr.q)[:, 0], axle(model, tr.q)[:, 1]))
    assert abs(np.polyfit(tr.t, heading, 1)[0] / steady_precession(BETA, W3) - 1) < 1e-5


def test_chaplygin_sleigh_velocity_decay():
    """The sleigh of tests/test_rolling.py (a knife edge behind the centre of mass, kept on
    the plane by a planar joint: holonomic and nonholonomic rows together) against its closed
    form, to 1e-7."""
    ms, Izz, b, u0, w0 = 2.0, 0.05, 0.3, 0.2, 1.5
    s = nc.System("sleigh", gravity=(0.0, 0.0, -g))
    body = s.add_body("sleigh", mass=ms, inertia=np.diag([0.02, 0.04, Izz]), position=(0.0, 0.0, 0.1),
                      velocity=(u0, b * w0, 0.0), angular_velocity=(0.0, 0.0, w0))
    s.add_joint(nc.Planar(s.ground, body, at=(0.0, 0.0, 0.1), normal=(0.0, 0.0, 1.0)))
    s.add_rolling(nc.KnifeEdge(body, at=(-b, 0.0, 0.0), blade=(1.0, 0.0, 0.0)))
    model = s.build()
    tr = nc.simulate(model, 3.0, 0.05, method="idas", rtol=1e-10, atol=1e-12)
    idx = model.layout.member_indices("sleigh")
    x, xd = tr.q[:, idx[3:6]], tr.v[:, idx[3:6]]
    w = x[:, 0] * xd[:, 1] - x[:, 1] * xd[:, 0]
    u = np.sum(tr.v[:, idx[0:3]] * x, axis=1)
    J = Izz + ms * b * b
    u_inf = np.sqrt(u0 ** 2 + J * w0 ** 2 / ms)
    arg = ms * b * u_inf * tr.t / J + np.arctanh(u0 / u_inf)
    np.testing.assert_allclose(u, u_inf * np.tanh(arg), atol=1e-7)
    np.testing.assert_allclose(w, np.sqrt(ms / J) * u_inf / np.cosh(arg), atol=1e-7)
    assert abs(w[-1]) < 0.1 * w0 and max(tr.constraint_residual.max(), tr.velocity_residual.max()) < 1e-12
    assert np.ptp(tr.energy) < 1e-8


def test_a_ball_on_an_accelerating_plane():
    """The moving plane (``B v = c(t)``): centre at (1/7) a_p t², friction (2/7) m a_p,
    normal force m g (closed form of tests/test_rolling_drives.py)."""
    model = ball_on_treadmill().build()
    tr = nc.simulate(model, 1.0, 0.05, method="idas", rtol=1e-10, atol=1e-12)
    x = tr.point("ball", (0, 0, 0))
    np.testing.assert_allclose(x[:, 0], A_P * tr.t ** 2 / 7, rtol=0, atol=1e-9)
    normal, fx, fy = multipliers(tr)
    np.testing.assert_allclose(normal, M * 9.81, rtol=1e-10)
    np.testing.assert_allclose(fx, 2 * M * A_P / 7, rtol=1e-8)
    assert tr.velocity_residual.max() < 1e-12


def test_a_pushed_ball_with_an_input_and_a_parameter():
    """An input P = 3 N scaled by the parameter 2: the centre at ½ 5P/(7m) t², friction −2P/7."""
    model = pushed_ball()
    tr = nc.simulate(model, 1.0, 0.05, method="idas", u=lambda t: [3.0], p={"scale": 2.0}, rtol=1e-10, atol=1e-12)
    P = 6.0
    np.testing.assert_allclose(tr.point("ball", (0, 0, 0))[:, 0], 0.5 * 5 * P / (7 * 2.0) * tr.t ** 2,
                               rtol=0, atol=1e-9)
    normal, fx, _ = multipliers(tr)
    np.testing.assert_allclose(fx, -2 * P / 7, rtol=0, atol=1e-8)


def test_the_dae_residual_vanishes_on_the_exact_accelerations(model):
    """The DAE's algebraic part is zero at the KKT accelerations and multipliers of the
    rolling system (an independent solve: ``accel_t``) and its ode is ``[v; a]``."""
    rs = rolling_system(model)
    dae = rolling_dae(rs)
    q, v = model.q0, model.v0
    a, lam = (np.asarray(x).ravel() for x in rs.accel_t(q, v, np.zeros(model.nq), 0.3))
    ode, alg = dae(0.3, np.concatenate([q, v]), np.concatenate([a, lam]), np.zeros(model.nu), model.p0)
    assert np.max(np.abs(np.asarray(alg))) < 1e-11
    np.testing.assert_allclose(np.asarray(ode).ravel(), np.concatenate([v, a]), rtol=0, atol=1e-14)


def test_refusals_are_named(model):
    with pytest.raises(NcgenError, match="method='idas': model 'rolling_disc' has rolling elements: "
                                         "joint_dynamics=True is not taken"):
        nc.simulate(model, 0.1, 0.05, method="idas", joint_dynamics=True)
    with pytest.raises(NcgenError, match="backend='compiled' is not taken"):
        nc.simulate(model, 0.1, 0.05, method="idas", backend="compiled")
    with pytest.raises(NcgenError, match="project=True is not taken"):
        nc.simulate(model, 0.1, 0.05, method="idas", project=True)
    with pytest.raises(NcgenError, match="feedback and controllers are not taken"):
        nc.simulate(pushed_ball(), 0.1, 0.05, method="idas", u=lambda t, q, v: [1.0])
