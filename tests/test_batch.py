"""``nc.simulate_batch``: many runs through the compiled stepper equal the loop of single
``nc.simulate(method="stepper")`` runs bit for bit; a failed run is reported, never raised."""
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import NcgenError, SimulationError
from ncgen.runtime.batch import STATUS_SETUP, STATUS_UNTRUSTED

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


@pytest.fixture(scope="module")
def slider_crank():
    return nc.System.from_toml(EXAMPLES / "slider_crank.toml").build()


@pytest.fixture(scope="module")
def cartpole():
    return nc.System.from_toml(EXAMPLES / "cartpole.toml").build()


def assert_same_run(batch, i, traj):
    for key in ("q", "v", "lam", "kinetic", "potential", "constraint_residual", "markers"):
        assert np.array_equal(getattr(batch, key)[i], getattr(traj, key)), key
    assert np.array_equal(batch.t, traj.t)


@pytest.mark.parametrize("workers", [1, 2])
def test_parameter_batch_equals_single_runs_bit_for_bit(slider_crank, workers):
    omega = np.linspace(3.0, 7.0, 5)
    batch = nc.simulate_batch(slider_crank, 0.5, 0.005, p={"omega": omega}, workers=workers)
    assert batch.q.shape == (5, 101, slider_crank.nq) and batch.ok.all()
    for i, w in enumerate(omega):
        assert_same_run(batch, i, nc.simulate(slider_crank, 0.5, 0.005, method="stepper", p={"omega": w}))
        assert batch.p[i, 0] == w


def test_initial_states_and_input_sequences_per_run(cartpole):
    rng = np.random.default_rng(3)
    n, t = 4, np.arange(0.0, 0.5 + 1e-12, 0.01)
    U = rng.uniform(-2.0, 2.0, size=(n, len(t), 1))
    v0 = np.zeros((n, cartpole.nq))
    traj0 = nc.simulate(cartpole, 0.2, 0.01, method="stepper", u=lambda t: [1.0])
    q0 = np.array([traj0.q[5 * k] for k in range(n)])          # consistent states of a pushed run
    batch = nc.simulate_batch(cartpole, 0.5, 0.01, q0=q0, v0=v0, u=U, substeps=2, hold="linear")
    assert batch.ok.all()
    for i in range(n):
        single = nc.simulate(cartpole, 0.5, 0.01, method="stepper", q0=q0[i], v0=v0[i], u=U[i], substeps=2,
                             hold="linear")
        assert_same_run(batch, i, single)


def test_trusted_states_skip_the_projection_and_keep_the_bits(cartpole):
    """``project=False``: states taken as given (the runs keep their bits but for the
    projection's round-off), λ0 by one KKT solve of all runs (the element tables' on their
    path: equal to the model's ``accel`` to round-off)."""
    traj = nc.simulate(cartpole, 0.4, 0.005, method="stepper")
    q0, v0 = traj.q[::20], traj.v[::20]          # consistent (RATTLE keeps both constraint levels)
    fast = nc.simulate_batch(cartpole, 0.4, 0.005, q0=q0, v0=v0, project=False, check=False)
    for i in range(len(q0)):
        single = nc.simulate(cartpole, 0.4, 0.005, method="stepper", q0=q0[i], v0=v0[i])
        lam0 = np.asarray(cartpole.accel(q0[i], v0[i])[1]).reshape(-1)
        np.testing.assert_allclose(fast.lam[i, 0], lam0, rtol=0, atol=1e-12 * max(1.0, np.max(np.abs(lam0))))
        assert np.abs(fast.q[i] - single.q).max() < 1e-12        # only the projection's round-off differs
    assert_same_run(fast, 0, traj)


def test_a_failing_run_is_reported_and_the_others_complete(slider_crank):
    omega = np.array([4.0, 60.0, 5.0])           # 60 rad/s is too fast for RATTLE at h = 10 ms
    q0 = np.repeat(slider_crank.q0[None], 3, axis=0)
    q0[2, 0] += 0.3                              # far off the constraints: cannot start
    batch = nc.simulate_batch(slider_crank, 0.5, 0.01, p={"omega": omega}, q0=q0, scheme="rattle")
    assert list(batch.status[:2]) == [0, STATUS_UNTRUSTED] and batch.status[2] == STATUS_SETUP
    assert batch.message[1].startswith("not trustworthy: ") and "Use a step of at most" in batch.message[1]
    assert batch.message[2].startswith("could not start: ") and "inconsistent initial configuration" in batch.message[2]
    with pytest.raises(SimulationError) as single:
        nc.simulate(slider_crank, 0.5, 0.01, method="stepper", p={"omega": 60.0}, scheme="rattle")
    bad_from = len(single.value.trajectory.t)    # the single run keeps the states before the problem
    assert np.isnan(batch.q[1, bad_from:]).all() and np.array_equal(batch.q[1, :bad_from], single.value.trajectory.q)
    assert_same_run(batch, 0, nc.simulate(slider_crank, 0.5, 0.01, method="stepper", p={"omega": 4.0},
                                          scheme="rattle"))


def test_newton_failure_status_without_checks(slider_crank):
    batch = nc.simulate_batch(slider_crank, 0.5, 0.01, p={"omega": [5.0, 200.0]}, check=False, max_newton=1)
    assert batch.status[0] == 0 and batch.status[1] == 1          # Newton did not converge
    assert batch.message[1].startswith("the stepper failed in the step from t = 0 s to 0.01 s: Newton")
    assert np.isnan(batch.q[1, 1:]).all() and np.array_equal(batch.q[1, 0], slider_crank.q0)
    with pytest.raises(SimulationError, match="failed in the step from t = 0 s"):
        nc.simulate(slider_crank, 0.5, 0.01, method="stepper", p={"omega": 200.0}, max_newton=1)


def test_bad_batch_arguments_are_named(slider_crank):
    with pytest.raises(NcgenError, match=r"disagree on the number of runs \(q0: 2, p\['omega'\]: 3\)"):
        nc.simulate_batch(slider_crank, 0.1, 0.01, q0=np.zeros((2, slider_crank.nq)), p={"omega": [1, 2, 3]})
    with pytest.raises(NcgenError, match=r"q0: expected 8 values or an array of shape"):
        nc.simulate_batch(slider_crank, 0.1, 0.01, q0=np.zeros(3), project=False)
    with pytest.raises(NcgenError, match="workers: expected a positive number"):
        nc.simulate_batch(slider_crank, 0.1, 0.01, workers=0)


def test_batch_of_oscillators_matches_the_closed_form():
    """A sled on a spring pushed by a constant force: x(t) = F₀/k (1 − cos ωt), ω = √(k/m),
    one run per stiffness; RATTLE's error is O(h²), the default composition's O(h⁴)."""
    s = nc.System("osc", gravity=(0, 0))
    sled = s.add_point("sled", mass=2.0, position=(1.0, 0))
    k = s.add_parameter("k", 50.0)
    push = s.add_input("push")
    s.add_joint(nc.PointOnLine(s.ground, sled, at=(1.0, 0), axis=(1, 0)))
    s.add_force(nc.Spring(s.ground, (0, 0), sled, (0, 0), k=k, rest_length=1.0))
    s.add_force(nc.PointForce(sled, (0, 0), force=[push, 0.0]))
    osc = s.build()
    ks = np.array([20.0, 50.0, 80.0])
    errors = {"rattle": [], "auto": []}
    for scheme, runs in errors.items():
        for substeps in (1, 2):
            batch = nc.simulate_batch(osc, 1.0, 0.01, p={"k": ks}, u=np.full((101, 1), 5.0), substeps=substeps,
                                      scheme=scheme)
            assert batch.ok.all()
            exact = 5.0 / ks[:, None] * (1 - np.cos(np.sqrt(ks[:, None] / 2.0) * batch.t[None]))
            runs.append(np.abs(batch.q[:, :, 0] - 1.0 - exact).max())
    rattle, auto = errors["rattle"], errors["auto"]
    assert rattle[0] < 1e-4 and 3.5 < rattle[0] / rattle[1] < 4.5       # second order
    assert auto[0] < 1e-8 and 14 < auto[0] / auto[1] < 18                # the default: fourth order
