"""The stepper's accuracy: error estimates against the true error (IDAS at tight
tolerance), error control (``rtol``) on a chain, a stiff-spring pendulum and a fast-spinning
chain, checks that make untrustworthy fixed-step runs fail loudly, the energy balance of
non-conservative models, and the derived quantities computed in C."""
from __future__ import annotations

import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import AccuracyWarning, SimulationError
from ncgen.runtime import outputs
from ncgen.runtime.stepper_checks import ERROR_FRACTION, is_conservative

ROOT = Path(__file__).resolve().parent.parent
pytestmark = pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None,
                                reason="no C compiler")


def chain(n: int = 3, name: str = "acc_chain"):
    """n bars of 1 m and 1 kg sharing ends, a horizontal staircase fixed at the origin."""
    s = nc.System(f"{name}{n}", gravity=(0.0, 0.0, -9.81))
    start = s.ground.point((0.0, 0.0, 0.0))
    corner = np.zeros(3)
    for k in range(n):
        corner = corner + (np.array([1.0, 0.0, 0.0]) if k % 2 == 0 else np.array([0.0, 1.0, 0.0]))
        start = s.add_bar(f"b{k}", "rr", mass=1.0, ends=[start, tuple(corner)]).end(1)
    return s.build()


def stiff_pendulum(k: float = 1e4):
    """A bar pendulum (1 m, 1 kg) with a 0.5 kg point mass on a stiff spring at its tip
    (k = 1e4 N/m: 140 rad/s against the pendulum's 5 rad/s)."""
    s = nc.System("stiff_pendulum", gravity=(0.0, 0.0, -9.81))
    bar = s.add_bar("bar", "rr", mass=1.0, ends=[s.ground.point((0.0, 0.0, 0.0)), (1.0, 0.0, 0.0)])
    mass = s.add_point("mass", mass=0.5, position=(1.25, 0.0, 0.0), velocity=(0.0, 0.0, 0.3))
    s.add_force(nc.Spring(bar, (0.5, 0.0, 0.0), mass, (0.0, 0.0, 0.0), k=k, rest_length=0.25))
    return s.build()


def spinning_state(model, omega: float = 15.0):
    """``v0`` of a rigid rotation at ``omega`` rad/s about the vertical (every coordinate of
    a chain of 'rr' bars is a point)."""
    return np.cross([0.0, 0.0, omega], model.q0.reshape(-1, 3)).reshape(-1)


def reference(model, t_end, dt, **kw):
    return nc.simulate(model, t_end, dt, rtol=1e-10, atol=1e-10, **kw)


def size(y):
    return max(1.0, float(np.max(np.abs(y))))


# -------------------------------------------------------------- error control
@pytest.mark.parametrize("case", ["chain", "stiff", "spinning"])
@pytest.mark.parametrize("rtol", [1e-5, pytest.param(1e-7, marks=pytest.mark.slow)])   # fast: 1e-5, every case
def test_rtol_final_state_agrees_with_idas(case, rtol):
    """With rtol the final q and v agree with IDAS (rtol 1e-10) within 100 rtol (relative to
    the size of the state) after 2 s (the spinning chain's errors grow fast: 22 rtol at
    rtol 1e-5), with no accuracy warning."""
    model = stiff_pendulum() if case == "stiff" else chain(3)
    kw = {"v0": spinning_state(model)} if case == "spinning" else {}
    t_end = 2.0
    ref = reference(model, t_end, 0.1, **kw)
    with warnings.catch_warnings():
        warnings.simplefilter("error", AccuracyWarning)
        traj = nc.simulate(model, t_end, 0.1, method="stepper", rtol=rtol, **kw)
    assert traj.complete and traj.info["order"] == 4
    assert np.max(np.abs(traj.q[-1] - ref.q[-1])) <= 100 * rtol * size(ref.q[-1])
    assert np.max(np.abs(traj.v[-1] - ref.v[-1])) <= 100 * rtol * size(ref.v[-1])
    # the guarantee itself: the C step is accepted only with max |Φ| ≤ newton_tol = 1e-10 (its
    # check after each step, templates/c/runtime/ncgen_rattle.h), computed the same way here
    assert np.all(traj.constraint_residual <= 1e-10)
    assert np.all(traj.velocity_residual <= 1e-9 * size(traj.v))


def test_order_four_is_more_accurate_than_order_two_at_the_same_steps():
    """Richardson extrapolation (order 4) against plain RATTLE steps (order 2) under the same
    error control (which estimates the error of the order-2 halves in both, so both take the
    same steps): the extrapolated run is far more accurate."""
    model = chain(3)
    ref = reference(model, 1.0, 0.1)
    runs = {order: nc.simulate(model, 1.0, 0.1, method="stepper", rtol=1e-7, order=order) for order in (2, 4)}
    errors = {order: np.max(np.abs(r.q[-1] - ref.q[-1])) for order, r in runs.items()}
    assert abs(runs[4].info["stats"]["nsteps"] - runs[2].info["stats"]["nsteps"]) <= 2
    assert errors[4] <= 0.1 * errors[2]


def test_adaptive_sum_of_local_estimates_bounds_the_true_error():
    """Without the shadow run (estimate=False), the sum of the local estimates of an
    order-4 run (those of its unextrapolated halves) bounds its error on a non-chaotic motion."""
    model = stiff_pendulum()
    ref = reference(model, 1.0, 0.1)
    traj = nc.simulate(model, 1.0, 0.1, method="stepper", rtol=1e-6, estimate=False)
    true = np.max(np.abs(traj.q[-1] - ref.q[-1]))
    assert true <= traj.info["error_estimate"]["q"]
    assert "sum of the local" in traj.info["error_estimate"]["how"]


@pytest.mark.parametrize("case", ["chain", *(pytest.param(c, marks=pytest.mark.slow) for c in ("stiff", "spinning"))])
def test_adaptive_global_estimate_against_the_true_error(case):     # fast: chain; the others' runs: rtol test above
    """The global estimate of an rtol run (shadow run at 10 rtol: |y − y_shadow| / 10)
    against the true error in q after 2 s (IDAS at 1e-12): within a factor 10 (measured
    0.4–6), including the spinning chain whose error grows to 22 rtol."""
    model = stiff_pendulum() if case == "stiff" else chain(3)
    kw = {"v0": spinning_state(model)} if case == "spinning" else {}
    ref = nc.simulate(model, 2.0, 0.1, rtol=1e-12, atol=1e-12, **kw)
    traj = nc.simulate(model, 2.0, 0.1, method="stepper", rtol=1e-5, **kw)
    true = np.max(np.abs(traj.q[-1] - ref.q[-1]))
    estimate = traj.info["error_estimate"]
    assert 0.1 * true <= estimate["q"] <= 10 * true
    assert estimate["how"].startswith("global") and not estimate["exceeds_tolerance"]
    assert "estimated error at the end" in traj.summary()


@pytest.mark.slow      # runs of the spinning chain to its warning and failure; fast:
#                       test_a_chaotic_run_with_a_large_error_fails_loudly
def test_rtol_on_a_chaotic_motion_warns_or_fails_loudly():
    """rtol bounds the error of each step, not the global error: on the spinning chain the
    error grows along the motion.  Past 100 × the tolerance the run warns; past 1 % of the
    model's size it raises with the trusted part; check=False returns it unchecked."""
    model = chain(3)
    v0 = spinning_state(model)
    with pytest.warns(AccuracyWarning, match="more than 100 times the tolerance"):
        traj = nc.simulate(model, 3.0, 0.1, method="stepper", rtol=1e-6, v0=v0)
    assert traj.info["error_estimate"]["exceeds_tolerance"]
    ref = nc.simulate(model, 3.0, 0.1, rtol=1e-12, atol=1e-12, v0=v0)
    assert np.max(np.abs(traj.q[-1] - ref.q[-1])) > 100 * 1e-6          # the warning is right
    with pytest.raises(SimulationError, match="estimated global error in q") as failure:
        nc.simulate(model, 2.0, 0.1, method="stepper", rtol=1e-3, v0=v0)
    kept = failure.value.trajectory
    assert not kept.complete and 0 < kept.t[-1] < 2.0
    assert np.max(np.abs(kept.q - ref.q[:len(kept)])) <= ERROR_FRACTION * np.max(np.abs(model.q0))
    unchecked = nc.simulate(model, 2.0, 0.1, method="stepper", rtol=1e-3, v0=v0, check=False)
    assert unchecked.complete and unchecked.info["error_estimate"]["q"] > ERROR_FRACTION


# ------------------------------------------------------------ fixed-step estimate
@pytest.mark.parametrize("case, h", [("chain", 5e-3), pytest.param("chain", 2.5e-3, marks=pytest.mark.slow),
                                     pytest.param("spinning", 2e-3, marks=pytest.mark.slow), ("stiff", 1e-3)])   # fast: 2
def test_fixed_step_error_estimate_against_the_true_error(case, h):
    """The Richardson estimate of a RATTLE fixed-step run (against its shadow run with steps of 2h)
    against the true error in q at the end (IDAS at 1e-10), on a chain, a fast-spinning
    chain (errors grow fast) and the stiff-spring pendulum: within a factor 2."""
    model = stiff_pendulum() if case == "stiff" else chain(2 if case == "chain" else 3)
    kw = {"v0": spinning_state(model)} if case == "spinning" else {}
    ref = reference(model, 1.0, 0.1, **kw)
    traj = nc.simulate(model, 1.0, 0.1, method="stepper", substeps=round(0.1 / h), check=False, scheme="rattle",
                       **kw)
    true = np.max(np.abs(traj.q[-1] - ref.q[-1]))
    estimate = traj.info["error_estimate"]["q"]
    assert 0.5 * true <= estimate <= 2 * true
    assert "estimated error at the end" in traj.summary()


def test_a_chaotic_run_with_a_large_error_fails_loudly():
    """The spinning chain with RATTLE at h = 2 ms: the estimate sees the error grow and the run stops
    with the step to use; at that step the error is within the stated 1 % of the size."""
    model = chain(3)
    v0 = spinning_state(model)
    with pytest.raises(SimulationError, match="estimated error in q") as failure:
        nc.simulate(model, 1.0, 0.1, method="stepper", substeps=50, v0=v0, scheme="rattle")
    kept = failure.value.trajectory
    assert not kept.complete and 0 < kept.t[-1] < 1.0
    assert kept.info["error_estimate"]["q"] <= ERROR_FRACTION * np.max(np.abs(model.q0))   # the part kept
    substeps = int(str(failure.value).split("substeps=")[1].split(" ")[0])
    traj = nc.simulate(model, 1.0, 0.1, method="stepper", substeps=substeps, v0=v0, scheme="rattle")
    ref = reference(model, 1.0, 0.1, v0=v0)
    assert np.max(np.abs(traj.q - ref.q)) <= ERROR_FRACTION * np.max(np.abs(model.q0))


def test_past_the_stability_limit_raises():
    """The stiff spring (140 rad/s) at h = 0.02 s (ω h ≈ 2.8, beyond RATTLE's limit 2): the
    run does not return a blown-up trajectory; the error names a step that works."""
    model = stiff_pendulum()
    with pytest.raises(SimulationError, match=r"not trustworthy|failed") as failure:
        nc.simulate(model, 1.0, 0.02, method="stepper")
    message = str(failure.value)
    assert "substeps=" in message or "smaller step" in message or "dt" in message
    partial = failure.value.trajectory
    assert partial is not None and not partial.complete and partial.t[-1] < 1.0
    assert np.all(np.isfinite(partial.q))
    substeps = int(message.split("substeps=")[1].split(" ")[0]) if "substeps=" in message else 8
    nc.simulate(model, 1.0, 0.02, method="stepper", substeps=substeps)       # checked, passes


@pytest.mark.slow      # the tensegrity compiled and run twice; fast: test_past_the_stability_limit_raises (the same
#                       loud failure past the stability limit)
def test_tensegrity_at_its_default_step_fails_loudly_and_the_suggested_step_is_accurate(tmp_path, quick_cflags):
    """``ncgen simulate examples/tensegrity.toml --method stepper`` at the default dt: exit
    status 1 and a message naming the step to use; at that step the run passes its checks
    and is within the stated accuracy (1 % of the size) of IDAS (compiled at -O0:
    ``quick_cflags``, tests/conftest.py)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = nc.System.from_toml(ROOT / "examples" / "tensegrity.toml").build()
    out = subprocess.run([sys.executable, "-m", "ncgen.cli", "simulate", "examples/tensegrity.toml", "--t-end",
                          "0.5", "-o", str(tmp_path / "t.npz"), "--method", "stepper"],
                         cwd=ROOT, capture_output=True, text=True)
    assert out.returncode == 1
    assert "not trustworthy" in out.stderr and "--substeps " in out.stderr      # the CLI's flag, not Python's
    assert "substeps=" not in out.stderr and not (tmp_path / "t.npz").exists()
    substeps = int(out.stderr.split("--substeps ")[1].split(" ")[0])
    traj = nc.simulate(model, 0.5, 0.01, method="stepper", substeps=substeps)
    ref = reference(model, 0.5, 0.01)
    assert np.max(np.abs(traj.q - ref.q)) <= 0.1 * ERROR_FRACTION * np.max(np.abs(model.q0))   # it aims at 1 %
    assert traj.info["energy"]["conservative"] is False


# ------------------------------------------------------------ energy and outputs
def spring_damper():
    s = nc.System("acc_spring_damper", gravity=(0.0, 0.0, -9.81))
    bar = s.add_bar("bar", "rr", mass=1.0, ends=[s.ground.point((0.0, 0.0, 0.0)), (1.0, 0.0, 0.0)])
    bar.add_marker("tip", (1.0, 0.0, 0.0))
    mass = s.add_point("mass", mass=0.5, position=(1.0, 0.3, -0.5), velocity=(0.0, 0.5, 0.0))
    s.add_force(nc.Spring(bar, (0.5, 0.0, 0.0), mass, (0.0, 0.0, 0.0), k=80.0, rest_length=0.4, damping=2.0))
    return s.build()


def test_conservative_models_are_recognised():
    assert is_conservative(chain(2)) and is_conservative(stiff_pendulum())
    assert not is_conservative(spring_damper())


@pytest.mark.parametrize("scheme, low, high", [("rattle", 0.2, 0.3), ("auto", 1 / 20, 1 / 12)])
def test_energy_balance_of_a_damped_model_closes(scheme, low, high):
    """Dampers remove energy: E(t) − E(t0) equals the work W of the damper forces (the
    integral of P = vᵀ(F + ∇V), generated C) up to the scheme's error, which falls like h²
    with RATTLE and h⁴ with the default composition."""
    model = spring_damper()
    reports = [nc.simulate(model, 1.0, 0.01, method="stepper", substeps=s, scheme=scheme).info["energy"]
               for s in (2, 4)]
    for r in reports:
        assert r["conservative"] is False and r["work"] < -0.1      # the dampers dissipate
    assert reports[0]["balance_error"] < 5e-3 * abs(reports[0]["work"])
    assert low < reports[1]["balance_error"] / reports[0]["balance_error"] < high     # 1/4, 1/16


def test_energy_balance_of_a_driven_model_closes_at_order_two():
    """A driven crank (rheonomic constraint ``θ = ω t``) does work ``λᵀΦ_t``: each RATTLE step's
    work pairs its start with the first half-step's multiplier and its end with the second's,
    so the balance closes at order 2 (a first-order multiplier once made it fail at ω = 14
    rad/s for every step size); the drive's work, accumulated step by step, converges at
    order 2 to IDAS's (its quadrature at rtol 1e-10)."""
    model = nc.System.from_toml(ROOT / "examples" / "slider_crank.toml").build()
    p = {"omega": 14.0}
    runs = [nc.simulate(model, 1.0, 0.01, method="stepper", substeps=s, p=p, scheme="rattle") for s in (1, 2, 4)]
    errors = [r.info["energy"]["balance_error"] for r in runs]
    assert errors[0] < 5e-3 * abs(runs[0].info["energy"]["work"])
    for coarse, fine in zip(errors, errors[1:]):
        assert 0.2 < fine / coarse < 0.3                                              # h²: 1/4
    # the drive's work accumulated in the steps converges at order 2 to IDAS's quadrature
    # (measured 2.0e-3, 5.0e-4, 1.2e-4 of it at h = 10, 5, 2.5 ms: (ω h)² / 10)
    drives = reference(model, 1.0, 0.01, p=p).info["energy"]["parts"]["drives"]
    off = [abs(r.info["energy"]["parts"]["drives"] - drives) for r in runs]
    assert off[0] < 3e-3 * abs(drives)
    for coarse, fine in zip(off, off[1:]):
        assert 0.2 < fine / coarse < 0.3
    # the default fourth-order composition: its five steps' work summed, the balance at order 4
    errors = [nc.simulate(model, 1.0, 0.01, method="stepper", substeps=s, p=p).info["energy"]["balance_error"]
              for s in (1, 2, 4)]
    for coarse, fine in zip(errors, errors[1:]):
        assert 1 / 20 < fine / coarse < 1 / 12                                        # h⁴: 1/16


def test_stepper_multipliers_converge_at_order_two():
    """The multipliers a stepper run reports (the KKT multipliers of its output states) fall
    like h² against IDAS's, as the states do (RATTLE's own μ is first order)."""
    model = chain(3)
    ref = reference(model, 1.0, 0.05)
    errors = [np.max(np.abs(nc.simulate(model, 1.0, 0.05, method="stepper", substeps=s, scheme="rattle").lam
                            - ref.lam)) for s in (8, 16, 32)]
    assert errors[0] < 1e-2 * np.max(np.abs(ref.lam))
    for coarse, fine in zip(errors, errors[1:]):
        assert 0.2 < fine / coarse < 0.3


def test_outputs_from_c_match_the_model_functions():
    """Energies, residuals and markers computed in C equal those of the model's CasADi
    functions on the same states."""
    model = spring_damper()
    traj = nc.simulate(model, 0.5, 0.05, method="stepper", substeps=10)
    T, V = outputs.energies(model, traj.t, traj.q, traj.v, traj.p)
    r, rd = outputs.residuals(model, traj.t, traj.q, traj.v, traj.p)
    np.testing.assert_allclose(traj.kinetic, T, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(traj.potential, V, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(traj.constraint_residual, r, atol=1e-16)
    np.testing.assert_allclose(traj.velocity_residual, rd, atol=1e-16)
    np.testing.assert_allclose(traj.markers, outputs.markers(model, traj.q, traj.v), rtol=1e-14, atol=1e-15)
    assert traj.info["wall_time"] >= traj.info["stepping_time"]


@pytest.mark.parametrize("hold", ["zoh", "linear"])
def test_rtol_with_inputs_parameters_and_dampers(hold):
    """Error control with an input force (held as IDAS holds it), a parameter and dampers."""
    import casadi as ca

    s = nc.System("acc_driven", gravity=(0.0, 0.0, -9.81))
    bar = s.add_bar("bar", "rr", mass=1.0, ends=[s.ground.point((0.0, 0.0, 0.0)), (1.0, 0.0, 0.0)])
    mass = s.add_point("mass", mass=0.5, position=(1.0, 0.3, -0.5), velocity=(0.0, 0.5, 0.0))
    k = s.add_parameter("k", 40.0)
    push = s.add_input("push")
    s.add_force(nc.Spring(bar, (0.5, 0.0, 0.0), mass, (0.0, 0.0, 0.0), k=80.0, rest_length=0.4, damping=2.0))
    s.add_force(nc.Spring(s.ground, (1.0, 0.0, 0.5), mass, (0.0, 0.0, 0.0), k=k, rest_length=0.8, damping=1.5))
    s.add_force(nc.PointForce(mass, (0.0, 0.0, 0.0), force=ca.vertcat(0, push, 0)))
    model = s.build()
    kw = {"u": lambda t: [2.0 * np.sin(5 * t)], "p": {"k": 55.0}, "hold": hold}
    ref = reference(model, 1.0, 0.05, **kw)
    traj = nc.simulate(model, 1.0, 0.05, method="stepper", rtol=1e-7, **kw)
    assert np.max(np.abs(traj.q - ref.q)) <= 1e-5 * size(ref.q)
    assert np.max(np.abs(traj.v - ref.v)) <= 1e-5 * size(ref.v)
    energy = traj.info["energy"]
    assert energy["conservative"] is False and energy["relative"] < 1e-4     # work: trapezoidal, O(h²)


def test_without_the_estimate_the_same_steps_and_no_error_figure():
    model = chain(2)
    with_estimate = nc.simulate(model, 0.5, 0.1, method="stepper", substeps=50)
    without = nc.simulate(model, 0.5, 0.1, method="stepper", substeps=50, estimate=False)
    np.testing.assert_array_equal(with_estimate.q, without.q)
    assert np.isfinite(with_estimate.info["error_estimate"]["q"])
    assert np.isnan(without.info["error_estimate"]["q"])
