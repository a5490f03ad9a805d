"""IDAS through singular positions: the N four-bar of the IFToMM benchmark A02.

N + 1 cranks (bars of 1 m, 1 kg) hinged to the ground at x = 0, 1, ..., N and N couplers
(1 m, 1 kg) joining their tips: a chain of parallelograms.  Released at rest with the cranks
at θ0 = 45°, it falls through the flat position θ = 0 (all bars on the x axis, A loses rank
and the crossed branch meets the physical one).  On the physical branch every crank keeps the
same angle θ and the couplers translate, so the motion is that of one pendulum:

    ((N+1)/3 + N) m L² θ̈ = −((N+1)/2 + N) m g L cos θ

whose solution (here by DOP853 at 1e-13, an independent integrator of a one-line ODE) is the
reference for the tip of the first crank, (cos θ, sin θ).  Over 20 s it passes a flat
position (θ = 0 or ±180°) sixteen times.  The 3D form (:func:`n_fourbar_3d`: hinges
``nc.Revolute`` about z, gravity in the plane) has the same exact motion.
"""
import sys

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import ncgen as nc
from ncgen.codegen.load import NoCompilerWarning
from ncgen.errors import CompilerNotFound, SimulationError
from ncgen.runtime import idas_integrator
from ncgen.assembly.manifold import ManifoldProjector
from ncgen.runtime.rattle_bridge import rattle_interval

G = 9.81
THETA0 = np.pi / 4


def n_fourbar(N: int, **build):
    s = nc.System(f"nfourbar{N}", gravity=(0, -G))
    c, sn = np.cos(THETA0), np.sin(THETA0)
    cranks = [s.add_bar(f"crank{k}", mass=1.0, ends=[s.ground.point((k, 0)), (k + c, sn)])
              for k in range(N + 1)]
    for k in range(N):
        s.add_bar(f"coupler{k}", mass=1.0, ends=[cranks[k].end(1), cranks[k + 1].end(1)])
    return s.build(**build)


def n_fourbar_3d(N: int):
    """The chain in 3D: the cranks are bars hinged to the ground by ``nc.Revolute`` about z,
    the couplers bodies (two bars cannot share a hinge axis) hinged to the crank tips about
    z, gravity along −y.  The couplers translate, so their inertia does not enter: the exact
    motion is the planar one.  One hinge's axis alignment in each closed loop is implied by
    the others and dropped (a warning)."""
    s = nc.System(f"nfourbar3d{N}", gravity=(0, -G, 0))
    c, sn, z = np.cos(THETA0), np.sin(THETA0), (0, 0, 1)
    cranks = [s.add_bar(f"crank{k}", mass=1.0, ends=[(k, 0, 0), (k + c, sn, 0)]) for k in range(N + 1)]
    for k in range(N + 1):
        s.add_joint(nc.Revolute(s.ground, cranks[k], at=(k, 0, 0), axis=z))
    for k in range(N):
        coupler = s.add_body(f"coupler{k}", mass=1.0, inertia=np.diag([1e-3, 1 / 12, 1 / 12]),
                             position=(k + 0.5 + c, sn, 0))
        s.add_joint(nc.Revolute(cranks[k], coupler, at=(k + c, sn, 0), axis=z))
        s.add_joint(nc.Revolute(coupler, cranks[k + 1], at=(k + 1 + c, sn, 0), axis=z))
    with pytest.warns(UserWarning, match="dropping redundant constraints"):
        return s.build()


def exact_tip(N: int, t: np.ndarray) -> np.ndarray:
    k = G * ((N + 1) / 2 + N) / ((N + 1) / 3 + N)
    sol = solve_ivp(lambda _, y: [y[1], -k * np.cos(y[0])], (t[0], t[-1]), [THETA0, 0.0], t_eval=t,
                    method="DOP853", rtol=1e-13, atol=1e-13)
    return np.column_stack([np.cos(sol.y[0]), np.sin(sol.y[0])])


def tip_error(traj, N):
    """Largest distance (m) of the first crank's tip from the exact motion."""
    tip = np.column_stack([traj.coordinate("crank0.r_j.x")[0], traj.coordinate("crank0.r_j.y")[0]])
    return np.max(np.linalg.norm(tip - exact_tip(N, traj.t), axis=1))


def test_model_is_singular_when_flat():
    """The reference really passes the singular position: DOF 1 at 45°, A rank-deficient flat."""
    model = n_fourbar(2)
    assert model.dof == 1
    flat = np.array([1.0, 0.0, 2.0, 0.0, 3.0, 0.0])        # crank tips on the x axis
    s = np.linalg.svd(model.A(flat), compute_uv=False)
    assert s[-1] < 1e-12 * s[0]


@pytest.mark.slow                                  # 10-20 s of IDAS at 1e-10 through sixteen flat positions
@pytest.mark.parametrize("form, N, t_end", [("2d", 1, 20.0), ("2d", 10, 20.0), ("2d", 40, 10.0), ("3d", 1, 20.0)])
def test_idas_through_sixteen_flat_positions_is_as_accurate_as_a_regular_run(form, N, t_end):
    """The default run (project="auto") at rtol = atol = 1e-10 over 20 s, sixteen flat
    positions (N = 40: 10 s, eight, to keep the suite fast): IDAS away from them, the
    compiled error-controlled stepper at a hundredth of the tolerance over the intervals next
    to them.  Measured, tip to the exact motion over 20 s: 2.1e-7, 4.2e-7 m for 2D N = 1, 10,
    4.8e-7 m for 3D N = 1 (1.6e-6 m with the bridge at a tenth of the tolerance, 2.3e-6 m
    before the watched grid); before the bridge, 2.1e-5, 1.9e-5, 1.8e-5, 2.8e-5 (3.4e-5) m:
    IDAS restarted about 800 times in 20 s, each restart's first steps of order 1 losing
    ~1e-8 J.  All output grids and both backends: tests/test_singular_output_grid.py."""
    model = n_fourbar(N) if form == "2d" else n_fourbar_3d(N)
    traj = nc.simulate(model, t_end, 0.01, rtol=1e-10, atol=1e-10)
    assert traj.complete
    assert tip_error(traj, N) < 1e-6
    stats = traj.info["stats"]
    flat = int(round(16 * t_end / 20.0))
    assert stats["nsteps"] > 1000 and flat <= stats["rattle_intervals"] < 20 * flat    # IDAS does most of the run
    assert np.max(np.abs([model.phi(q) for q in traj.q])) < 3e-8      # IDAS's drift at atol 1e-10: 7e-9 m² measured


def test_hand_over_and_return_hold_both_constraint_levels(monkeypatch):
    """Every bridged interval starts from a state projected onto Φ = 0 and A v = 0 and ends
    on both (the stepper's Newton tolerance), to the run's atol (1e-10), and the bridge runs
    at a hundredth of the run's tolerances (at least 1e-12)."""
    model = n_fourbar(1)
    ends, tols = [], []
    real = idas_integrator._bridge.__call__

    def recorded(self, t0, t1, x, column):
        x1, z1 = real(self, t0, t1, x, column)
        ends.extend([x, x1])
        tols.append(self.tols)
        return x1, z1

    monkeypatch.setattr(idas_integrator._bridge, "__call__", recorded)
    nc.simulate(model, 2.0, 0.01, rtol=1e-10, atol=1e-10)
    assert len(ends) >= 8 and np.allclose(tols, 1e-12, rtol=1e-12, atol=0)
    nq = model.nq
    for x in ends:
        q, v = x[:nq], x[nq:]
        assert np.max(np.abs(model.phi(q))) <= 1e-10 and np.max(np.abs(model.A(q) @ v)) <= 1e-10


def test_a_failed_watched_chunk_is_retried_up_to_just_before_where_idas_gave_up():
    """IDAS's message gives the time it reached (shifted: relative to the chunk's start); the
    retry ends two outputs before it, or halves the chunk when no time is given."""
    from ncgen.runtime.idas import ChunkFailure

    at = ChunkFailure("IDA_ERR_FAIL", "At t = 0.253 and h = 1e-12, the error test failed repeatedly", "")
    assert idas_integrator._retry_length(at, 1.0, 0.01, 64) == 24
    assert idas_integrator._retry_length(at, 1.0, 0.01, 10) == 9
    assert idas_integrator._retry_length(ChunkFailure("X", "no time here", ""), 1.0, 0.01, 64) == 32


@pytest.mark.slow      # 2000 IDAS restarts over 20 s; fast: test_hand_over_and_return_hold_both_constraint_levels
#                       (the chunked IDAS run with its first step),
#                       test_a_failed_watched_chunk_is_retried_up_to_just_before_where_idas_gave_up
def test_idas_restarted_at_every_output_keeps_its_accuracy(monkeypatch):
    """The cause of the error above, on a regular motion (released at −8°, never flat, IDAS
    alone): one IDAS call per output interval (2000 restarts in 20 s) stays within 1e-6 m of
    the exact motion (measured 3.3e-7 m; 5.4e-6 m with IDAS's own first step, 10⁻³ dt, whose
    order-1 error is far above rtol) — ``ChunkedIDAS.first_step``."""
    monkeypatch.setattr(idas_integrator, "CHUNKS", 10**6)
    monkeypatch.setattr(sys.modules[__name__], "THETA0", np.radians(-8.0))
    model = n_fourbar(1)
    traj = nc.simulate(model, 20.0, 0.01, rtol=1e-10, atol=1e-10, project=False)
    assert tip_error(traj, 1) < 1e-6


@pytest.mark.parametrize("room, slope, bend, full, expected", [
    (1.0, -0.1, 0.0, 100, 11),       # linear fall: crosses after 10 intervals, run to the 11th output
    (1.0, -0.1, 0.0125, 100, 100),   # the fall slows down enough never to cross: the longest call
    (1.0, -0.01, -0.02, 100, 10),    # accelerating fall: 1 − 0.02 n − 0.01 n² = 0 at n ≈ 9.05
    (1.0, 0.1, -0.002, 200, 64),     # rising, turns and comes back after ~108 intervals: a power of 2 below
    (1.0, 0.1, -0.002, 50, 50),      # ... at most full
    (0.0, 0.1, 0.0, 100, 1),         # at the limit already
])
def test_the_next_watched_call_ends_at_the_predicted_crossing(room, slope, bend, full, expected):
    """``room + n slope + n (n + 1)/2 bend = 0``: the call ends at the first output past the
    crossing when it is near, at a power of 2 below it when far, never beyond ``full``."""
    assert idas_integrator._chunk_to_limit(room, slope, bend, full) == expected


@pytest.mark.parametrize("N", [1, 10])
def test_stepper_with_rtol_follows_the_exact_motion_over_10_s(N):
    """The error-controlled stepper (order 4) through the eight flat positions, to 1e-6 m."""
    model = n_fourbar(N)
    traj = nc.simulate(model, 10.0, 0.01, method="stepper", rtol=1e-6)
    assert tip_error(traj, N) < 1e-6


@pytest.mark.parametrize("N", [1, pytest.param(10, marks=pytest.mark.slow)])   # N = 10: fast: N = 1, the same path
def test_stepper_at_tight_rtol_crosses_the_flat_positions(N):
    """rtol 1e-11: next to a flat position the KKT solves are ill-conditioned and the part of
    the step-doubling difference normal to the constraints stops falling with the step (it
    made the step collapse, status 7, at rtol below ~1e-9); measured on the tangent part the
    estimate stays regular.  All eight flat positions in 10 s, to 1e-9 m of the exact motion
    (measured: 8e-11 m for N = 1, 4.7e-11 m for N = 10), with few rejected steps."""
    model = n_fourbar(N)
    traj = nc.simulate(model, 10.0, 0.01, method="stepper", rtol=1e-11)
    assert traj.complete
    assert tip_error(traj, N) < 1e-9
    assert traj.info["stats"]["rejected_steps"] < 100
    assert not traj.info["error_estimate"]["exceeds_tolerance"]


def test_stepper_below_round_off_still_fails_loudly():
    """The tangent estimate is no licence to accept noise: at rtol 1e-16 (below double
    round-off) the steps are rejected until the run stops with a SimulationError, with the
    trajectory up to there."""
    model = n_fourbar(1)
    with pytest.raises(SimulationError, match="error-controlled stepper") as failure:
        nc.simulate(model, 1.0, 0.01, method="stepper", rtol=1e-16)
    assert failure.value.trajectory.t[-1] < 1.0


@pytest.mark.parametrize("N, t_end", [(1, 2.0), pytest.param(10, 1.0, marks=pytest.mark.slow)])   # N = 10 compiles
def test_idas_with_projection_stays_on_the_physical_branch(N, t_end):                       # its bridge; fast: N = 1
    """project=True: one output interval per IDAS call, projected after each; through every
    flat position (at t ≈ 0.42 s, ...) on the parallelogram branch."""
    model = n_fourbar(N)
    traj = nc.simulate(model, t_end, 0.01, rtol=1e-10, atol=1e-12, project=True)
    assert traj.complete and traj.info["projected_from"] == 0.0
    assert tip_error(traj, N) < 1e-5
    assert np.max(np.abs([model.phi(q) for q in traj.q])) < 1e-9
    assert traj.info["stats"]["rattle_intervals"] >= 1


def test_without_a_compiler_numpy_rattle_crosses_the_flat_positions(monkeypatch):
    """No C compiler: the bridge is NumPy RATTLE (steps of about sqrt(rtol) s), said by a
    warning; the run still stays on the physical branch (second order: 1e-4 s steps here)."""
    def no_compiler(model, cflags=None):
        raise CompilerNotFound("no C compiler found (test)")

    monkeypatch.setattr(idas_integrator, "load_stepper", no_compiler)
    model = n_fourbar(1)
    with pytest.warns(NoCompilerWarning, match="NumPy RATTLE"):
        traj = nc.simulate(model, 0.6, 0.01, rtol=1e-8)
    assert traj.info["stats"]["rattle_intervals"] >= 1
    assert tip_error(traj, 1) < 1e-5


def test_the_near_singular_limit_scales_with_the_starting_conditioning():
    """A long chain of parallelograms is less well conditioned everywhere (σ_min/σ_max of A
    at 45°: 0.38 for N = 1, 0.025 for N = 40): the limit scales with the start, so that for
    N = 1 and N = 40 alike, IDAS is replaced 5–6° from the flat position, not everywhere."""
    for N in (1, 40):
        model = n_fourbar(N)
        projector = ManifoldProjector(model, model.p0, 1e-12)
        projector.start(0.0, np.concatenate([model.q0, model.v0]))

        def at(degrees):
            th = np.radians(degrees)
            q = np.concatenate([[k + np.cos(th), np.sin(th)] for k in range(N + 1)])
            return projector.near_singular(0.0, np.concatenate([q, np.zeros_like(q)]))

        assert not at(45) and not at(10) and at(4) and at(-1)


def test_rattle_bridge_crosses_the_flat_position_at_second_order():
    """The NumPy RATTLE bridge (rank-robust) from rest at 45° through the flat position at
    t ≈ 0.42 s to 0.5 s: on the physical branch, error ÷ 4 when the step is halved."""
    model = n_fourbar(1)
    x0 = np.concatenate([model.q0, model.v0])
    ref = exact_tip(1, np.array([0.0, 0.5]))[-1]
    errors = [np.linalg.norm(rattle_interval(model, 0.0, x0, np.zeros(0), model.p0, 0.5, n, 1e-14)[:2] - ref)
              for n in (250, 500)]
    assert errors[1] < 3e-6
    assert 3.5 < errors[0] / errors[1] < 4.5


@pytest.mark.parametrize("N", [1, pytest.param(10, marks=pytest.mark.slow)])   # N = 10 compiles its bridge; fast: N = 1
def test_idas_by_default_is_replaced_from_the_first_flat_position(N):
    """project="auto" (the default): the chunk that meets the first near-singular
    configuration is cut there and the interval crossed by the compiled stepper
    (``projected_from``: the first such output time), and the run stays on the physical branch."""
    model = n_fourbar(N)
    traj = nc.simulate(model, 1.0, 0.01, rtol=1e-10, atol=1e-12)
    assert traj.info["project"] == "auto" and 0.3 < traj.info["projected_from"] < 0.42    # the first flat position
    assert tip_error(traj, N) < 1e-5


def test_idas_without_projection_leaves_the_branch_or_stops():
    """The failure mode the projection removes (kept visible): without it, IDAS either
    switches to the crossed branch at the first flat position or stops with a SimulationError."""
    model = n_fourbar(1)
    try:
        traj = nc.simulate(model, 1.0, 0.01, rtol=1e-10, atol=1e-12, project=False)
    except SimulationError as e:
        assert e.trajectory is not None
        return
    assert tip_error(traj, 1) > 1e-2


def test_stepper_stays_on_the_physical_branch():
    """The RATTLE stepper through the flat positions (second order: error ∝ dt²)."""
    model = n_fourbar(1)
    traj = nc.simulate(model, 2.0, 0.01, method="stepper", substeps=20)
    assert tip_error(traj, 1) < 1e-4


def test_a_failing_kkt_start_is_a_simulation_error(monkeypatch):
    """An interval starting where the KKT system cannot be solved (here: accel made to fail)
    is a SimulationError with the time reached and the trajectory, never a raw CasADi error."""
    model = n_fourbar(1)

    def broken(*_):
        return np.full(model.nq + model.nc, np.nan)

    calls = {"n": 0}
    real = idas_integrator.robust_algebraic

    def fails_later(m, t, q, v, u, p):
        calls["n"] += 1
        return broken() if t > 0.25 else real(m, t, q, v, u, p)

    monkeypatch.setattr(idas_integrator, "robust_algebraic", fails_later)
    with pytest.raises(SimulationError, match="not finite") as info:
        nc.simulate(model, 1.0, 0.01, rtol=1e-8)
    e = info.value
    assert 0.2 <= e.time <= 0.3 and e.trajectory is not None and len(e.trajectory) > 1


def test_watching_leaves_a_regular_run_alone():
    """A model far from any singular configuration (a stiff spring, 1 s outputs): the
    default run bridges nothing and is as accurate as IDAS alone (project=False), both
    against a run at rtol 1e-13.  It is not the same run: the watch splits each output
    interval into 0.01 s parts (measured: 2.4e-7 watched, 1.5e-6 alone)."""
    s = nc.System("stiff_watch", gravity=(0.0, 0.0, -9.81))
    bar = s.add_bar("bar", "rr", mass=1.0, ends=[s.ground.point((0.0, 0.0, 0.0)), (1.0, 0.0, 0.0)])
    mass = s.add_point("mass", mass=0.5, position=(1.25, 0.0, 0.0), velocity=(0.0, 0.0, 0.3))
    s.add_force(nc.Spring(bar, (0.5, 0.0, 0.0), mass, (0.0, 0.0, 0.0), k=1e4, rest_length=0.25))
    model = s.build()
    watched = nc.simulate(model, 4.0, 1.0, rtol=1e-10, atol=1e-12)
    plain = nc.simulate(model, 4.0, 1.0, rtol=1e-10, atol=1e-12, project=False)
    reference = nc.simulate(model, 4.0, 1.0, rtol=1e-13, atol=1e-14, project=False)
    assert watched.info["stats"]["rattle_intervals"] == 0 and watched.info["projected_from"] is None
    assert watched.info["branch_changes"] == [] and watched.info["watched_interval"] == pytest.approx(0.01)
    error = np.abs(watched.q - reference.q).max()
    assert error < 1e-6 and error < 2 * max(np.abs(plain.q - reference.q).max(), 1e-8)
