"""``nc.simulate_batch`` with its checks screened over the batch: the runs of a 5-bar chain
on the element tables (no compile) equal single ``nc.simulate`` runs bit for bit, checks
included; a run the single-run check rejects is rejected with the same reason, and only such
runs are checked one by one; ``estimate`` chooses the shadow run; the multipliers of the
output states come from one compiled KKT solve per run and agree with the flat functions'."""
import sys
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import SimulationError
from ncgen.runtime.batch import STATUS_UNTRUSTED
from ncgen.runtime.table_stepper import load_any_stepper

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from batch import initial_rates  # noqa: E402  (the benchmark's random bar rates, consistent)
from common import chain_system  # noqa: E402

KEYS = ("q", "v", "lam", "kinetic", "potential", "constraint_residual", "markers")


@pytest.fixture(scope="module")
def chain():
    return chain_system(5).build()


def assert_same_run(batch, i, traj):
    for key in KEYS:
        assert np.array_equal(getattr(batch, key)[i], getattr(traj, key), equal_nan=True), key


@pytest.mark.parametrize("estimate", [True, "local", False])
def test_checked_batch_on_the_tables_equals_single_runs(chain, estimate):
    """States projected chunk by chunk while the threads integrate; checks screened."""
    V0 = initial_rates(10 if estimate is True else 3, seed=2)[0]     # 10: more runs than a chunk
    batch = nc.simulate_batch(chain, 0.5, 0.05, v0=V0, substeps=10, workers=2, kernels="tables",
                              estimate=estimate)
    assert batch.info["kernels"] == "tables" and batch.ok.all(), batch.message
    assert batch.info["checked_alone"] == 0                   # the screen passed every run
    assert batch.info["estimate"] == {True: "shadow"}.get(estimate, estimate)
    for i in range(len(V0)):
        single = nc.simulate(chain, 0.5, 0.05, method="stepper", v0=V0[i], substeps=10, kernels="tables",
                             estimate=estimate)
        assert_same_run(batch, i, single)


def test_rejected_runs_carry_the_single_runs_reason(chain):
    """RATTLE at h = 20 ms drifts by more than 1 % of the chain's energy (the energy check) and
    at 50 ms needs split steps; at 5 ms it is trusted.  Each run of the batch is rejected
    exactly when the single run raises, with its reason, and keeps the rows the single run
    keeps; only the rejected runs are checked on their own."""
    V0 = initial_rates(3, seed=0)[0] * np.array([0.5, 3.0, 12.0])[:, None]
    for dt, substeps in ((0.02, 1), (0.05, 1), (0.02, 4)):
        batch = nc.simulate_batch(chain, 0.6, dt, v0=V0, substeps=substeps, scheme="rattle", estimate=False,
                                  kernels="tables", workers=2)
        for i in range(len(V0)):
            try:
                single = nc.simulate(chain, 0.6, dt, method="stepper", v0=V0[i], substeps=substeps,
                                     scheme="rattle", estimate=False, kernels="tables")
            except SimulationError as e:
                assert batch.status[i] == STATUS_UNTRUSTED
                reason = batch.message[i].removeprefix("not trustworthy: ")
                assert reason != batch.message[i] and reason + "." in str(e)
                kept = len(e.trajectory.t)
                assert np.array_equal(batch.q[i, :kept], e.trajectory.q) and np.isnan(batch.q[i, kept:]).all()
            else:
                assert batch.status[i] == 0 and batch.message[i] == ""
                assert_same_run(batch, i, single)
        assert batch.info["checked_alone"] == int(np.sum(batch.status != 0))
    assert batch.ok.all()                                     # the last, at 5 ms: every run trusted


def test_table_multipliers_agree_with_the_flat_accel(chain):
    """λ of the KKT system at the states of a run, from the element library's compiled solve
    (one call for all states, and one state alone), against the dense KKT solve of
    ``nc.forward_dynamics`` on the flat functions (measured 1e-14 of 25 N/m)."""
    traj = nc.simulate(chain, 0.5, 0.05, method="stepper", substeps=10, v0=initial_rates(1, seed=3)[0][0],
                       kernels="tables")
    stepper = load_any_stepper(chain, kernels="tables")
    lam = stepper.multipliers(traj.q, traj.v)
    ref = np.array([nc.forward_dynamics(chain, q, v)[1] for q, v in zip(traj.q, traj.v)])
    np.testing.assert_allclose(lam, ref, rtol=0, atol=1e-13 * np.abs(ref).max())
    assert np.array_equal(stepper.multipliers(traj.q[4], traj.v[4]), lam[4])
    assert np.isnan(stepper.multipliers(np.zeros(chain.nq), np.zeros(chain.nq))).all()   # A = 0: singular


def test_two_threads_decide_as_one_on_good_and_bad_runs(chain):
    """Runs from slow (trusted) to fast (rejected for energy drift or split steps; the fastest
    fails in the stepper): two threads give the very bits, statuses and reasons of one thread,
    and each run's decision is the single run's (``nc.simulate`` raises exactly for the
    rejected ones, with the reason the batch gives)."""
    V0 = initial_rates(12, seed=4)[0] * np.repeat([1, 3, 5, 8, 30, 60], 2)[:, None]
    runs = {w: nc.simulate_batch(chain, 0.5, 0.05, v0=V0, substeps=2, workers=w, kernels="tables") for w in (1, 2)}
    one, two = runs[1], runs[2]
    for key in KEYS + ("status",):
        assert np.array_equal(getattr(one, key), getattr(two, key), equal_nan=True), key
    assert one.message == two.message
    reasons = " ".join(one.message)
    assert one.ok.sum() >= 3 and "energy" in reasons and "had to be split" in reasons and (one.status > 0).any()
    for i in range(len(V0)):
        try:
            single = nc.simulate(chain, 0.5, 0.05, method="stepper", v0=V0[i], substeps=2, kernels="tables")
        except SimulationError as e:
            assert one.status[i] != 0 and one.message[i].split(": ", 1)[1].split(". Later,")[0] in str(e)
        else:
            assert one.status[i] == 0
            assert_same_run(one, i, single)


def test_a_run_whose_shadow_run_fails_takes_its_estimate_from_a_run_at_half_the_step(chain):
    """The 5-bar chain released at 15 rad/s per axis, h = 2 ms: the shadow run (steps of 4 ms)
    fails by t = 0.2 s while the run goes on with an energy drift of 0.3 %, its error against
    IDAS (rtol 1e-10) past 1 % of the chain's size by t = 0.4 s.  The estimate from there comes
    from a run with steps of h/2 (within 0.5–2× of that error at the end) and rejects the run by
    t = 0.4 s, in the batch and alone alike; a slow run of the same batch is trusted."""
    from batch_estimates import rates
    from ncgen.runtime.stepper_checks import ERROR_FRACTION
    v0 = rates([0.5, 2.0, 5.0, 10.0, 15.0, 20.0], 8)[0][[0, 37]]
    batch = nc.simulate_batch(chain, 0.5, 0.1, v0=v0, substeps=50, workers=1, kernels="tables")
    assert batch.status[0] == 0 and batch.status[1] == STATUS_UNTRUSTED
    assert "estimated error in q reached" in batch.message[1] and "by t = 0.4 s" in batch.message[1]
    with pytest.raises(SimulationError, match="estimated error in q reached .* by t = 0.4 s"):
        nc.simulate(chain, 0.5, 0.1, method="stepper", v0=v0[1], substeps=50, kernels="tables")
    run = nc.simulate(chain, 0.5, 0.1, method="stepper", v0=v0[1], substeps=50, kernels="tables", check=False)
    ref = nc.simulate(chain, 0.5, 0.1, v0=v0[1], rtol=1e-10, atol=1e-10)
    error = np.max(np.abs(run.q - ref.q), axis=1)[1:]
    size = np.max(np.abs(chain.q0))
    assert error[3] > ERROR_FRACTION * size and run.info["energy"]["relative"] < 0.01   # the energy check passes
    assert "h/2" in run.info["error_estimate"]["how"]
    estimate = run.info["error_estimate"]["q"]
    assert 0.5 < estimate / error[-1] < 2.0


def test_fine_estimates_replace_a_failed_shadow_and_rows_without_any_are_flagged():
    """:func:`fine_estimates` on rows whose shadow failed (−2): Richardson from a run at h/2
    (here a stand-in stepper whose run is off by 0.03 and fails after 3 of 5 rows, order 2:
    0.04 = 0.03 · 4/3), rows it did not reach get NO_ESTIMATE, which :func:`row_flags` flags;
    rows whose shadow held are left alone and the run is made with steps of h/2."""
    from ncgen.codegen.stepper_package import STATS
    from ncgen.runtime.stepper import StepperRows, StepperStart, fine_estimates
    from ncgen.runtime.stepper_checks import NO_ESTIMATE, row_flags

    class Half:
        def simulate_stats(self, q0, v0, lam0, t0, h, n_steps, every, U, p, step, run):
            self.h, self.every = h, every
            return Q - 0.03, V + 0.03, None, None, 3, 3 * every, 0

    t, Q, V = np.linspace(0.0, 0.5, 6), np.zeros((5, 2)), np.zeros((5, 2))
    S = np.zeros((5, len(STATS)))
    S[:, STATS.index("error_q")] = S[:, STATS.index("error_v")] = [1e-3, -2, -2, -2, -2]
    stepper = Half()
    status = fine_estimates(stepper, StepperStart(t, np.zeros((6, 0)), None, None, None, None),
                            StepperRows(Q, V, None, S, 5), "zoh", 10, None, 2)
    assert status == 3 and stepper.h == pytest.approx(0.005) and stepper.every == 20
    np.testing.assert_allclose(S[:, STATS.index("error_q")], [1e-3, 0.04, 0.04, NO_ESTIMATE, NO_ESTIMATE])
    np.testing.assert_allclose(S[:, STATS.index("error_v")], [1e-3, 0.04, 0.04, NO_ESTIMATE, NO_ESTIMATE])
    zero = np.zeros(5)
    flags = row_flags(zero, zero, zero + 1, 1, zero, zero, 1.0, error_q=S[:, STATS.index("error_q")])
    assert flags["shadow"].tolist() == [False, False, False, True, True]
