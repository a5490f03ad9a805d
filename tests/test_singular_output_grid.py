"""IDAS through singular positions whatever the output grid (issue 38).

The N four-bar of IFToMM A02 (:mod:`test_singular_positions`: N + 1 cranks and N couplers, a
chain of parallelograms released at 45°, sixteen flat positions in 20 s, exact motion that of
one pendulum).  A watched run (``project="auto"``, the default) checks ``σ_min/σ_max`` of A and
places its IDAS calls and RATTLE bridges on an internal grid of at most
``idas_integrator.WATCHED_SAMPLE`` s, so the output grid (1 ms to 0.5 s) no longer decides where
the near-singular band is looked for.  Before, an output every 0.05 s or more let IDAS cross a
flat position between two outputs and end on the other branch, up to 2 m from the exact
motion, without a word.
"""
import warnings

import casadi as ca
import numpy as np
import pytest

import ncgen as nc
from ncgen.assembly.manifold import ManifoldProjector
from ncgen.errors import BranchWarning, SimulationError
from ncgen.runtime import idas_integrator
from test_singular_positions import G, THETA0, n_fourbar, n_fourbar_3d, tip_error

TOL = {"rtol": 1e-10, "atol": 1e-10}
INTERVALS = (0.001, 0.01, 0.05, 0.1, 0.5)


def run(model, t_end, dt, backend="compiled", **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("error", BranchWarning)      # a branch change is a failure here
        return nc.simulate(model, t_end, dt, method="idas", backend=backend, **TOL, **kw)


def test_every_output_grid_gives_the_same_motion_on_the_branch():
    """Outputs every 0.01, 0.05, 0.1 and 0.5 s: one internal grid of 0.01 s, so the same motion
    (to round-off) at the common output times, within 1e-6 m of the exact motion over 3 s
    (three flat positions; before, an output every 0.5 s left the branch at t = 1.5 s)."""
    runs = {dt: run(n_fourbar(1), 3.0, dt) for dt in (0.01, 0.05, 0.1, 0.5)}
    for dt, traj in runs.items():
        assert traj.complete and traj.info["watched_interval"] == pytest.approx(0.01)
        assert traj.info["branch_changes"] == [] and traj.info["stats"]["rattle_intervals"] >= 3
        assert tip_error(traj, 1) < 1e-6
        every = int(round(0.5 / dt))
        np.testing.assert_allclose(traj.q[::every], runs[0.5].q, rtol=0, atol=1e-12)


def test_a_millisecond_grid_and_the_vm_backend_follow_the_same_motion():
    """An output every 1 ms (the watched grid is the output grid) and CasADi's VM with an
    output every 0.5 s: both within 1e-6 m of the exact motion and of the compiled run with
    outputs every 0.01 s, over 1 s (one flat position, at 0.42 s)."""
    model = n_fourbar(1)
    ref = run(model, 1.0, 0.01)
    fine = run(model, 1.0, 0.001)
    vm = run(model, 1.0, 0.5, backend="vm")
    assert fine.info["watched_interval"] == pytest.approx(0.001) and vm.info["backend"] == "vm"
    for traj in (ref, fine, vm):
        assert traj.complete and tip_error(traj, 1) < 1e-6
    np.testing.assert_allclose(fine.q[::10], ref.q, rtol=0, atol=1e-6)
    np.testing.assert_allclose(vm.q, ref.q[::50], rtol=0, atol=1e-6)


@pytest.mark.slow      # a long watched run; fast: test_every_output_grid_gives_the_same_motion_on_the_branch
def test_long_output_intervals_no_longer_run_out_of_steps():
    """Planar N = 10 with an output every 0.5 s stopped with "IDAS needed more than max_steps
    steps": the step limit is per interval of the watched grid, not per output interval."""
    model = n_fourbar(10)
    traj = run(model, 3.0, 0.5)
    assert traj.complete and tip_error(traj, 10) < 1e-6


def test_a_coarse_watched_grid_is_caught_by_the_rate_of_the_conditioning():
    """With a watched grid of 0.1 s (twice as long as the time the four-bar spends in the
    near-singular band around a flat position) the band can fall between two grid times:
    the rate of σ_min/σ_max at both ends says it could, and the interval is bridged.  The
    run stays on its branch over the eight flat positions of 10 s."""
    model = n_fourbar(1)
    real = idas_integrator.WATCHED_SAMPLE
    try:
        idas_integrator.WATCHED_SAMPLE = 0.1
        traj = run(model, 10.0, 0.5)
    finally:
        idas_integrator.WATCHED_SAMPLE = real
    assert traj.info["watched_interval"] == pytest.approx(0.1)
    assert traj.complete and tip_error(traj, 1) < 3e-6


def crank_tips(t1, t2):
    """``[q; v]`` of the N = 1 four-bar at rest with crank angles ``t1``, ``t2`` (rad)."""
    q = np.array([np.cos(t1), np.sin(t1), 1 + np.cos(t2), np.sin(t2)])
    return np.concatenate([q, np.zeros(4)])


def test_the_branch_test_tells_a_passage_from_a_change_of_branch():
    """Across the flat position of the four-bar from +6° (the near-singular band's edge):
    to −6° on the parallelogram branch the chord leaves the tangent motions by sin 6° = 0.10
    of its length, to the other branch (the first crank flat, the second at −6°) by 0.46."""
    model = n_fourbar(1)
    projector = ManifoldProjector(model, model.p0, 1e-12)
    a = np.radians(6.0)
    same = projector.departure(0.0, crank_tips(a, a), 0.05, crank_tips(-a, -a))
    other = projector.departure(0.0, crank_tips(a, a), 0.05, crank_tips(0.0, -a))
    assert same == pytest.approx(np.sin(a), rel=1e-6) and same < idas_integrator.BRANCH_DEPARTURE
    assert other > 0.4 > idas_integrator.BRANCH_DEPARTURE


def test_a_bridged_interval_that_changes_branch_is_a_loud_warning():
    """A bridged interval whose end is on the other branch: a BranchWarning naming the
    interval's times, and its times in the returned list; the intervals on one branch pass."""
    model = n_fourbar(1)
    projector = ManifoldProjector(model, model.p0, 1e-12)
    a = np.radians(6.0)

    class Bridged:
        spans = [(0.3, 0.31), (0.31, 0.32), (0.32, 0.33)]

    grid = np.round(np.arange(0.0, 0.5001, 0.01), 12)
    X = np.array([crank_tips(a, a) if t <= 0.31 else crank_tips(0.0, -a) for t in grid])
    with pytest.warns(BranchWarning, match=r"between t = 0\.31 s and 0\.32 s .*branch test"):
        changes, largest = idas_integrator._branch_changes(model, projector, Bridged(), grid, X)
    assert changes == [(0.31, 0.32)] and largest > 0.4


def driven_to_flat(T):
    """The four-bar with its first crank's tip driven down to the flat position, reached at
    rest at ``T`` and held there: from ``T`` on the parallelogram branch is locked and the
    second crank and the coupler (folded onto each other) can only fall, on the other branch
    of Φ = 0, which is singular everywhere (the two bars' constraints coincide)."""
    s = nc.System("fourbar_driven_flat", gravity=(0, -G))
    c, sn = np.cos(THETA0), np.sin(THETA0)
    cranks = [s.add_bar(f"crank{k}", mass=1.0, ends=[s.ground.point((k, 0)), (k + c, sn)]) for k in range(2)]
    s.add_bar("coupler0", mass=1.0, ends=[cranks[0].end(1), cranks[1].end(1)])
    s.add_joint(nc.CoordinateDriver(cranks[0], "r_j", "y", value=lambda t: sn * ca.fmax(0, 1 - t / T) ** 2))
    return s.build()


@pytest.mark.parametrize("dt", [0.01, 0.5])
def test_a_mechanism_driven_onto_another_branch_fails_loudly_at_that_time(dt):
    """The driven four-bar must leave its branch at T = 0.5 s: the run stops with a
    SimulationError naming the interval that ends there and the singular configuration,
    with the trajectory up to it, whatever the output grid."""
    model = driven_to_flat(0.5)
    with pytest.raises(SimulationError, match=r"between t = 0\.49 s .* singular configuration") as failure:
        run(model, 1.0, dt)
    e = failure.value
    assert 0.45 <= e.time <= 0.5 and e.trajectory is not None


#: Planar N = 40 and 3D N = 10 take 2-4 min a run at outputs of 0.01 s or more and over 10 min
#: at 1 ms (2 loaded cores): the ``exhaustive`` tier, run by hand (tests/conftest.py), not by CI.
EXHAUSTIVE = pytest.mark.exhaustive
FORMS = [("2d", 1), ("2d", 10), pytest.param("2d", 40, marks=EXHAUSTIVE), ("3d", 1),
         pytest.param("3d", 10, marks=EXHAUSTIVE)]


@pytest.mark.slow
@pytest.mark.timeout(1800)                  # outputs every 1 ms on the VM: minutes each under load
@pytest.mark.parametrize("dt", INTERVALS)
@pytest.mark.parametrize("backend", ["compiled", "vm"])
@pytest.mark.parametrize("form, N", FORMS)
def test_the_a02_family_stays_on_its_branch_for_every_output_grid(form, N, backend, dt):
    """The full matrix of issue 38: planar N = 1, 10, 40 and 3D N = 1, 10, outputs every
    0.001, 0.01, 0.05, 0.1 and 0.5 s, both backends, 20 s at rtol = atol = 1e-10: every run
    complete, no branch change, within 1e-6 m of the exact motion (one run per test, so
    that each stays within the per-test time limit)."""
    model = n_fourbar(N) if form == "2d" else n_fourbar_3d(N)
    traj = run(model, 20.0, dt, backend=backend)
    assert traj.complete and traj.info["branch_changes"] == []
    assert tip_error(traj, N) < 1e-6, (dt, tip_error(traj, N))


@pytest.mark.parametrize("degrees", [40.0, 10.0, 3.0, -2.0])
def test_the_rate_of_the_conditioning_matches_finite_differences(degrees):
    """``ratio_rate``'s ṙ (from the singular vectors and Ȧ) against a central difference of
    σ_min/σ_max along the motion, on the four-bar moving on its branch at 1 rad/s."""
    model = n_fourbar(1)
    projector = ManifoldProjector(model, model.p0, 1e-12)
    th = np.radians(degrees)
    x = crank_tips(th, th)
    x[4:] = [-np.sin(th), np.cos(th), -np.sin(th), np.cos(th)]
    r, rate = projector.ratio_rate(0.0, x)
    eps = 1e-6
    ahead, behind = x[:4] + eps * x[4:], x[:4] - eps * x[4:]
    fd = (projector.ratio(0.0, np.r_[ahead, x[4:]]) - projector.ratio(0.0, np.r_[behind, x[4:]])) / (2 * eps)
    assert r == pytest.approx(projector.ratio(0.0, x), rel=1e-12)
    assert rate == pytest.approx(fd, rel=1e-6, abs=1e-9) and abs(rate) > 1e-3


def test_the_rate_of_the_conditioning_of_a_driven_mechanism_matches_finite_differences():
    """The same on the driven four-bar (Φ_t ≠ 0) at t = 0.2 s, moving with its drive."""
    eps = 1e-6
    driven = driven_to_flat(0.5)
    projector = ManifoldProjector(driven, driven.p0, 1e-12)
    t = 0.2
    traj = nc.simulate(driven, t, t / 20, method="idas", backend="vm", **TOL)
    xt = np.r_[traj.q[-1], traj.v[-1]]
    nq = driven.nq
    fd = (projector.ratio(t + eps, np.r_[xt[:nq] + eps * xt[nq:], xt[nq:]])
          - projector.ratio(t - eps, np.r_[xt[:nq] - eps * xt[nq:], xt[nq:]])) / (2 * eps)
    assert projector.ratio_rate(t, xt)[1] == pytest.approx(fd, rel=1e-5, abs=1e-9)
