"""``method="idas"``: SUNDIALS IDAS (through CasADi) on the index-1 DAE, behind the
integrator seam (:mod:`ncgen.runtime.integrator`): chunked calls with a progress bar, a
Python feedback interval by interval, and the watch for singular configurations (``project``)
with its RATTLE bridge and branch test (see :func:`~ncgen.runtime.simulation.simulate`)."""
from __future__ import annotations

import math
import time
import warnings

import numpy as np

from ncgen.assembly.joint_ode import dae_with_inputs
from ncgen.assembly.manifold import NEAR_SINGULAR, RATE_BLOCK, ManifoldProjector, robust_algebraic
from ncgen.codegen.load import NoCompilerWarning
from ncgen.errors import BranchWarning, CompilerNotFound, NcgenError, SimulationError, SimulationInterrupted, option
from ncgen.interrupts import raise_if_interrupted
from ncgen.runtime.backend_policy import choose_backend
from ncgen.runtime.dae import load_dae
from ncgen.runtime.diagnose import explain, shift_time
from ncgen.assembly.derived import power_parts_function
from ncgen.runtime.energy_balance import idas_report, interval_works
from ncgen.runtime.feedback import FeedbackFailed, with_partial
from ncgen.runtime.idas import ChunkedIDAS, ChunkFailure
from ncgen.runtime.inputs import hold_columns
from ncgen.runtime.integrator import Run, refuse_integrator
from ncgen.runtime.idas_options import IdasOptions
from ncgen.runtime.options import SimulationOptions
from ncgen.runtime.simulation_progress import Progress
from ncgen.runtime.rolling_idas import check_rolling_idas, simulate_rolling_idas
from ncgen.runtime.rattle_bridge import RattleFailure, compiled_interval, rattle_interval
from ncgen.runtime.run_start import failed_at_start, initial_multipliers, natural_feedback
from ncgen.runtime.stepper_checks import is_conservative
from ncgen.runtime.stepper_library import load_stepper
from ncgen.runtime.trajectory import Trajectory

#: What :func:`_run` returns as its failure when Ctrl-C stopped it.
INTERRUPTED = "interrupted"
#: The run is split into at most this many chunks (progress updates; see ncgen.runtime.idas).
CHUNKS = 20
#: Largest ``nq · nc`` that ``project="auto"`` watches (an SVD of A per output time).
AUTO_MAX_SIZE = 100_000
#: Output intervals of the first IDAS call while watching for singular configurations
#: (``project="auto"``; later chunks are sized from how fast ``σ_min/σ_max`` of A changes).
WATCHED_CHUNK = 10
#: Largest spacing (s) of the grid on which a watched run (``project`` ``"auto"`` or ``True``)
#: checks ``σ_min/σ_max`` of A and places its IDAS calls and bridges: each output interval is
#: split into ``ceil(dt / WATCHED_SAMPLE)`` equal parts, so that the run is the same for every
#: output grid that is a multiple of it (a user's choice for plotting; finer grids are used
#: as they are).  The ratio's rate is watched too: an interval across which the ratio, moving
#: at the larger of its end rates, could dip below the near-singular limit and come back
#: unseen is bridged (``_run``: ``hidden``), so a faster motion is bridged more, not missed.
#: The four-bar of IFToMM A02 crosses the band around a flat position in about 0.05 s; with
#: a spacing of 0.1 s it still stays on its branch over 20 s (to 3e-6 m,
#: ``tests/test_singular_output_grid.py``); with 0.5 s IDAS failed loudly at a flat position.
WATCHED_SAMPLE = 0.01
#: A predicted crossing of the near-singular limit closer than this many output intervals is
#: run to (one IDAS call); a farther one is approached by a power of 2 below it.
CLOSE_CROSSING = 16
#: IDAS steps per output interval at most while watching (``project="auto"`` or ``True``):
#: IDAS can spend its whole ``max_steps`` creeping up to a singular configuration.  A chunk
#: that fails is retried up to just before where IDAS gave up; an interval that needs more steps away from
#: a singular configuration gets the full ``max_steps`` and lifts the limit for the run.
WATCHED_MAX_STEPS = 1_000
#: ``σ_min/σ_max`` of A at the start of an interval that IDAS fails on (projecting), below
#: which the failure is put down to a singular configuration ahead and the interval bridged.
FAILING_NEAR_SINGULAR = 0.25
#: Smallest rtol and atol of the compiled stepper standing in for IDAS next to a singular
#: configuration: the tightest at which it was measured through the flat positions of the
#: N four-bar of IFToMM A02 (N = 1, 10; rtol 1e-10 to 1e-12 cross all eight in 10 s, its
#: error estimate being taken on the tangent part of the step, see ``templates/c/runtime/ncgen_adaptive.h``).
BRIDGE_MIN_TOL = 1e-12
#: The bridge's tolerances are the run's divided by this (at least :data:`BRIDGE_MIN_TOL`):
#: the adaptive stepper's error per unit time at a given tolerance is larger than IDAS's next
#: to a singular configuration.  In the 3D N four-bar (N = 1, rtol = atol = 1e-10, 20 s, 8 %
#: of the time bridged) the error to the exact motion was 1.6e-6 m with a tenth of the run's
#: tolerances, 4.8e-7 m with a hundredth (the 2D form: 1.7e-7 and 2.1e-7 m); the bridge is
#: compiled and short, so the tighter tolerance costs little.
BRIDGE_TIGHTER = 100.0
#: Branch test of a bridged interval (``_branch_changes``): the part of its chord outside the
#: tangent motions at its ends, relative to its length, above which the motion changed branch.
#: On one branch it is about half the angle the tangent turns over the interval; across to
#: another, about the sine of the angle between the branches' tangents.  Measured on the
#: four-bar of IFToMM A02 staying on its branch: at most 0.14 (N = 1 ... 40, 2D and 3D,
#: intervals of 0.01 s; below 0.3 with 0.1 s); from its parallelogram branch at 6° to the other
#: branch at the flat position's other side: 0.46.
BRANCH_DEPARTURE = 0.3
#: Largest number of NumPy RATTLE steps across one output interval (``_bridge`` without a
#: C compiler).
BRIDGE_MAX_STEPS = 20_000


class IdasIntegrator:
    """``method="idas"``: IDAS on the index-1 DAE (:func:`_simulate_idas`) behind the
    integrator seam (:mod:`ncgen.runtime.integrator`)."""

    METHOD = "idas"
    Options = IdasOptions

    def __init__(self, model, opts: SimulationOptions):
        if getattr(model, "contact_model", "smooth") == "nonsmooth" and model.nk:
            built = option("contacts='nonsmooth'", "--contacts nonsmooth")
            stepper = option("method='stepper'", "--method stepper")
            smooth = option("build the model with contacts='smooth'", "--contacts smooth")
            raise NcgenError(f"simulate: model {model.name!r} was built with {built}, which only the compiled "
                             f"stepper handles: use {stepper}, or {smooth} (compliant contacts) for IDAS")
        refuse_integrator(opts, self.METHOD)
        self.model, self.opts = model, IdasOptions.of(opts)
        if model.rolling:
            check_rolling_idas(model, self.opts)

    def run(self, run: Run) -> Trajectory:
        if self.model.rolling:
            return simulate_rolling_idas(self.model, run, self.opts)
        return _simulate_idas(self.model, run, self.opts)


def _simulate_idas(model, run: Run, opts: IdasOptions) -> Trajectory:
    """IDAS over the grid ``run.t`` from the consistent state ``(run.q, run.v)`` (see
    :func:`simulate`); a compiled ``run.controller`` and the joint dynamics enter its DAE, a
    Python ``run.feedback`` is called at the start of every output interval."""
    t, U, columns, pv, q, v, feedback = run.t, run.U, run.columns, run.p, run.q, run.v, run.feedback
    t0, hold, project = float(t[0]), opts.hold, opts.project
    rtol, atol = 1e-8 if opts.rtol is None else opts.rtol, 1e-10 if opts.atol is None else opts.atol
    dae, used, choice, extra = _idas_dae(model, run, opts)
    if feedback is not None:
        columns = _feedback_at_start(model, run, opts, dae, used)
    z0 = _start_rates(model, run, dae, extra)
    watch = project == "auto" and model.nq * model.nc <= AUTO_MAX_SIZE and model.nc > 0
    projector = ManifoldProjector(model, pv, atol) if (project is True or watch) and feedback is None else None
    m = 1 if projector is None else math.ceil((t[1] - t[0]) / WATCHED_SAMPLE - 1e-9)
    balance = feedback is None and not is_conservative(model, inputs=bool(np.any(U != 0)) or extra is not None)
    runner = _chunked_idas(model, dae, used, extra, opts, float(t[1] - t[0]) / m, balance, (rtol, atol), pv)
    if feedback is not None:
        return _idas_feedback(model, runner, run, z0, opts, {"method": "idas", "backend": used, "rtol": rtol,
                                                             "atol": atol}, dae)
    if projector is not None:
        projector.start(t0, np.concatenate([q, v]))
    bridge = _bridge(model, runner, pv, rtol, atol) if projector is not None else None
    bar = Progress(t0, t[-1], opts.progress, label=f"simulating {model.name}: ")
    start, cpu_start = time.perf_counter(), time.process_time()
    grid = t if m == 1 else t[0] + (t[-1] - t[0]) * np.arange(m * (len(t) - 1) + 1) / (m * (len(t) - 1))
    W = np.full((len(grid), 5), np.nan) if balance else None      # each interval's work by class (quadratures)
    try:
        X, Z, failure, projected_from = _run(_GridRun(runner, grid, np.concatenate([q, v]), z0, np.repeat(
            columns, m, axis=1), pv, None if projector is None else (projector, bridge), watch, W), bar)
    finally:
        bar.close()
    k, reached = (len(X) - 1) // m, float(grid[len(X) - 1])    # the last output reached; the last good time
    message = _stop_message(model, failure, grid, X, Z, U[k], pv, dae, t[k])
    watch_stats, watch_info = _watch_report(model, projector, bridge, grid, X)
    work = None if W is None else _output_works(model, grid, X, Z, U, m, pv, W)
    X, Z, nq = X[::m], Z[::m], model.nq
    info = {"method": "idas", "backend": used, "backend_reason": choice.reason if used == choice.backend
            else "no C compiler", "rtol": rtol, "atol": atol, "hold": hold,
            "auto": run.why_not, "joint_dynamics": bool(opts.joint_dynamics),
            "controller": None if run.controller is None else run.controller.describe(),
            "linear_solver": opts.linear_solver, "stats": dict(runner.stats, **watch_stats), "project": project,
            "projected_from": None if projected_from is None else float(grid[projected_from]), **watch_info,
            "wall_time": time.perf_counter() - start, "cpu_time": time.process_time() - cpu_start,
            "complete": failure is None}
    if message is not None:
        info["message"] = message
    U_applied = _applied_inputs(model, extra, t[:k + 1], U[:k + 1], X, pv)
    traj = Trajectory.from_states(model, t[:k + 1], X[:, :nq], X[:, nq:], Z[:, nq:], U_applied, pv, info)
    traj.info["energy"] = idas_report(model, traj, is_conservative(model, inputs=bool(np.any(U_applied != 0))), work)
    if failure is not None:
        error = SimulationInterrupted if failure is INTERRUPTED else SimulationError
        raise error(message, time=reached, trajectory=traj)
    return traj


def _applied_inputs(model, extra, t, U, X, p) -> np.ndarray:
    """The inputs applied at the output times ``t``: ``U`` plus ``extra``'s (a compiled
    controller's and the joint dynamics') at the states ``X``."""
    if extra is None:
        return U
    nq = model.nq
    return U + np.array([_extra_value(model, extra, t[i], X[i, :nq], X[i, nq:], p) for i in range(len(t))])


def _idas_dae(model, run: Run, opts: IdasOptions):
    """``(dae, used, choice, extra)``: the index-1 DAE on the backend chosen (``used``: the
    one loaded, ``choice``: :func:`choose_backend`'s), with the inputs ``extra`` of a compiled
    controller and the joint dynamics in it (None without them)."""
    choice = choose_backend(model, len(run.t) - 1, opts.backend)
    dae, used = load_dae(model, "auto" if opts.backend == "auto" and choice.backend == "compiled" else choice.backend)
    extra = _natural_inputs(model, run.controller, opts.joint_dynamics)
    if extra is not None:
        dae = dae_with_inputs(model, dae, extra)
    return dae, used, choice, extra


def _start_rates(model, run: Run, dae, extra) -> np.ndarray:
    """``z0 = [a; λ]`` at the start: the KKT multipliers and accelerations of ``(run.q, run.v)``
    with the first input (``extra``'s included)."""
    t0, q, v, pv = float(run.t[0]), run.q, run.v, run.p
    u0 = run.U[0] + _extra_value(model, extra, t0, q, v, pv)
    lam = initial_multipliers(model, t0, q, v, u0, pv, dae)
    a = np.array(model.functions["ode"](t0, q, v, lam, u0, pv)[1]).reshape(-1)
    return np.concatenate([a, lam])


def _chunked_idas(model, dae, used: str, extra, opts: IdasOptions, h: float, balance: bool, tols: tuple, pv):
    """IDAS in chunks over intervals of ``h`` s (:class:`ChunkedIDAS`), ``tols = (rtol, atol)``;
    ``balance``: the work of each class integrated as quadratures; the algebraic state of a
    (re)start solved with ``extra``'s inputs added."""
    rtol, atol = tols
    return ChunkedIDAS(dae, h=h, nu=model.nu, hold=opts.hold, rtol=rtol, atol=atol,
                       max_steps=opts.max_steps, linear_solver=opts.linear_solver, expand=(used == "vm"),
                       power=power_parts_function(model) if balance else None, extra=extra,
                       algebraic=lambda tk, x, uk: _algebraic(
                           model, tk, x, uk + _extra_value(model, extra, tk, x[:model.nq], x[model.nq:], pv), pv))


def _stop_message(model, failure, grid, X, Z, u, p, dae, t_out: float) -> str | None:
    """The message of a run on ``grid`` that stopped at its last state ``X[-1], Z[-1]`` (input
    ``u``; ``t_out``: the last output time reached) by Ctrl-C or IDAS's failure; None when it
    did not stop."""
    if failure is None:
        return None
    reached = float(grid[len(X) - 1])
    if failure is INTERRUPTED:
        message = f"simulation of {model.name!r} interrupted (Ctrl-C) at t = {reached:.6g} s"
    else:
        message = _failure_message(model, failure, grid, len(X) - 1, X[-1], Z[-1, model.nq:], u, p, dae)
    return message + f" On the output grid it ends at t = {t_out:.6g} s." if t_out < reached else message


def _watch_report(model, projector, bridge, grid, X) -> tuple[dict, dict]:
    """``(stats, info)`` the watch for singular configurations adds to a run's: the projector's
    counts, the bridged intervals and the largest branch departure (:func:`_branch_changes`);
    the watched grid's spacing and the branch changes (None and none without a watch)."""
    if projector is None:
        return {}, {"watched_interval": None, "branch_changes": []}
    changes, departure = _branch_changes(model, projector, bridge, grid, X)
    return (dict(projector.counts, rattle_intervals=bridge.count, branch_departure=departure),
            {"watched_interval": float(grid[1] - grid[0]), "branch_changes": changes})


def _output_works(model, grid, X, Z, U, m: int, p, W) -> np.ndarray:
    """The work of each class over each output interval (rows at the output times) from the
    quadratures ``W`` on the watched ``grid`` (``m`` intervals an output interval)."""
    u_grid = U[np.minimum(np.arange(len(X)) // m, len(U) - 1)]
    return interval_works(model, grid[:len(X)], X, Z, u_grid, p, W[:len(X)])[::m]


def _natural_inputs(model, controller, joint_dynamics: bool):
    """``(t, q, v, p) -> u_extra`` of a compiled controller and the joint dynamics, or None."""
    if controller is None and not joint_dynamics:
        return None
    from ncgen.assembly.joint_ode import armature_vector, natural_inputs_function

    if joint_dynamics and np.any(armature_vector(model)):
        raise NcgenError("joint_dynamics: armature (joint.dynamics['armature']) is honoured by method='joint' only "
                         "(the natural-coordinate mass matrix is constant); use method='joint' or drop it")
    from ncgen.model.controllers import ComputedTorque

    inverse = None
    if isinstance(controller, ComputedTorque):
        from ncgen.assembly.tree_dynamics import recursive_inverse_dynamics_function
        inverse = recursive_inverse_dynamics_function(model)
    return natural_inputs_function(model, inverse, controller=controller, joint_dynamics=joint_dynamics)


def _extra_value(model, extra, t: float, q, v, p) -> np.ndarray:
    if extra is None:
        return np.zeros(model.nu)
    return np.array(extra(t, q, v, p)).reshape(-1)




def _feedback_at_start(model, run: Run, opts: IdasOptions, dae, used: str) -> np.ndarray:
    """``run.U[0]`` set to the feedback at the start (a failure there raised with the state it
    failed at) and the input columns held zoh, the only hold a feedback takes."""
    t0, q, v, pv = float(run.t[0]), run.q, run.v, run.p
    if opts.hold != "zoh":
        raise NcgenError("hold='linear' with a feedback u(t, q, v): the feedback is held over each output "
                         "interval (zoh); use hold='zoh'")
    try:
        run.U[0] = natural_feedback(model, run.feedback, t0, q, v, pv)
    except FeedbackFailed as e:
        lam = initial_multipliers(model, t0, q, v, np.zeros(model.nu), pv, dae)
        raise failed_at_start(model, e, t0, q, v, pv, lam, {"method": "idas", "backend": used,
                                                            "feedback": run.feedback[0], "complete": False}) \
            from e.__cause__
    return hold_columns(run.U, run.t, opts.hold)


def _idas_feedback(model, runner, run: Run, z0: np.ndarray, opts: IdasOptions, info: dict, dae) -> Trajectory:
    """IDAS one output interval at a time from ``(run.q, run.v)`` and ``z0 = [a; λ]``, the
    feedback evaluated at the start of each (held zoh); ``info``: the trajectory's method,
    backend and tolerances."""
    t, U, p, feedback, nq = run.t, run.U, run.p, run.feedback, model.nq
    X = np.empty((len(t), 2 * nq))
    Z = np.empty((len(t), nq + model.nc))
    X[0], Z[0] = np.concatenate([run.q, run.v]), z0
    bar = Progress(t[0], t[-1], opts.progress, label=f"simulating {model.name}: ")
    start, cpu_start, failure, k = time.perf_counter(), time.process_time(), None, 0
    try:
        while k < len(t) - 1:
            if k:
                try:
                    U[k] = natural_feedback(model, feedback, float(t[k]), X[k, :nq], X[k, nq:], p)
                except FeedbackFailed as e:
                    failure = e
                    break
            try:
                X[k + 1:k + 2], Z[k + 1:k + 2] = runner.advance(t[k], X[k], Z[k], U[k][:, None], p)
            except ChunkFailure as e:
                failure = e
                break
            k += 1
            bar.update(t[k])
    finally:
        bar.close()
    U[k] = U[k - 1] if k else U[0]
    info = {**info, "hold": "zoh", "feedback": feedback[0], "linear_solver": opts.linear_solver,
            "stats": dict(runner.stats), "wall_time": time.perf_counter() - start,
            "cpu_time": time.process_time() - cpu_start, "complete": failure is None}
    traj = Trajectory.from_states(model, t[:k + 1], X[:k + 1, :nq], X[:k + 1, nq:], Z[:k + 1, nq:], U[:k + 1], p,
                                  info)
    if isinstance(failure, FeedbackFailed):
        raise with_partial(failure, traj) from failure.__cause__
    if failure is not None:
        message = _failure_message(model, failure, t, k, X[k], Z[k, nq:], U[k], p, dae)
        traj.info["message"] = message
        raise SimulationError(message, time=float(t[k]), trajectory=traj)
    return traj


def _algebraic(model, t: float, x, u, p) -> np.ndarray:
    """``z = [a; λ]`` consistent with the state ``x = [q; v]`` and input ``u`` at ``t``: the KKT
    system, which is the DAE's algebraic equations, solved rank-robustly
    (:func:`~ncgen.assembly.manifold.robust_algebraic`).  Non-finite values raise
    :class:`~ncgen.runtime.idas.ChunkFailure` (never a raw CasADi error)."""
    z = robust_algebraic(model, t, x[:model.nq], x[model.nq:], u, p)
    if not np.all(np.isfinite(z)):
        raise ChunkFailure("KKT_FAIL", "At t = 0, the accelerations and multipliers are not finite "
                           "at the start of the output interval", "accel")
    return z


class _bridge:
    """IDAS's stand-in over one output interval next to a singular configuration
    (:mod:`ncgen.runtime.rattle_bridge`): the model's compiled error-controlled stepper
    (compiled on first use) with tolerances ``max(rtol / BRIDGE_TIGHTER, BRIDGE_MIN_TOL)`` and
    ``max(atol / BRIDGE_TIGHTER, BRIDGE_MIN_TOL)``, or,
    without a C compiler, NumPy RATTLE steps of about ``sqrt(rtol)`` s (at most
    :data:`BRIDGE_MAX_STEPS`); ``count`` of uses."""

    def __init__(self, model, runner: ChunkedIDAS, p, rtol: float, atol: float):
        self.model, self.runner, self.p, self.rtol, self.atol = model, runner, p, rtol, atol
        self.tols = max(rtol / BRIDGE_TIGHTER, BRIDGE_MIN_TOL), max(atol / BRIDGE_TIGHTER, BRIDGE_MIN_TOL)
        self.count = 0
        self.spans: list[tuple[float, float]] = []     # the bridged intervals
        self.stepper = None            # the compiled stepper; False: no C compiler
        self.h_next, self.t_next = 0.0, None

    def _compiled(self):
        if self.stepper is None:
            try:
                self.stepper = load_stepper(self.model)
            except CompilerNotFound as e:
                warnings.warn(f"no C compiler found ({e}): IDAS is replaced next to singular configurations by "
                              f"NumPy RATTLE steps of about sqrt(rtol) s, slower and less accurate than the "
                              f"compiled stepper; install gcc", NoCompilerWarning, stacklevel=4)
                self.stepper = False
        return self.stepper

    def _stepped(self, stepper, t0: float, t1: float, x, u0, u1):
        """The compiled stepper over ``[t0, t1]`` (raises
        :class:`~ncgen.runtime.rattle_bridge.RattleFailure`)."""
        lam = _algebraic(self.model, t0, x, u0, self.p)[self.model.nq:]
        U = np.vstack([u0, u1]) if self.model.nu else None
        h0 = self.h_next if self.t_next == t0 else 0.0
        x1, self.h_next = compiled_interval(stepper, x, lam, t0, t1 - t0, U, self.runner.hold == "linear", self.p,
                                            *self.tols, h0)
        self.t_next = t1
        return x1

    def __call__(self, t0: float, t1: float, x, column):
        """``(x1, z1)``: the state and algebraic state at ``t1`` from ``x`` at ``t0``."""
        u0, u1 = self.runner._input(column, t0), self.runner._input(column, t1)
        stepper = self._compiled()
        try:
            if stepper:
                x1 = self._stepped(stepper, t0, t1, x, u0, u1)
            else:
                n = min(BRIDGE_MAX_STEPS, max(1, math.ceil((t1 - t0) / math.sqrt(self.rtol))))
                x1 = rattle_interval(self.model, t0, x, u0, self.p, t1 - t0, n, self.atol)
        except RattleFailure as e:
            raise ChunkFailure("RATTLE_FAIL", str(e), "rattle") from None
        self.count += 1
        self.spans.append((t0, t1))
        return x1, _algebraic(self.model, t1, x1, u1, self.p)


class _GridRun:
    """The states of one IDAS run on the grid ``t`` (the watched grid, see
    :data:`WATCHED_SAMPLE`): rows of ``X`` (``[q; v]``) and ``Z`` (``[a; λ]``) filled up to
    ``top``; ``watch``: ``(projector, bridge)`` (the near-singular watch, see :func:`_run`) or
    None; ``work`` (an array of a row per grid time, or None): row ``k + 1`` receives the work
    of each class over interval ``k`` from IDAS's quadratures (``runner.last_work``), a bridged
    interval's stays as it was.  Watching, it remembers ``σ_min/σ_max`` of A and its rate at
    the outputs (``R``), the ratio's last second difference seen by IDAS (``bend``), where IDAS
    resumed after the last bridge and its stretches between bridges, and ``since``: the first
    output from which the run was bridged or projected."""

    def __init__(self, runner: ChunkedIDAS, t, x0, z0, columns, p, watch=None, auto=False, work=None):
        self.runner, self.t, self.columns, self.p, self.auto, self.work = runner, t, columns, p, auto, work
        self.projector, self.bridge = watch if watch is not None else (None, None)
        self.watching = watch is not None
        self.n_int = len(t) - 1
        self.full = 1 if self.watching and not auto else max(1, math.ceil(self.n_int / CHUNKS))
        self.X = np.empty((len(t), len(x0)))
        self.Z = np.empty((len(t), len(z0)))
        self.R = np.full((len(t), 2), np.nan)     # σ_min/σ_max of A and its rate at the grid times (watching)
        self.h = float(t[1] - t[0])
        self.X[0], self.Z[0] = x0, z0
        self.since = None if auto or not self.watching else 0
        self.max_steps = WATCHED_MAX_STEPS if self.watching else None
        self.top = 0                              # the last output with a state
        self.bend = np.nan                        # the last second difference of that ratio seen by IDAS
        self.resumed, self.stretches = None, []   # where IDAS resumed after the last bridge; its stretches between

    def advance(self, k, n, max_steps=None):
        """IDAS over intervals k ... k + n − 1."""
        X, Z, t = self.X, self.Z, self.t
        X[k + 1:k + n + 1], Z[k + 1:k + n + 1] = self.runner.advance(t[k], X[k], Z[k], self.columns[:, k:k + n],
                                                                     self.p, max_steps)
        if self.work is not None:
            self.work[k + 1:k + n + 1] = self.runner.last_work
        self.R[k + 1:k + n + 1] = np.nan
        self.top = k + n

    def ratio(self, i) -> float:
        """``σ_min/σ_max`` of A at output i, with those of the outputs after it up to
        :data:`~ncgen.assembly.manifold.RATE_BLOCK` (evaluated together)."""
        R = self.R
        if np.isnan(R[i, 0]):
            j = max(i + 1, min(self.top + 1, i + RATE_BLOCK))
            R[i:j] = self.projector.ratio_rates(self.t[i:j], self.X[i:j])
            raise_if_interrupted()
        return R[i, 0]

    def near(self, i, limit=NEAR_SINGULAR) -> bool:
        return self.ratio(i) < limit * self.projector.scale

    def hidden(self, i) -> bool:
        """Whether the ratio could have dipped below the near-singular limit between grid
        times i − 1 and i, both above it: going down to the limit and back takes a travel of
        ``(r_{i−1} − limit) + (r_i − limit)``, which the ratio, moving at the larger of its two
        end rates, covers within the interval."""
        limit = NEAR_SINGULAR * self.projector.scale
        room = self.ratio(i - 1) + self.ratio(i) - 2.0 * limit
        return room < max(abs(self.R[i - 1, 1]), abs(self.R[i, 1])) * self.h

    def chunk(self, k) -> int:
        """Intervals of the next IDAS call from output k (see :func:`_run`)."""
        if not self.watching:
            return self.full
        if not np.isfinite(self.bend) or k == 0:
            return min(self.full, WATCHED_CHUNK)
        limit = NEAR_SINGULAR * self.projector.scale
        n = _chunk_to_limit(self.ratio(k) - limit, self.ratio(k) - self.ratio(k - 1), self.bend, self.full)
        if k == self.resumed and self.stretches:    # just after a bridge: no longer than the last stretches
            n = min(n, max(1, min(self.stretches[-2:]) - 1))
        return n

    def observe(self, k0, k):
        """Update ``bend`` from the ratios at outputs k0 − 1 ... k (IDAS's, away from the flat
        position, where the ratio is smooth)."""
        r = np.array([self.ratio(i) for i in range(max(0, k0 - 1), k + 1)])
        if len(r) > 2:
            self.bend = float(np.diff(r, 2)[-1])

    def bridged(self, k) -> int:
        """Interval k crossed by the bridge from the projected state."""
        self.since = k if self.since is None else self.since
        if self.resumed is not None and k > self.resumed:
            self.stretches.append(k - self.resumed)
        self.resumed = k + 1
        X, Z, t = self.X, self.Z, self.t
        X[k] = self.projector(t[k], X[k])
        X[k + 1], Z[k + 1] = self.bridge(t[k], t[k + 1], X[k], self.columns[:, k])
        self.R[k:k + 2] = np.nan
        self.top = k + 1
        return k + 1

    def single(self, k) -> int:
        """Interval k by IDAS (first with the watched step limit), else, watching and not far
        from a singular configuration (:data:`FAILING_NEAR_SINGULAR`), bridged.  An interval
        that needs more steps than the limit away from one lifts the limit for the run."""
        try:
            self.advance(k, 1, self.max_steps)
            return k + 1
        except ChunkFailure:
            if self.watching and self.near(k, FAILING_NEAR_SINGULAR):
                return self.bridged(k)
            if self.max_steps is None:
                raise
        self.advance(k, 1)
        self.max_steps = None
        return k + 1

    def cut(self, k0, k) -> int:
        """Watching, after IDAS from output k0 to k: the chunk cut at the last output before
        the first that is near-singular or could hide a near-singular configuration, crossed
        by the bridge; the output to go on from."""
        first = next((i for i in range(k0 + 1, k + 1) if self.near(i) or self.hidden(i)), None)
        self.observe(k0, k if first is None else first)
        return k if first is None else self.bridged(first - 1)

    def project(self, k):
        """The state at output k projected onto the constraints."""
        self.X[k] = self.projector(self.t[k], self.X[k])
        self.R[k] = np.nan


def _run(run: _GridRun, bar: Progress):
    """States on the grid up to the end or the first failure: ``(X, Z, failure or None,
    index of the first output time from which the run was bridged or projected, or None)``.

    IDAS over chunks of several output intervals (one with ``project=True``); a failed
    chunk is retried one interval at a time, to keep every state before the failure
    (watching: shorter, ending before where IDAS gave up, then chunks again).
    Watching (``run.watch``: ``project`` True or ``"auto"``, see :func:`simulate`) every output
    configuration is watched (``σ_min/σ_max`` of A): the first chunk is at most
    :data:`WATCHED_CHUNK` intervals, later ones end at the first output past where that
    ratio would reach the near-singular limit by its slope and bend at the last outputs
    (:func:`_chunk_to_limit`), the first after a bridge no longer than the shorter of the last
    two IDAS stretches between bridges (a periodic motion meets its next flat position about
    as far on); a chunk that fails is tried again up to just before where IDAS gave up
    (:func:`_retry_length`); a chunk that
    reaches the limit, or has an interval across which the ratio could dip below it unseen
    (``hidden``: its rate at both ends), is cut at the last output before it; every interval
    that starts or ends at a near-singular configuration, that could hide one, or that IDAS
    fails on not far from one (:data:`FAILING_NEAR_SINGULAR`), is crossed by the bridge
    instead, from the projected state.  ``run.auto=False``: the state is also projected after
    every interval."""
    k, n_int = 0, run.n_int
    cap = n_int
    while k < n_int:
        try:
            raise_if_interrupted()
            if run.watching and run.near(k):
                k = run.bridged(k)
            else:
                k0, n = k, min(run.chunk(k), n_int - k, cap)
                try:
                    run.advance(k, n, run.max_steps)
                    k, cap = k + n, n_int
                except ChunkFailure as e:
                    if run.watching and n > 1:           # again from k, ending before where IDAS gave up
                        cap = _retry_length(e, float(run.t[k]), run.h, n)
                        continue
                    k = run.single(k)
                    while not run.watching and k < k0 + n:
                        k = run.single(k)
                if run.watching:
                    k = run.cut(k0, k)
        except ChunkFailure as last:
            return run.X[:k + 1], run.Z[:k + 1], last, run.since
        except KeyboardInterrupt:
            return run.X[:k + 1], run.Z[:k + 1], INTERRUPTED, run.since
        except SystemError:                  # Ctrl-C inside a C call that then returned a value
            try:
                raise_if_interrupted()
            except KeyboardInterrupt:
                return run.X[:k + 1], run.Z[:k + 1], INTERRUPTED, run.since
            raise
        if run.watching and not run.auto:
            run.project(k)
        bar.update(run.t[k])
    return run.X, run.Z, None, run.since


def _branch_changes(model, projector: ManifoldProjector, bridge: _bridge, grid, X) -> tuple[list, float]:
    """The bridged intervals (each next to a singular configuration) that fail the branch
    test: the chord from the interval's start to its end leaves the tangent motions at either
    end by more than :data:`BRANCH_DEPARTURE` of its length
    (:meth:`~ncgen.assembly.manifold.ManifoldProjector.departure`).  Each is warned about
    (:class:`~ncgen.errors.BranchWarning`, naming its times) and returned as ``(t_a, t_b)``,
    with the largest departure of all bridged intervals (0 without any)."""
    changes, largest = [], 0.0
    for t_a, t_b in bridge.spans:
        a, b = np.searchsorted(grid, t_a), np.searchsorted(grid, t_b)
        if b >= len(X):
            continue
        e = projector.departure(float(grid[a]), X[a], float(grid[b]), X[b])
        largest = max(largest, e)
        if e > BRANCH_DEPARTURE:
            changes.append((float(t_a), float(t_b)))
            warnings.warn(f"simulation of {model.name!r}: between t = {t_a:.6g} s and {t_b:.6g} s the motion passed "
                          f"a singular configuration of the constraints (A lost rank) and left it on another "
                          f"branch of Phi = 0 than it came on (branch test: the chord between the two times "
                          f"leaves the tangent motions by {e:.2g} of its length, above {BRANCH_DEPARTURE:g}); "
                          f"check that this is the physical motion (a mechanism at rest at that configuration "
                          f"and pushed along the other branch), or use a smaller rtol", BranchWarning,
                          stacklevel=4)
    return changes, largest


def _retry_length(failure: ChunkFailure, t_k: float, h: float, n: int) -> int:
    """Output intervals of the next try of a watched chunk of ``n`` from ``t_k`` that failed:
    up to the second-last output before the time IDAS gave up (a flat position ahead: the
    try then reaches the near-singular limit and is cut there), half as many if IDAS named
    no time; at least 1, fewer than ``n``."""
    t_fail = shift_time(failure.message, t_k)[1]
    if t_fail is None or not math.isfinite(t_fail):
        return max(1, n // 2)
    return max(1, min(n - 1, int((t_fail - t_k) / h) - 1))


def _chunk_to_limit(room: float, slope: float, bend: float, full: int) -> int:
    """Output intervals of the next IDAS call while watching a ratio now ``room`` above its
    limit, changing by ``slope`` per interval and that change by ``bend`` per interval: up to
    the first output past the predicted crossing ``room + n slope + n (n+1)/2 bend = 0``
    (the call is then cut at the last output above the limit), at most ``full``; a far
    crossing is approached by a power of 2 below it (few lengths: one integrator each).
    IDAS loses accuracy at each restart (its first steps are of order 1), so the calls are
    as long as the prediction allows."""
    if room <= 0.0:
        return 1
    a, b = 0.5 * bend, slope + 0.5 * bend
    disc = b * b - 4.0 * a * room
    if abs(a) < 1e-300:
        n = -room / b if b < 0.0 else math.inf
    elif disc < 0.0 or (a > 0.0 and b >= 0.0):
        n = math.inf
    else:
        n = (-b - math.sqrt(disc)) / (2.0 * a)
    if n >= full:
        return full
    if n < CLOSE_CROSSING:
        return int(n) + 1
    return 2 ** int(math.log2(n))


def _failure_message(model, failure: ChunkFailure, t, k, x, lam, u, p, dae) -> str:
    nq = model.nq
    said, t_fail = shift_time(failure.message, float(t[k]))
    where = f" (IDAS gave up at t = {t_fail:.6g} s)" if t_fail is not None else ""
    cause = explain(model, failure.flag, float(t[k]), x[:nq], x[nq:], lam, u, p, dae)
    detail = f" IDAS said: {said}" if said else ""
    return (f"simulation of {model.name!r} failed between t = {t[k]:.6g} s and the next output time "
            f"{t[k + 1]:.6g} s{where}: {cause}.{detail} The trajectory up to t = {t[k]:.6g} s is "
            f"attached to this error as .trajectory.")
