"""The RATTLE stepper with velocity constraints (``nc.simulate(model, method="stepper")`` on a
model with rolling elements) says how accurate it is, as the compiled stepper does
(:mod:`ncgen.runtime.stepper_checks`): a global error estimate from a shadow run, the energy
drift of a conservative model or the energy balance with the work of inputs, drives and
moving planes, and a run that fails those checks raised; IDAS integrates those works as
quadratures, and the projected Runge–Kutta integrator reports a conservative run's drift.
Against independent references:
the true error against DOPRI5 at rtol 1e-12, the energy drift's second order, and the
closed-form works of a pushed ball, a ball on an accelerating plane and a ball pulled by a
driven distance."""
import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import SimulationError
from test_rolling_driven import ACC, M as M_PULLED, model as pulled_ball   # noqa: F401  (a fixture)
from test_rolling_drives import A_P, M, ball_on_treadmill
from test_rolling_forces import M as M_PUSHED, pushed_ball
from test_rolling_system import disc_toml


@pytest.fixture(scope="module")
def wobbly():
    """A disc tilted by 0.3 rad, spinning at 25 rad/s and wobbling (tests/test_rolling_rattle.py's)."""
    return nc.System.from_toml(disc_toml(0.3, 25.0, 0.0, wobble=1.0)).build()


@pytest.fixture(scope="module")
def dopri_reference(wobbly):
    """DOPRI5 at rtol 1e-12 over 1 s: the true solution for both estimates below."""
    return nc.simulate(wobbly, 1.0, 0.05, method="rolling", rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("substeps", [16, 17])
def test_the_error_estimate_follows_the_true_error(wobbly, dopri_reference, substeps):
    """Over 1 s at h = 3.1 / 2.9 ms (a shadow run with steps of 2h when ``substeps`` is even,
    of h/2 when odd): the estimate in q and v within 0.7–1.4 of the true error against DOPRI5
    at rtol 1e-12 (measured 1.00 and 1.00 for both)."""
    ref = dopri_reference
    tr = nc.simulate(wobbly, 1.0, 0.05, method="stepper", substeps=substeps, backend="compiled", check=False)
    est = tr.info["error_estimate"]
    for key, got, want in (("q", tr.q, ref.q), ("v", tr.v, ref.v)):
        ratio = est[key] / np.max(np.abs(got[-1] - want[-1]))
        assert 0.7 < ratio < 1.4, (key, ratio)
    assert ("2h" if substeps % 2 == 0 else "h/2") in est["how"]
    assert tr.info["energy"]["conservative"]
    off = nc.simulate(wobbly, 0.2, 0.05, method="stepper", substeps=substeps, backend="compiled", estimate=False)
    assert np.isnan(off.info["error_estimate"]["q"])


def test_the_energy_drift_of_a_conservative_model_is_second_order(wobbly):
    """``info["energy"]["drift"]`` is max |E − E(0)| (the exact motion keeps E) and falls by
    4 per halving of h (ratios within 3.5–4.5)."""
    drift = []
    for substeps in (10, 20, 40):
        tr = nc.simulate(wobbly, 0.5, 0.05, method="stepper", substeps=substeps, backend="compiled", check=False)
        report = tr.info["energy"]
        assert report["conservative"]
        assert report["drift"] == pytest.approx(np.max(np.abs(tr.energy - tr.energy[0])), rel=1e-12)
        drift.append(report["drift"])
    ratios = np.array(drift[:-1]) / np.array(drift[1:])
    assert np.all((ratios > 3.5) & (ratios < 4.5)), ratios


def test_a_coarse_run_is_refused_and_says_which_step_to_take(wobbly):
    """h = 12.5 ms on the wobbling disc (true error 0.37 m over 1 s): the check raises at the
    first output whose estimate passes 1 % of the model's size, names ``substeps`` and not
    ``rtol`` (not taken here), and attaches the trajectory before it."""
    with pytest.raises(SimulationError) as e:
        nc.simulate(wobbly, 1.0, 0.05, method="stepper", substeps=4, backend="compiled")
    message = str(e.value)
    assert "not trustworthy: the estimated error in q reached" in message and "substeps=" in message, message
    assert "rtol" not in message, message
    kept = e.value.trajectory
    assert kept is not None and kept.info["complete"] is False and len(kept) >= 1


def test_a_pushed_ball_work_of_its_input():
    """A push P = 6 N (input 3 N scaled by 2): the centre at ½ (5P/(7m)) t², so the input's
    work P x and the kinetic energy gained are (5 P²/(14 m)) t² (to 1e-9 J; the trapezoidal
    rule is exact for the constant force times the linear speed)."""
    tr = nc.simulate(pushed_ball(), 1.0, 0.05, method="stepper", substeps=20, u=lambda t: [3.0], p={"scale": 2.0})
    report = tr.info["energy"]
    assert not report["conservative"]
    m, P = M_PUSHED, 6.0
    want = 5 * P ** 2 / (14 * m) * tr.t ** 2
    np.testing.assert_allclose(report["works"]["inputs"], want, rtol=0, atol=1e-9)
    np.testing.assert_allclose(report["works"]["total"], want, rtol=0, atol=1e-9)
    assert report["balance_error"] < 1e-9


def test_a_ball_on_an_accelerating_plane_work_of_the_plane():
    """The plane's work ``∫ −λᵀĉ dt`` (under "drives") is (1/7) m a_p² t², the energy gained,
    to 1e-9 J."""
    tr = nc.simulate(ball_on_treadmill().build(), 1.0, 0.05, method="stepper", substeps=5, backend="compiled")
    report = tr.info["energy"]
    want = M * A_P ** 2 * tr.t ** 2 / 7
    np.testing.assert_allclose(report["works"]["drives"], want, rtol=0, atol=1e-9)
    np.testing.assert_allclose(tr.energy - tr.energy[0], want, rtol=0, atol=1e-9)
    assert report["balance_error"] < 1e-9 and set(report["parts"]) == {"dampers", "drives"}


def test_a_ball_pulled_by_a_driven_distance_work_of_the_drive(pulled_ball):  # noqa: F811
    """The drive's work ``∫ λᵀΦ_t dt`` is ½ (7/5) m ḋ², ḋ = a t, the energy gained, to 1e-10 J
    at h = 5 ms (a constant pull times a linear speed: the trapezoidal rule is exact;
    measured 1.2e-13 J)."""
    tr = nc.simulate(pulled_ball, 1.0, 0.05, method="stepper", substeps=10)
    want = 0.5 * 1.4 * M_PULLED * (ACC * tr.t) ** 2
    report = tr.info["energy"]
    np.testing.assert_allclose(report["works"]["drives"], want, rtol=0, atol=1e-10)
    assert not report["conservative"] and report["balance_error"] < 1e-10


def test_idas_integrates_the_works_and_the_rolling_integrator_reports_the_drift(wobbly):
    """IDAS (rtol 1e-10) integrates the powers as quadratures: the plane's work on the ball of
    the accelerating plane (1/7) m a_p² t² and the push's work (5 P²/(14 m)) t² to 1e-8 J
    (measured 2.2e-10 and 2.3e-9 J); a conservative run's drift (IDAS and ``method="rolling"``)
    is max |E − E(0)|."""
    tr = nc.simulate(ball_on_treadmill().build(), 1.0, 0.05, method="idas", rtol=1e-10, atol=1e-12)
    report = tr.info["energy"]
    assert not report["conservative"] and report["quadrature"] == "integrated by IDAS as quadratures"
    np.testing.assert_allclose(report["works"]["drives"], M * A_P ** 2 * tr.t ** 2 / 7, rtol=0, atol=1e-8)
    tr = nc.simulate(pushed_ball(), 1.0, 0.05, method="idas", u=lambda t: [3.0], p={"scale": 2.0}, rtol=1e-10,
                     atol=1e-12)
    np.testing.assert_allclose(tr.info["energy"]["works"]["inputs"], 5 * 6.0 ** 2 / (14 * M_PUSHED) * tr.t ** 2,
                               rtol=0, atol=1e-8)
    for method in ("idas", "rolling"):
        tr = nc.simulate(wobbly, 0.5, 0.05, method=method)
        report = tr.info["energy"]
        assert report["conservative"] and report["drift"] == np.max(np.abs(tr.energy - tr.energy[0])), method
        assert "energy (conservative" in tr.summary()
