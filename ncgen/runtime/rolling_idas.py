"""``nc.simulate(model, ..., method="idas")`` for a model with nonholonomic elements
(``model.rolling``): IDAS on the index-1 DAE of :func:`ncgen.assembly.rolling_dae.rolling_dae`
(the holonomic rows and the velocity rows ``B(q) v = c(q, t)`` at the acceleration level, each
with its own multipliers, Baumgarte-stabilised), its outputs projected onto both constraint
levels.

IDAS runs on in its own state from output to output (in :data:`CHUNKS` calls, each started
from the projected state and its KKT multipliers); its state drifts off the constraints by
about its local error (``rtol`` times the size of the rates: 3e-7 on the 10 s rolling disc of
``tests/test_rolling_idas.py`` at rtol 1e-8), which the Baumgarte terms keep from growing.
Every output is that state projected onto ``Φ̂(q) = 0`` and ``Â(q) v = ĉ(q, t)``
(:func:`ncgen.runtime.rolling_integrator.project`, least-norm corrections to 1e-14 of the
system's size), so the trajectory's constraint residuals are at round-off, and ``lam`` the
KKT multipliers there (:func:`ncgen.assembly.rolling_dae.rolling_kkt`).  ``info["stats"]``
holds IDAS's counters and ``"drift"``, the largest residual of IDAS's own states before
projection; ``info["energy"]`` the energy drift of a conservative run, or the energy balance
with the work of inputs, drives and moving planes integrated by IDAS as quadratures
(:func:`ncgen.assembly.nonholonomic.power_function`, on IDAS's own states).  Restarting IDAS
at every output from the projected state instead was measured worse (each restart begins at
order 1: the disc's energy error grew from 8.6e-7 to 6.6e-5 J over 2 s with 200 restarts),
so the projection is of the outputs only.

Taken: open-loop inputs (``hold``), parameter values in the forces, forces of time, planes
moving along themselves.  Not taken (refused by name): feedback and compiled controllers,
``joint_dynamics``, ``project=True``, ``backend="compiled"`` (the DAE runs on CasADi's virtual
machine, ``info["backend"] = "vm"``), other parameter values in the model's constraints.
"""
from __future__ import annotations

import math
import time

import numpy as np

from ncgen.assembly.nonholonomic import power_function, rolling_system
from ncgen.assembly.rolling_dae import rolling_dae, rolling_kkt
from ncgen.errors import NcgenError, SimulationError
from ncgen.runtime.energy_balance import idas_report
from ncgen.runtime.idas import ChunkedIDAS, ChunkFailure
from ncgen.runtime.integrator import Run
from ncgen.runtime.simulation_progress import Progress
from ncgen.runtime.rolling_integrator import conservative_run, project
from ncgen.runtime.trajectory import Trajectory

#: IDAS calls per run at most (each restarts IDAS at order 1; they give the progress bar its steps).
CHUNKS = 20


def check_rolling_idas(model, opts) -> None:
    """Refuse, by name, what the rolling IDAS path does not take (module docstring); ``opts``:
    IDAS's option group (:class:`~ncgen.runtime.idas_integrator.IdasOptions`)."""
    if opts.joint_dynamics:
        raise NcgenError(f"method='idas': model {model.name!r} has rolling elements: joint_dynamics=True is not "
                         "taken (the joints' damping, friction and limits are not in the rolling equations)")
    if opts.backend == "compiled":
        raise NcgenError(f"method='idas': model {model.name!r} has rolling elements: backend='compiled' is not "
                         "taken (the rolling DAE runs on CasADi's virtual machine); give backend='vm' or 'auto'")
    if opts.project is True:
        raise NcgenError(f"method='idas': model {model.name!r} has rolling elements: project=True is not taken "
                         "(its outputs are always projected onto both constraint levels); give project='auto'")


def _functions(system):
    """``(dae, kkt)`` of ``system``, made once (kept in ``system.compiled_steps`` beside its steps)."""
    if "idas" not in system.compiled_steps:
        system.compiled_steps["idas"] = rolling_dae(system), rolling_kkt(system)
    return system.compiled_steps["idas"]


def simulate_rolling_idas(model, run: Run, opts) -> Trajectory:
    """IDAS over ``run``'s grid for a model with rolling elements (module docstring); ``opts``:
    IDAS's option group (:class:`~ncgen.runtime.idas_integrator.IdasOptions`)."""
    if run.controller is not None or run.feedback is not None:
        raise NcgenError(f"method='idas': model {model.name!r} has rolling elements: feedback and controllers are "
                         "not taken (open-loop inputs are); give u as samples or a function of t")
    system = rolling_system(model)
    if system.parametric_constraints and not np.array_equal(run.p, model.p0):
        raise NcgenError(f"method='idas': model {model.name!r}: its constraints depend on the parameters, and the "
                         "rolling equations are built with model.p0; give p=None")
    dae, kkt = _functions(system)
    nq, p, t = model.nq, np.asarray(run.p, float), run.t
    rtol = 1e-8 if opts.rtol is None else opts.rtol
    atol = 1e-10 if opts.atol is None else opts.atol

    def multipliers(tk, x, u):
        a, lam = kkt(tk, x[:nq], x[nq:], u, p)
        return np.concatenate([np.asarray(a).ravel(), np.asarray(lam).ravel()])

    conservative = conservative_run(system, run.U)
    runner = ChunkedIDAS(dae, h=float(t[1] - t[0]), nu=model.nu, hold=opts.hold, rtol=rtol, atol=atol,
                         max_steps=opts.max_steps, linear_solver=opts.linear_solver, expand=True,
                         algebraic=multipliers, power=None if conservative else power_function(system))
    X0 = np.concatenate(project(system, run.q, run.v, t=float(t[0])))
    start = time.perf_counter()
    X, W, drift, failure = _march(model, system, runner, run, p, X0, conservative, opts.progress)
    k = len(X) - 1
    tk = t[:k + 1]
    U = run.U[:k + 1]
    lam = np.array([multipliers(ti, x, U[i])[nq:] for i, (ti, x) in enumerate(zip(tk, X))])
    stats = dict(runner.stats, drift=drift)
    info = {"method": "idas", "backend": "vm", "rtol": rtol, "atol": atol, "hold": opts.hold, "stats": stats,
            "rolling_names": [e.name for e in model.rolling], "auto": run.why_not,
            "wall_time": time.perf_counter() - start, "complete": failure is None}
    traj = Trajectory.from_states(model, tk, X[:, :nq], X[:, nq:], lam, U, p, info)
    traj.constraint_names = list(system.row_names)
    levels = np.array([system.residuals(x[:nq], x[nq:], ti) for ti, x in zip(tk, X)])
    traj.constraint_residual, traj.velocity_residual = levels[:, 0], levels[:, 1]
    work = None if conservative else np.cumsum(W, axis=0)
    traj.info["energy"] = idas_report(model, traj, conservative, work)
    if failure is not None:
        error, end = failure
        message = (f"simulation of {model.name!r} (rolling elements, IDAS) failed between t = {t[k]:.6g} s and "
                   f"t = {t[end]:.6g} s: IDAS said: {error.message or error.error}. The "
                   f"trajectory up to t = {t[k]:.6g} s is attached to this error as .trajectory.")
        traj.info["message"] = message
        raise SimulationError(message, time=float(t[k]), trajectory=traj)
    return traj


def _march(model, system, runner, run: Run, p: np.ndarray, X0: np.ndarray, conservative: bool, progress):
    """IDAS from output to output in at most :data:`CHUNKS` calls, each started from the last
    projected output: ``(X, W, drift, failure)``, the projected outputs reached, the work of
    each power over each output interval (row: its end; zero on a conservative run), the
    largest residual of IDAS's own states, and ``(error, end)`` of a failed call (None: none
    failed; ``end``: the output index the failed call was to reach)."""
    t, columns, nq = run.t, run.columns, model.nq
    W = np.zeros((len(t), 5))
    X = np.empty((len(t), 2 * nq))
    X[0] = X0
    n_int, full = len(t) - 1, max(1, math.ceil((len(t) - 1) / CHUNKS))
    drift, failure, k = 0.0, None, 0
    bar = Progress(t[0], t[-1], progress, label=f"simulating {model.name}: ")
    try:
        while k < n_int:
            n = min(full, n_int - k)
            try:
                states, _ = runner.advance(float(t[k]), X[k], None, columns[:, k:k + n], p)
            except ChunkFailure as e:
                failure = e, k + n
                break
            if not conservative:
                W[k + 1:k + 1 + n] = runner.last_work
            for i, x in enumerate(states, start=k + 1):
                drift = max(drift, *system.residuals(x[:nq], x[nq:], float(t[i])))
                X[i] = np.concatenate(project(system, x[:nq], x[nq:], t=float(t[i])))
            k += n
            bar.update(t[k])
    finally:
        bar.close()
    return X[:k + 1], W[:k + 1], drift, failure
