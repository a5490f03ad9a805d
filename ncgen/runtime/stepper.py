"""Simulation with the compiled stepper (``nc.simulate(..., method="stepper")``).

The scheme (RATTLE for constant mass matrices, see :mod:`ncgen.assembly.stepper_equations`)
runs entirely in generated C (:mod:`ncgen.codegen.stepper_package`, loaded by
:mod:`ncgen.runtime.stepper_library`): the step loop, its error
estimates and the derived quantities of the trajectory (energies, constraint residuals,
markers: one compiled call over all samples).  Python prepares the inputs, checks the run
(:mod:`ncgen.runtime.stepper_checks`) and wraps the result in a
:class:`~ncgen.runtime.trajectory.Trajectory`.

Two modes:

* **Fixed steps** (``rtol=None``): ``substeps`` steps of ``h = dt / substeps`` per output
  interval; a step whose Newton iteration fails is split into halves (at most
  ``max_halvings`` times, recursively), so the output grid stays fixed.  The step is, by
  default (``scheme="auto"``) and with ``scheme="rattle4"``, Suzuki's symmetric five-stage
  composition of RATTLE steps ``g h, g h, (1 − 4g) h, g h, g h`` with
  ``g = 1 / (4 − 4^(1/3))`` (order 4, symplectic, on both constraint levels; five RATTLE
  steps each), or with ``scheme="rattle"`` (and for models with contacts, which keep their
  own scheme) RATTLE's (order 2).  The error estimate (``info["error_estimate"]``, see
  :mod:`ncgen.runtime.stepper_checks`): by default (``estimate=True`` or ``"shadow"``) a
  shadow run with steps of ``2h`` from the same start, ``|y_h − y_2h| / (2^p − 1)``, ``p``
  the order (Richardson; global: it follows the growth of errors along the motion; half the
  work again); ``estimate="local"``: the local errors of one pair of steps in six, from a
  step of 2h over the pair, summed along the run and grown as a RATTLE shadow run's errors
  grow (a fifth more work; far too low where errors grow fast and RATTLE at 2h cannot follow
  the motion);
  ``estimate=False`` skips it.  The run is checked (see :mod:`ncgen.runtime.stepper_checks`) and an
  untrustworthy one raises :class:`~ncgen.errors.SimulationError`.
* **Error control** (``rtol`` given): each step is taken whole and as two halves, the
  difference estimates the local error (Richardson; where the whole difference fails the
  test, its part tangent to the constraints: the normal part is a constraint residual that,
  next to a singular configuration, carries the round-off of the ill-conditioned KKT
  solves), the step is accepted when every
  component of q and v is within ``atol + rtol |y|`` and continues from the Richardson
  extrapolation (order 4, RATTLE being symmetric) projected onto both constraint levels
  (``order=2``: from the two halves, keeping RATTLE's symplecticity).  With
  ``scheme="rattle4"`` the steps are the fourth-order composition's (three composed steps
  per step tried), the local error ``|halves − whole| / 15`` and the extrapolation
  ``halves + (halves − whole) / 15`` (``order=2``: from the halves); at tight tolerances
  this takes several times fewer RATTLE steps than RATTLE's error control for the same
  error (double pendulum, 1e-9: 2300 against 10400).  ``scheme="auto"`` keeps RATTLE's.  Steps
  end on every output time.  ``rtol`` bounds this local error; a shadow run at 10× looser tolerances
  estimates the global error (:mod:`ncgen.runtime.stepper_checks`), and the run warns or
  raises where that estimate says the tolerance was not met.

Inputs: with ``hold="zoh"`` the sample of the output interval, with ``hold="linear"`` the
interpolated input at the step's midpoint (second order for smooth inputs).  Multipliers in
the trajectory are those of the last half-step (first-order accurate in h); at ``t0`` they
solve the KKT system.
"""
from __future__ import annotations

import os
import time
from typing import NamedTuple

import numpy as np

from ncgen.codegen.stepper_abi import RunOptions
from ncgen.codegen.stepper_package import STATS, STATUS, STEP_INTERRUPTED, TOL
from ncgen.errors import NcgenError, SimulationError, SimulationInterrupted, option
from ncgen.progress import Ticker
from ncgen.runtime.energy_balance import balance_report, nonsmooth_contacts, stepper_works
from ncgen.runtime.dynamics_at_state import multipliers_at_samples
from ncgen.runtime.options import SimulationOptions
from ncgen.runtime.stepper_checks import (NO_ESTIMATE, SHADOW_FACTOR, check_fixed, check_global, contact_report,
                                          energy_report, error_estimate, is_conservative, shadow_estimates,
                                          shadow_report, trusted_before_failure, warn_unconverged)
from ncgen.runtime.stepper_library import step_options
from ncgen.runtime.stepper_options import StepperOptions
from ncgen.runtime.table_stepper import load_any_stepper
from ncgen.runtime.trajectory import NAME_KEYS, Trajectory, derived_outputs

#: With error control, the Newton tolerance is at most this fraction of min(rtol, atol)
#: (floored at 1e-14), so that Newton's residual stays below the error estimates.
NEWTON_FRACTION = 1e-3
#: Step attempts allowed per output interval of the RATTLE bridge
#: (:func:`ncgen.runtime.rattle_bridge.compiled_interval`).
MAX_STEPS = 100_000
def simulate_stepper(model, t: np.ndarray, U: np.ndarray, p: np.ndarray, q0: np.ndarray, v0: np.ndarray,
                     lam0: np.ndarray, options: StepperOptions | SimulationOptions | None = None, *, cflags=None,
                     **shortcuts) -> Trajectory:
    """Integrate ``model`` over the uniform grid ``t`` (s) from the consistent state
    ``(q0, v0)`` with multipliers ``lam0`` at ``t[0]``; ``U`` holds the input samples on the
    grid, shape ``(len(t), nu)``, ``p`` the parameter values.  ``options``: the stepper's group
    (:class:`StepperOptions`) or a :class:`~ncgen.runtime.options.SimulationOptions` (keyword
    arguments are shortcuts for its fields): ``rtol`` (and ``atol``, default ``rtol``, units of
    q and v) switch to error control (module docstring); ``check=False`` turns off the checks of
    a fixed-step run, ``estimate=False`` its error estimate (and so the error check).  Raises
    :class:`~ncgen.errors.SimulationError` naming the time and the cause, with the
    trajectory up to the last output time before it."""
    opts = options if isinstance(options, StepperOptions) and not shortcuts else \
        StepperOptions.of(SimulationOptions.resolve(options, **shortcuts))
    opts.check_together()
    stepper = load_any_stepper(model, cflags, opts.kernels)
    conservative = is_conservative(model, inputs=bool(np.any(np.asarray(U) != 0)))
    if opts.rtol is not None and stepper.nd:
        raise NcgenError(f"rtol: model {model.name!r} has nonsmooth contacts, whose impacts the error control "
                         f"cannot follow; use fixed steps ({option('substeps=N', '--substeps N')}) or "
                         + option("build it with contacts='smooth'", "--contacts smooth"))
    if opts.scheme == "rattle4" and stepper.nd:
        raise NcgenError(f"scheme: 'rattle4' needs a smooth model; {model.name!r} has nonsmooth contacts, which "
                         f"keep their own scheme (first order at impacts): use scheme='rattle' or build it with "
                         f"contacts='smooth'")
    check_contact_workspace(model, stepper.nd)
    run = _fixed if opts.rtol is None else _adaptive
    return run(model, stepper, StepperStart(t, U, p, q0, v0, lam0), opts, conservative)


def physical_memory() -> int:
    """This machine's physical memory, bytes."""
    return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")


#: Bytes per impulse component of the contact stepper's workspace before a run (its per-row
#: arrays, ncgen_rattle.h's layout(): about 32 doubles or indices each; the Delassus blocks are
#: allocated during the run, by the active rows: contact_reserve()).
CONTACT_BYTES_PER_ROW = 32 * 8


def check_contact_workspace(model, nd: int) -> None:
    """Refuse, naming the model and the sizes, a nonsmooth contact stepper whose per-row arrays
    (``nd`` impulse components) need more bytes than this machine's physical memory: the C
    would fail to allocate them.  The dense blocks of a contact solve (3 n² doubles for n
    active rows) are allocated as the run needs them; if that fails the run stops with status
    5 ("bad input or out of memory")."""
    need, have = CONTACT_BYTES_PER_ROW * nd, physical_memory()
    if need > have:
        raise NcgenError(f"model {model.name!r}: its nonsmooth contact stepper needs {need / 2**30:.1f} GiB for its "
                         f"per-row arrays ({CONTACT_BYTES_PER_ROW} bytes for each of nd = {nd:,} impulse components), "
                         f"more than this machine's {have / 2**30:.1f} GiB of memory; use fewer contact elements "
                         f"(pairs that can meet), or contacts='smooth' with method='idas'")


class StepperStart(NamedTuple):
    """A stepper run's data: the output grid ``t`` (s), the input samples ``U`` on it, the
    parameter values ``p``, the consistent state ``(q0, v0)`` and multipliers ``lam0`` at ``t[0]``."""

    t: np.ndarray
    U: np.ndarray
    p: np.ndarray
    q0: np.ndarray
    v0: np.ndarray
    lam0: np.ndarray


class StepperRows(NamedTuple):
    """What a run of the C loops returns per output row after the start: the states ``Q``,
    ``V``, the multipliers ``LAM``, the statistics ``S`` (``STATS``), and the rows done."""

    Q: np.ndarray
    V: np.ndarray
    LAM: np.ndarray
    S: np.ndarray
    rows: int


def _fixed(model, stepper, data: StepperStart, opts: StepperOptions, conservative: bool) -> Trajectory:
    """Fixed steps (module docstring)."""
    t, U, p, q0, v0, lam0 = data
    hold, substeps, tol, max_iter, max_halvings = opts.hold, opts.substeps, opts.newton_tol, opts.max_newton, \
        opts.max_halvings
    n_out = len(t) - 1
    h = float(t[1] - t[0]) / substeps
    contacts = stepper.nd > 0          # nonsmooth contacts: no shadow run, one-sided energy check
    IMP = np.zeros((n_out, stepper.nd)) if contacts else None      # contact impulses per output interval
    start, cpu_start = time.perf_counter(), time.process_time()
    rattle4 = fixed_scheme(model, opts.scheme) == "rattle4"
    mode = ESTIMATE_MODES[opts.estimate] if opts.estimate and not contacts else 0
    with Ticker(f"stepper: {model.name}, {n_out * substeps:,} steps"):
        Q, V, LAM, S, status, done, splits = stepper.simulate_stats(
            q0, v0, lam0, float(t[0]), h, n_out * substeps, substeps, step_inputs(U, t, hold, substeps), p,
            step_options(tol, max_iter, max_halvings, int(rattle4)),
            RunOptions(estimate=mode, track_work=int(not conservative)), impulse_out=IMP)
    rows = done // substeps
    shadow_failed = mode == ESTIMATE_MODES["shadow"] and np.any(S[:rows, STATS.index("error_q")] == -2)
    if shadow_failed and status != STEP_INTERRUPTED:
        status = _estimate_at_half_step(model, stepper, data, StepperRows(Q, V, LAM, S, rows), opts, rattle4, status)
    stepping, stepping_cpu = time.perf_counter() - start, time.process_time() - cpu_start
    info = {"method": "stepper", "backend": "compiled", "kernels": stepper.kernels,
            **_fixed_scheme_info(contacts, rattle4), "h": h,
            "substeps": substeps, "hold": hold, "tol": tol, "max_iter": max_iter,
            "max_halvings": max_halvings, "estimate": ESTIMATE_NAMES[mode], "stepping_time": stepping,
            "stepping_cpu_time": stepping_cpu, "complete": status == 0,
            "stats": _stats(S[:rows], splits)}
    traj = _trajectory(model, stepper, data, StepperRows(Q, V, LAM, S, rows), info, conservative, start,
                       None if IMP is None else IMP[:rows])
    if shadow_failed:
        _say_half_step(traj)
    if contacts:
        traj.info["contacts"] = contact_report(S[:rows])
        warn_unconverged(model, traj.info["contacts"])
    if status == STEP_INTERRUPTED:
        _interrupted(model, traj, float(t[rows]))
    if status != 0:
        t_fail = float(t[0]) + done * h
        message = (f"simulation of {model.name!r} with the stepper failed in the step from "
                   f"t = {t_fail:.6g} s to {t_fail + h:.6g} s (h = {h:.3g} s, halved up to "
                   f"{max_halvings} times): {STATUS.get(status, f'status {status}')}. The trajectory up to "
                   f"t = {t[rows]:.6g} s is attached to this error as .trajectory.")
        if opts.check:                 # rows before the failure kept only as far as they are trusted
            failed = STATUS.get(status, f"status {status}")
            check_fixed(model, traj, S[:rows], h, substeps, contacts, conservative,
                        after=f" The stepper then failed at t = {t_fail:.6g} s: {failed}.")
        traj.info["message"] = message
        raise SimulationError(message, time=float(t[rows]), trajectory=traj)
    if opts.check:
        check_fixed(model, traj, S[:rows], h, substeps, contacts, conservative)
    return traj


def _fixed_scheme_info(contacts: bool, rattle4: bool) -> dict:
    """The ``scheme``, ``order`` and ``stages`` entries of a fixed-step run's ``info``."""
    return {"scheme": "RATTLE, nonsmooth contacts" if contacts else
            "RATTLE, Suzuki's fourth-order composition" if rattle4 else "RATTLE", "order": 4 if rattle4 else 2,
            "stages": COMPOSITION_STAGES if rattle4 else 1}


def _estimate_at_half_step(model, stepper, data: StepperStart, run: StepperRows, opts: StepperOptions,
                           rattle4: bool, status: int) -> int:
    """Where the shadow run (steps of 2h) failed Newton, the error estimate of ``run``'s rows from
    a run with steps of h/2 (:func:`fine_estimates`, written into ``run.S``); the run's status,
    interrupted if that run was."""
    with Ticker(f"stepper: {model.name}, its shadow run failed: a run with steps of h/2 for the estimate"):
        fine = fine_estimates(stepper, data, run, opts.hold, opts.substeps,
                              step_options(opts.newton_tol, opts.max_newton, opts.max_halvings, int(rattle4)),
                              4 if rattle4 else 2)
    return STEP_INTERRUPTED if fine == STEP_INTERRUPTED else status


def _say_half_step(traj: Trajectory) -> None:
    """The error report of a run whose shadow failed names the estimate of :func:`_estimate_at_half_step`."""
    if traj.info["error_estimate"].get("how", "").startswith("Richardson"):
        traj.info["error_estimate"]["how"] += (", from where Newton failed at 2h |y_h - y_h/2| 2^p / (2^p - 1) "
                                               "against a run with steps of h/2")


def _adaptive(model, stepper, data: StepperStart, opts: StepperOptions, conservative: bool) -> Trajectory:
    """Error control (module docstring)."""
    t, U, p, q0, v0, lam0 = data
    hold, tol, max_iter, order, max_steps = opts.hold, opts.newton_tol, opts.max_newton, opts.order, opts.max_steps
    check, estimate = opts.check, opts.estimate
    rattle4 = opts.scheme == "rattle4"            # "auto" keeps RATTLE's error control
    rtol = opts.rtol
    atol = rtol if opts.atol is None else opts.atol
    n_out = len(t) - 1
    dt = float(t[1] - t[0])
    start = time.perf_counter()

    def run(rtol, atol):
        options = RunOptions(rtol=rtol, atol=atol, h0=0.0, extrapolate=int(order == 4), max_steps=max_steps,
                             hold_linear=int(hold == "linear"), track_work=int(not conservative))
        return stepper.simulate_adaptive(q0, v0, lam0, float(t[0]), dt, n_out, U if model.nu else None, p, options,
                                         step_options(newton_tolerance(rtol, atol, tol), max_iter, 0, int(rattle4)))

    with Ticker(f"stepper: {model.name}, rtol {rtol:g}"):
        Q, V, LAM, S, status, rows, h_next = run(rtol, atol)
        shadow = run(SHADOW_FACTOR * rtol, SHADOW_FACTOR * atol) if estimate and status == 0 else None
    if shadow is not None and shadow[4] == STEP_INTERRUPTED:   # stopped in the shadow run: no estimate
        status, shadow = STEP_INTERRUPTED, None
    info = _adaptive_info(stepper, opts, atol, time.perf_counter() - start, status == 0, S[:rows])
    traj = _trajectory(model, stepper, data, StepperRows(Q, V, LAM, S, rows), info, conservative, start)
    if status == STEP_INTERRUPTED:
        _interrupted(model, traj, float(t[rows]))
    if status != 0:
        message = (f"simulation of {model.name!r} with the error-controlled stepper (rtol {rtol:g}, atol "
                   f"{atol:g}) failed between t = {t[rows]:.6g} s and {t[rows + 1]:.6g} s (last step tried "
                   f"{h_next:.3g} s): {STATUS.get(status, f'status {status}')}.")
        kept, why = traj, ""
        if check:
            with Ticker(f"stepper: {model.name}, shadow run at rtol {SHADOW_FACTOR * rtol:g}"):
                eq = shadow_estimates(Q, V, run(SHADOW_FACTOR * rtol, SHADOW_FACTOR * atol), rows)[0] \
                    if estimate and rows else None
            kept, why = trusted_before_failure(model, traj, S[:rows], eq)
        message += f"{why} The trajectory up to t = {kept.t[-1]:.6g} s is attached to this error as .trajectory."
        kept.info.update(complete=False, message=message)
        raise SimulationError(message, time=float(kept.t[-1]), trajectory=kept)
    if shadow is not None:
        eq, ev = shadow_estimates(Q, V, shadow, rows)
        same_steps = np.array_equal(S[:rows, 0], shadow[3][:rows, 0])
        traj.info["error_estimate"] = shadow_report(traj, eq, ev, rtol, atol, S[:rows], same_steps)
        if check:
            check_global(model, traj, eq, rtol, atol)
    return traj


def _adaptive_info(stepper, opts: StepperOptions, atol: float, stepping: float, complete: bool, S) -> dict:
    """The trajectory's ``info`` of an error-controlled run: its scheme, tolerances and options,
    the time stepping took (s), whether it is complete, and the counts of the statistics ``S``."""
    rattle4, order, rtol = opts.scheme == "rattle4", opts.order, opts.rtol
    info = {"method": "stepper", "backend": "compiled", "kernels": stepper.kernels,
            "scheme": "RATTLE, Suzuki's fourth-order composition" if rattle4 else "RATTLE" if order == 2 else "RATTLE, Richardson-extrapolated and projected",
            "order": 4 if rattle4 else order, "rtol": rtol, "atol": atol, "hold": opts.hold,
            "tol": newton_tolerance(rtol, atol, opts.newton_tol), "max_iter": opts.max_newton,
            "max_steps": opts.max_steps, "estimate": bool(opts.estimate), "stepping_time": stepping,
            "complete": complete, "stats": _stats(S, int(S[:, 2].sum()))}
    info["stats"]["rejected_steps"] = info["stats"].pop("step_splits")
    return info


#: ``estimate`` of a fixed-step run → the C loop's mode (``ESTIMATE_*`` of ncgen_fixed.h).
ESTIMATE_MODES = {True: 2, "shadow": 2, "local": 1}
ESTIMATE_NAMES = {0: False, 1: "local", 2: "shadow"}
#: RATTLE steps per step of ``scheme="rattle4"`` (COMPOSITION_STAGES of ncgen_fixed.h).
COMPOSITION_STAGES = 5


def fixed_scheme(model, scheme: str) -> str:
    """The fixed-step scheme a run uses: ``scheme``, with ``"auto"`` read as ``"rattle4"``
    for models without contacts and ``"rattle"`` for those with contacts (smooth or not:
    stiff contact forces and impacts keep RATTLE)."""
    if scheme != "auto":
        return scheme
    return "rattle" if getattr(model, "contacts", None) else "rattle4"


def fine_estimates(stepper, data: StepperStart, rows: StepperRows, hold: str, substeps: int, step, order: int) -> int:
    """Where the shadow run of a fixed-step run (steps of 2h) failed — the error columns of
    ``rows.S`` at −2 from some output row on — the global estimate from a run with steps of
    h/2 from the same start instead, written into those rows of ``rows.S`` in place:
    ``|y_h − y_h/2| 2^p / (2^p − 1)`` (Richardson from the finer side, ``p`` the scheme's
    ``order``).  Newton failing at 2h only says the step
    is within a factor 2 of its limit: a run verified against a closed form can be there (a stiff
    winch), and so can one far off (the 5-bar chain at 15 rad/s, h = 2 ms: 0.74 m off IDAS,
    benchmarks/batch_estimates.py); the run at h/2 tells them apart, at twice the run's work,
    only where the shadow failed.  ``step``: the run's step options.  Rows where that run failed
    too get :data:`~ncgen.runtime.stepper_checks.NO_ESTIMATE` (the checks flag them).  Returns
    that run's status (0 when none was needed)."""
    S, n = rows.S, rows.rows
    col_q, col_v = STATS.index("error_q"), STATS.index("error_v")
    failed = S[:n, col_q] == -2
    if not failed.any():
        return 0
    t, U, p, q0, v0, lam0 = data
    fine = 2 * substeps
    h = float(t[1] - t[0]) / fine
    Qf, Vf, _, _, status, done, _ = stepper.simulate_stats(q0, v0, lam0, float(t[0]), h, n * fine, fine,
                                                           step_inputs(U[:n + 1], t[:n + 1], hold, fine), p, step,
                                                           RunOptions(estimate=0, track_work=0))
    k = done // fine
    factor = 2.0 ** order / (2.0 ** order - 1.0)
    use = np.flatnonzero(failed[:k])
    S[use, col_q] = factor * np.max(np.abs(rows.Q[use] - Qf[use]), axis=1)
    S[use, col_v] = factor * np.max(np.abs(rows.V[use] - Vf[use]), axis=1)
    none = k + np.flatnonzero(failed[k:])
    S[none, col_q] = S[none, col_v] = NO_ESTIMATE
    return status


def _interrupted(model, traj: Trajectory, t_stop: float):
    """Raises :class:`~ncgen.errors.SimulationInterrupted` with ``traj``, the run up to
    ``t_stop`` (s) when Ctrl-C stopped it, marked incomplete."""
    message = f"simulation of {model.name!r} with the stepper interrupted (Ctrl-C) at t = {t_stop:.6g} s"
    traj.info.update(complete=False, message=message)
    raise SimulationInterrupted(message, time=t_stop, trajectory=traj)


def newton_tolerance(rtol: float, atol: float, tol: float = TOL) -> float:
    """The Newton tolerance of an error-controlled run: ``tol``, at most
    :data:`NEWTON_FRACTION` × ``min(rtol, atol)`` (floored at 1e-14)."""
    return min(tol, max(NEWTON_FRACTION * min(rtol, atol), 1e-14))


def _stats(S: np.ndarray, splits: int) -> dict:
    return {"nsteps": int(S[:, 0].sum()), "newton_iterations": int(S[:, 1].sum()), "step_splits": int(splits)}


def _trajectory(model, stepper, data: StepperStart, out: StepperRows, info: dict, conservative: bool, start: float,
                impulses=None, accel=None):
    """The trajectory of the run ``data`` up to the first ``out.rows`` output rows, derived quantities from the
    compiled ``<model>_outputs`` (joint states and contact outputs from
    :func:`~ncgen.runtime.trajectory.derived_outputs`; ``impulses``: the nonsmooth contact
    impulses per output interval); the multipliers of the output states
    (:func:`~ncgen.runtime.dynamics_at_state.multipliers_at_samples` with ``accel``), or with
    nonsmooth contacts the stepper's ``LAM``; sets the error estimate, the energy report and
    the wall time (from ``start``) in ``info``."""
    (t, U, p, q0, v0, lam0), (Q, V, LAM, S, rows) = data, out
    q = np.vstack([q0, Q[:rows]])
    v = np.vstack([v0, V[:rows]])
    tt, u = t[:rows + 1], U[:rows + 1]
    tables = getattr(stepper, "kernels", "flat") == "tables"      # no flat function on the tables' path
    if nonsmooth_contacts(model):  # nonsmooth contacts: the step's own multipliers (μ)
        lam = np.vstack([lam0, LAM[:rows]])
    elif tables:
        lam = stepper.multipliers(q, v, u)
    else:                         # the states' own multipliers: second order, as the states
        lam = multipliers_at_samples(model, tt, q, v, u, p, accel)
    Y = stepper.outputs(tt, q, v, lam, u, p)
    dim, n_markers = model.dim, len(model.marker_names)
    markers = Y[:, 5:].reshape(len(tt), n_markers, dim)
    work = np.concatenate([[0.0], S[:rows, STATS.index("work")]])
    names = {key: getattr(model, key) for key in NAME_KEYS}
    extra_names, extra = derived_outputs(model, tt, q, v, p, impulses)
    traj = Trajectory(model_name=model.name, names={**names, **extra_names}, info=info, model=model, t=tt, q=q,
                      v=v, lam=lam, u=u, p=p, kinetic=Y[:, 0], potential=Y[:, 1], constraint_residual=Y[:, 2],
                      velocity_residual=Y[:, 3], markers=markers, **extra)
    traj.info["error_estimate"] = error_estimate(S[:rows], info.get("substeps"), info.get("estimate"), q, v,
                                                 info.get("order") == 4)
    traj.info["energy"] = energy_report(traj, work, conservative, S[:rows])
    if not conservative and len(traj):
        balance_report(model, traj.info["energy"], stepper_works(S[:rows]))
    traj.info["wall_time"] = time.perf_counter() - start
    return traj


def step_inputs(U: np.ndarray, t: np.ndarray, hold: str, substeps: int) -> np.ndarray | None:
    """Inputs of every step, shape ``(n_steps, nu)`` (see the module docstring), or None
    without inputs."""
    if U.shape[1] == 0:
        return None
    if hold == "zoh":
        return np.repeat(U[:-1], substeps, axis=0)
    frac = (np.arange(substeps) + 0.5) / substeps
    return (U[:-1, None, :] + frac[None, :, None] * (U[1:] - U[:-1])[:, None, :]).reshape(-1, U.shape[1])
