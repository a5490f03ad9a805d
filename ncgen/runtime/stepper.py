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
  ``max_halvings`` times, recursively), so the output grid stays fixed.  A shadow run with
  steps of ``2h`` from the same start gives the global error estimate ``|y_h − y_2h| / 3``
  (Richardson; ``info["error_estimate"]``, about half the work again; ``estimate=False``
  skips it).  The run is checked (see :mod:`ncgen.runtime.stepper_checks`) and an
  untrustworthy one raises :class:`~ncgen.errors.SimulationError`.
* **Error control** (``rtol`` given): each step is taken whole and as two halves, the
  difference estimates the local error (Richardson; where the whole difference fails the
  test, its part tangent to the constraints: the normal part is a constraint residual that,
  next to a singular configuration, carries the round-off of the ill-conditioned KKT
  solves), the step is accepted when every
  component of q and v is within ``atol + rtol |y|`` and continues from the Richardson
  extrapolation (order 4, RATTLE being symmetric) projected onto both constraint levels
  (``order=2``: from the two halves, keeping RATTLE's symplecticity).  Steps end on every
  output time.  ``rtol`` bounds this local error; a shadow run at 10× looser tolerances
  estimates the global error (:mod:`ncgen.runtime.stepper_checks`), and the run warns or
  raises where that estimate says the tolerance was not met.

Inputs: with ``hold="zoh"`` the sample of the output interval, with ``hold="linear"`` the
interpolated input at the step's midpoint (second order for smooth inputs).  Multipliers in
the trajectory are those of the last half-step (first-order accurate in h); at ``t0`` they
solve the KKT system.
"""
from __future__ import annotations

import math
import time
import warnings

import numpy as np

from ncgen.codegen.stepper_package import HALVINGS_LIMIT, MAX_HALVINGS, MAX_ITER, STATS, STATUS, TOL
from ncgen.progress import Ticker
from ncgen.runtime.energy_balance import balance_parts
from ncgen.errors import AccuracyWarning, NcgenError, SimulationError, option
from ncgen.runtime.inputs import HOLDS
from ncgen.runtime.stepper_checks import (ERROR_FRACTION, GLOBAL_FACTOR, SHADOW_FACTOR, contact_report,
                                          energy_report, error_estimate, is_conservative, shadow_estimates,
                                          shadow_report, untrusted_global_row,
                                          untrusted_row)
from ncgen.runtime.stepper_library import load_stepper
from ncgen.runtime.trajectory import NAME_KEYS, Trajectory, derived_outputs

#: With error control, the Newton tolerance is at most this fraction of min(rtol, atol)
#: (floored at 1e-14), so that Newton's residual stays below the error estimates.
NEWTON_FRACTION = 1e-3
#: Default step attempts allowed per output interval with error control.
MAX_STEPS = 100_000


def simulate_stepper(model, t: np.ndarray, U: np.ndarray, p: np.ndarray, q0: np.ndarray, v0: np.ndarray,
                     lam0: np.ndarray, *, hold: str = "zoh", substeps: int = 1, tol: float = TOL,
                     max_iter: int = MAX_ITER, max_halvings: int = MAX_HALVINGS, rtol: float | None = None,
                     atol: float | None = None, order: int = 4, max_steps: int = MAX_STEPS,
                     check: bool = True, estimate: bool = True, cflags=None) -> Trajectory:
    """Integrate ``model`` over the uniform grid ``t`` (s) from the consistent state
    ``(q0, v0)`` with multipliers ``lam0`` at ``t[0]``; ``U`` holds the input samples on the
    grid, shape ``(len(t), nu)``, ``p`` the parameter values.  ``rtol`` (and ``atol``, default
    ``rtol``, units of q and v) switch to error control (module docstring); ``check=False``
    turns off the checks of a fixed-step run, ``estimate=False`` its error estimate (and so
    the error check).  Raises :class:`~ncgen.errors.SimulationError` naming the time and the
    cause, with the trajectory up to the last output time before it."""
    substeps, max_iter, max_halvings = int(substeps), int(max_iter), int(max_halvings)
    _check_options(substeps, tol, max_iter, max_halvings, hold, rtol, atol, order, max_steps)
    stepper = load_stepper(model, cflags)
    conservative = is_conservative(model, inputs=bool(np.any(np.asarray(U) != 0)))
    if rtol is not None and stepper.nd:
        raise NcgenError(f"rtol: model {model.name!r} has nonsmooth contacts, whose impacts the error control "
                         f"cannot follow; use fixed steps ({option('substeps=N', '--substeps N')}) or "
                         + option("build it with contacts='smooth'", "--contacts smooth"))
    if rtol is None:
        return _fixed(model, stepper, t, U, p, q0, v0, lam0, hold, substeps, tol, max_iter, max_halvings,
                      check, bool(estimate), conservative)
    return _adaptive(model, stepper, t, U, p, q0, v0, lam0, hold, tol, max_iter, float(rtol),
                     float(rtol if atol is None else atol), order, int(max_steps), conservative, check,
                     bool(estimate))


def _check_options(substeps, tol, max_iter, max_halvings, hold, rtol, atol, order, max_steps):
    if substeps < 1:
        raise NcgenError(f"substeps: expected a positive number of steps per output interval, got {substeps}")
    if not (math.isfinite(tol) and tol > 0):
        raise NcgenError(f"tol: expected a positive Newton tolerance, got {tol!r}")
    if max_iter < 1:
        raise NcgenError(f"max_iter: expected at least one Newton iteration, got {max_iter}")
    if not 0 <= max_halvings <= HALVINGS_LIMIT:
        raise NcgenError(f"max_halvings: expected 0 to {HALVINGS_LIMIT} step halvings, got {max_halvings}")
    if hold not in HOLDS:
        raise NcgenError(f"hold: expected one of {', '.join(HOLDS)}, got {hold!r}")
    for name, value in (("rtol", rtol), ("atol", atol)):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise NcgenError(f"{name}: expected a positive tolerance, got {value!r}")
    if order not in (2, 4):
        raise NcgenError(f"order: expected 2 (RATTLE) or 4 (Richardson-extrapolated RATTLE), got {order!r}")
    if int(max_steps) < 1:
        raise NcgenError(f"max_steps: expected a positive number of steps, got {max_steps!r}")


def _fixed(model, stepper, t, U, p, q0, v0, lam0, hold, substeps, tol, max_iter, max_halvings, check,
           estimate, conservative) -> Trajectory:
    n_out = len(t) - 1
    h = float(t[1] - t[0]) / substeps
    contacts = stepper.nd > 0          # nonsmooth contacts: no shadow run, one-sided energy check
    IMP = np.zeros((n_out, stepper.nd)) if contacts else None      # contact impulses per output interval
    start = time.perf_counter()
    with Ticker(f"stepper: {model.name}, {n_out * substeps:,} steps"):
        Q, V, LAM, S, status, done, splits = stepper.simulate_stats(
            q0, v0, lam0, float(t[0]), h, n_out * substeps, substeps, step_inputs(U, t, hold, substeps), p, tol,
            max_iter, max_halvings, estimate and not contacts, not conservative, impulse_out=IMP)
    stepping = time.perf_counter() - start
    rows = done // substeps
    info = {"method": "stepper", "backend": "compiled", "scheme": "RATTLE, nonsmooth contacts" if contacts else
            "RATTLE", "h": h, "substeps": substeps, "hold": hold, "tol": tol, "max_iter": max_iter,
            "max_halvings": max_halvings, "estimate": estimate and not contacts, "stepping_time": stepping, "complete": status == 0,
            "stats": _stats(S[:rows], splits)}
    traj = _trajectory(model, stepper, t, q0, v0, lam0, Q, V, LAM, S, rows, U, p, info, conservative, start,
                       None if IMP is None else IMP[:rows])
    if contacts:
        traj.info["contacts"] = contact_report(S[:rows])
        _warn_unconverged(model, traj.info["contacts"])
    if status != 0:
        t_fail = float(t[0]) + done * h
        message = (f"simulation of {model.name!r} with the stepper failed in the step from "
                   f"t = {t_fail:.6g} s to {t_fail + h:.6g} s (h = {h:.3g} s, halved up to "
                   f"{max_halvings} times): {STATUS.get(status, f'status {status}')}. The trajectory up to "
                   f"t = {t[rows]:.6g} s is attached to this error as .trajectory.")
        traj.info["message"] = message
        raise SimulationError(message, time=float(t[rows]), trajectory=traj)
    if check:
        bad = untrusted_row(model, traj, S[:rows], h, contacts=contacts)
        if bad is not None:
            row, reason = bad
            kept = traj.head(row + 1)          # the states before C row `row`
            message = (f"simulation of {model.name!r} with the stepper (fixed step h = {h:.3g} s) is not "
                       f"trustworthy: {reason}. The trajectory up to t = {kept.t[-1]:.6g} s, before the "
                       f"problem showed, is attached to this error as .trajectory "
                       f"(check=False returns the whole run unchecked).")
            work = np.concatenate([[0.0], S[:row, STATS.index("work")]])
            kept.info.update(complete=False, message=message, error_estimate=error_estimate(S[:row], substeps),
                             energy=energy_report(kept, work, conservative))
            raise SimulationError(message, time=float(kept.t[-1]), trajectory=kept)
    return traj


def _warn_unconverged(model, report: dict) -> None:
    """Warnings when some contact solves stopped at the sweep limit, and when the push-out
    left a penetration deeper than ten times its tolerance (see
    :func:`~ncgen.runtime.stepper_checks.contact_report`)."""
    if report["penetration"] > 10 * report["penetration_tol"]:
        warnings.warn(f"simulate: contacts of {model.name!r} ended a step up to {report['penetration']:.3g} m inside "
                      f"(the push-out aims at {report['penetration_tol']:g} m and is repeated at most 4 times "
                      f"per step; info['contacts'])", stacklevel=5)
    if report["pgs_unconverged"]:
        warnings.warn(f"simulate: {report['pgs_unconverged']} contact solve(s) of {model.name!r} stopped at "
                      f"{report['pgs_max_sweeps']} projected Gauss-Seidel sweeps before the contact velocities "
                      f"settled to {report['pgs_tol']:g} (1 + max|U|) m/s; the last sweep still changed one by up to "
                      f"{report['pgs_residual']:.3g} (1 + max|U|) m/s (info['contacts']; redundant contacts, as under "
                      f"a body or a chain lying flat or in a pile, make it crawl, and friction can make it cycle)", stacklevel=5)


def _adaptive(model, stepper, t, U, p, q0, v0, lam0, hold, tol, max_iter, rtol, atol, order, max_steps,
              conservative, check, estimate) -> Trajectory:
    n_out = len(t) - 1
    dt = float(t[1] - t[0])
    start = time.perf_counter()

    def run(rtol, atol):
        return stepper.simulate_adaptive(q0, v0, lam0, float(t[0]), dt, n_out, U if model.nu else None,
                                         hold == "linear", p, rtol, atol, 0.0, order == 4, max_steps,
                                         not conservative, newton_tolerance(rtol, atol, tol), max_iter)

    with Ticker(f"stepper: {model.name}, rtol {rtol:g}"):
        Q, V, LAM, S, status, rows, h_next = run(rtol, atol)
        shadow = run(SHADOW_FACTOR * rtol, SHADOW_FACTOR * atol) if estimate and status == 0 else None
    stepping = time.perf_counter() - start
    info = {"method": "stepper", "backend": "compiled", "scheme": "RATTLE" if order == 2 else
            "RATTLE, Richardson-extrapolated and projected", "order": order, "rtol": rtol, "atol": atol,
            "hold": hold, "tol": newton_tolerance(rtol, atol, tol), "max_iter": max_iter, "max_steps": max_steps,
            "estimate": estimate, "stepping_time": stepping, "complete": status == 0,
            "stats": _stats(S[:rows], int(S[:rows, 2].sum()))}
    info["stats"]["rejected_steps"] = info["stats"].pop("step_splits")
    traj = _trajectory(model, stepper, t, q0, v0, lam0, Q, V, LAM, S, rows, U, p, info, conservative, start)
    if status != 0:
        message = (f"simulation of {model.name!r} with the error-controlled stepper (rtol {rtol:g}, atol "
                   f"{atol:g}) failed between t = {t[rows]:.6g} s and {t[rows + 1]:.6g} s (last step tried "
                   f"{h_next:.3g} s): {STATUS.get(status, f'status {status}')}. The trajectory up to "
                   f"t = {t[rows]:.6g} s is attached to this error as .trajectory.")
        traj.info["message"] = message
        raise SimulationError(message, time=float(t[rows]), trajectory=traj)
    if shadow is not None:
        eq, ev = shadow_estimates(Q, V, shadow, rows)
        traj.info["error_estimate"] = shadow_report(traj, eq, ev, rtol, atol)
        if check:
            _check_global(model, traj, eq, rtol, atol)
    return traj


def _check_global(model, traj, eq, rtol, atol):
    """Raise where the global estimate in q passes 1 % of the model's size (as for fixed
    steps), warn (:class:`~ncgen.errors.AccuracyWarning`) where it passes
    :data:`~ncgen.runtime.stepper_checks.GLOBAL_FACTOR` × the tolerance."""
    row = untrusted_global_row(model, eq)
    if row is not None:
        kept = traj.head(row + 1)
        message = (f"simulation of {model.name!r} with the error-controlled stepper (rtol {rtol:g}, atol {atol:g}) "
                   f"is not trustworthy: the estimated global error in q reached {eq[row]:.3g} m by "
                   f"t = {traj.t[row + 1]:.6g} s, more than {ERROR_FRACTION:g} of the model's size. rtol bounds "
                   f"the error of each step; errors that grow along the motion (chaotic or fast-spinning "
                   f"motion) need a smaller rtol, or the motion cannot be followed that far. The trajectory up "
                   f"to t = {kept.t[-1]:.6g} s is attached to this error as .trajectory (check=False returns "
                   f"the whole run unchecked).")
        kept.info.update(complete=False, message=message)
        raise SimulationError(message, time=float(kept.t[-1]), trajectory=kept)
    report = traj.info["error_estimate"]
    if report["exceeds_tolerance"]:
        warnings.warn(f"simulation of {model.name!r} with the error-controlled stepper: the estimated global "
                      f"error at the end ({report['q']:.3g} in q, {report['v']:.3g} in v) is more than "
                      f"{GLOBAL_FACTOR:g} times the tolerance (rtol {rtol:g}, atol {atol:g}): rtol bounds the "
                      f"error of each step, and errors grow along this motion; use a smaller rtol if the end "
                      f"state matters (traj.info['error_estimate'])", AccuracyWarning, stacklevel=4)


def newton_tolerance(rtol: float, atol: float, tol: float = TOL) -> float:
    """The Newton tolerance of an error-controlled run: ``tol``, at most
    :data:`NEWTON_FRACTION` × ``min(rtol, atol)`` (floored at 1e-14)."""
    return min(tol, max(NEWTON_FRACTION * min(rtol, atol), 1e-14))


def _stats(S: np.ndarray, splits: int) -> dict:
    return {"nsteps": int(S[:, 0].sum()), "newton_iterations": int(S[:, 1].sum()), "step_splits": int(splits)}


def _trajectory(model, stepper, t, q0, v0, lam0, Q, V, LAM, S, rows, U, p, info, conservative, start,
                impulses=None):
    """The trajectory of the first ``rows`` output rows, derived quantities from the
    compiled ``<model>_outputs`` (joint states and contact outputs from
    :func:`~ncgen.runtime.trajectory.derived_outputs`; ``impulses``: the nonsmooth contact
    impulses per output interval); sets the error estimate, the energy report and the wall
    time (from ``start``) in ``info``."""
    q = np.vstack([q0, Q[:rows]])
    v = np.vstack([v0, V[:rows]])
    lam = np.vstack([lam0, LAM[:rows]])
    tt, u = t[:rows + 1], U[:rows + 1]
    Y = stepper.outputs(tt, q, v, lam, u, p)
    dim, n_markers = model.dim, len(model.marker_names)
    markers = Y[:, 5:].reshape(len(tt), n_markers, dim)
    work = np.concatenate([[0.0], S[:rows, STATS.index("work")]])
    names = {key: getattr(model, key) for key in NAME_KEYS}
    extra_names, extra = derived_outputs(model, tt, q, v, p, impulses)
    traj = Trajectory(model_name=model.name, names={**names, **extra_names}, info=info, model=model, t=tt, q=q,
                      v=v, lam=lam, u=u, p=p, kinetic=Y[:, 0], potential=Y[:, 1], constraint_residual=Y[:, 2],
                      velocity_residual=Y[:, 3], markers=markers, **extra)
    traj.info["error_estimate"] = error_estimate(S[:rows], info.get("substeps"))
    traj.info["energy"] = energy_report(traj, work, conservative)
    if not conservative and len(traj):
        traj.info["energy"]["parts"] = balance_parts(model, traj)
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
