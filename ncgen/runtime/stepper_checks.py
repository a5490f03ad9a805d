"""What a stepper run says about its own accuracy: error estimates, the energy report, and
the checks the driver (:mod:`ncgen.runtime.stepper`) calls last: :func:`check_fixed` and
:func:`check_global` make an untrustworthy run an error (or a warning),
:func:`warn_unconverged` reports contact solves that stopped early.

A fixed-step run (:func:`ncgen.runtime.stepper.simulate_stepper` without ``rtol``) is
**untrustworthy** from the first output interval where

* a step had to be split (Newton's method did not converge at the step asked for);
* Newton's method needed more than :data:`NEWTON_LIMIT` iterations per RATTLE step on average
  (five per step of the fourth-order composition);
* the energy of a conservative model changed by more than :data:`ENERGY_FRACTION` of the
  energy scale, or, for a model with non-conservative forces or drives, the energy balance
  ``E(t) − E(t0) − W(t)`` (``W``: work of those forces and drives) is off by that much (the
  scale is at least :func:`roundoff_energy`, the error that rounding the positions can
  make and, with nonsmooth contacts, the work the contacts can do within their solves'
  velocity tolerance, so that a motion of that energy, a block resting under 1e-15 N, or at
  the origin under a reversing push of 1e-12 N, is no alarm);
* the estimated global error in q exceeds :data:`ERROR_FRACTION` of the model's size
  ``max |q0|`` (m);
* the shadow run of the error estimate (steps of 2h) failed and so did the run with steps
  of h/2 that then gives the estimate (:func:`~ncgen.runtime.stepper.fine_estimates`): the
  run has no estimate from there on;
* nonsmooth contacts: a contact solve stopped at its sweep limit with a last sweep that
  still changed a contact velocity by more than :data:`PGS_TRUST` (1 + max |U|) m/s;
* nonsmooth contacts: the contacts created energy, their work (normal + friction +
  push-out, accumulated step by step by the C loop) rising over an output row by more than
  :data:`CREATED_FRACTION` of the energy scale and the round-off floor
  (:func:`created_rows`, :func:`created_floor`), as when an unstable step lets a stack sink
  and the push-out lifts it back (a model whose contacts cannot dissipate is conservative:
  its contact work is not tracked, and ``E − E0`` itself is checked).

Models with nonsmooth contacts get no shadow run: an impact falls into different steps of
the run and of its shadow (steps of 2h), so their difference measures where the impact was
resolved, not the integration error (it is first order in h there).  Their energy check is
one-sided: contacts with restitution e ≤ 1 and Coulomb friction only take energy out, so
the run is flagged where ``E − E0 − W`` *rises* above :data:`ENERGY_FRACTION` of the energy
scale (W: the work of the non-conservative forces and drives; the contact impulses' work is
not in it), and a loss is what the contacts dissipate.

An error-controlled run (``rtol``) raises likewise where its global error estimate in q
exceeds :data:`ERROR_FRACTION` of the model's size, and warns
(:class:`~ncgen.errors.AccuracyWarning`) where the estimate at the end exceeds
:data:`GLOBAL_FACTOR` times its tolerance.

Error estimates (``info["error_estimate"]``, in m for q and m/s for v; never zero: at least
the round-off floor :func:`roundoff_floor`).  Fixed steps, by default (``estimate=True`` or
``"shadow"``): a **global** estimate, ``|y_h − y_2h| / (2^p − 1)`` against a shadow run
with steps of 2h (Richardson, p the scheme's order, 2 or 4; valid while both runs are in
the asymptotic regime; it follows the growth of errors along the motion, at half the work
again).  ``estimate="local"`` costs a fifth: the local error of one pair of steps in six
(and the run's last), from one step of 2h over the pair, ``d = (y_2h − y_pair) / (2^p −
1)``, summed along the run with the weight of the pairs each sample stands for; for the
fourth-order composition that sum is scaled by the growth of RATTLE's errors, ``max(1,
|y_R − y| / |Σ d_R|)`` from a RATTLE shadow run with steps of 2h (one RATTLE step per two
steps, a tenth of the work) and RATTLE steps of 2h from the sampled pairs' starts (their
local errors ``d_R``).  Measured against IDAS at 1e-12 (benchmarks/work_precision.py's
cases): 0.1–2.7× the true error on the 20-bar chain from h = 10 ms (error 9e-3 m) to
1.25 ms (3.6e-7 m); on the 5-bar chain spinning at 10 rad/s 0.4–1.7× at h ≤ 0.25 ms but
0.02–0.03× at 0.5–1 ms, where RATTLE at 2h no longer follows the motion and its growth is
lost: use the default there.
Error control: ``|y(rtol) − y(10 rtol)| / 10`` against a shadow run at 10× looser
tolerances (about half the work again), the error taken as proportional to the tolerance:
measured within 0.3–4× of the true error on a chain,
a stiff-spring pendulum and a fast-spinning chain (``tests/test_stepper_accuracy.py``).
Without the shadow run (``estimate=False``) an error-controlled run reports the sum of the
local estimates of its accepted steps, which misses that growth.
"""
from __future__ import annotations

import math
import warnings

import numpy as np

from ncgen.assembly.derived import depends_on_time, potential_force_residual_function
from ncgen.assembly.stepper_equations import nonsmooth
from ncgen.codegen.stepper_package import (CONTACT_STATS, PENETRATION_TOL, PGS_MAX_ITER, PGS_TOL, REPEAT_TOL,
                                         STATS)
from ncgen.errors import AccuracyWarning, SimulationError, option, user_stacklevel
from ncgen.model.data import model_data

#: The error columns of the statistics from where the shadow run (steps of 2h) failed and so did
#: the run with steps of h/2 that then gives the estimate (the C loops write −2 where the shadow failed).
NO_ESTIMATE = -3.0
#: Largest allowed change of a conservative model's energy, and error of the energy balance
#: of a non-conservative one, as a fraction of the energy scale ``max(|E|, T, |V − V0|, |W|)``
#: seen so far.
ENERGY_FRACTION = 0.01
#: Largest allowed estimated global error in q, as a fraction of the model's size max |q0|.
ERROR_FRACTION = 0.01
#: Most Newton iterations per step (average over an output interval) of a trusted run.
NEWTON_LIMIT = 8
#: Nonsmooth contacts: the largest last-sweep change of a contact velocity, relative to
#: 1 + max |U| (m/s per m/s), of a contact solve that stopped at its sweep limit in a trusted
#: run.  Below it such a solve is reported (``info["contacts"]`` and a warning), above it
#: the run is untrustworthy.
PGS_TRUST = 1e-3
#: The shadow run of an error-controlled run (its global error estimate) has tolerances
#: this many times looser.
SHADOW_FACTOR = 10.0
#: An error-controlled run warns when its global error estimate at the end exceeds this
#: many times the tolerance ``atol + rtol · max |y|``.
GLOBAL_FACTOR = 100.0



#: Nonsmooth contacts: the largest rise of the contacts' work (normal + friction + push-out)
#: over one output row, as a fraction of the energy scale, that is not energy created by the
#: contacts (beside the round-off floor; :func:`created_floor` says why).
CREATED_FRACTION = 1e-4
#: The classes of work that are the nonsmooth contacts' doing (``work_<class>`` of :data:`STATS`).
CONTACT_WORK = ("contacts", "friction", "push_out")


def created_work(S: np.ndarray) -> np.ndarray:
    """The work (J) of every class but the contacts' (normal, friction, push-out) from the
    start to each output row of a stepper's run with statistics ``S``, 0 prepended: ``E −
    E0`` less it is the contacts' doing, which must never be a gain."""
    rest = S[:, STATS.index("work")] - sum(S[:, STATS.index(f"work_{k}")] for k in CONTACT_WORK)
    return np.concatenate([[0.0], rest])


def contact_work_rise(S: np.ndarray) -> np.ndarray:
    """Per output row: the increment (J) of the contacts' work (normal + friction + push-out,
    :data:`CONTACT_WORK`) over the row, one column per class (rows × 3)."""
    W = np.column_stack([S[:, STATS.index(f"work_{k}")] for k in CONTACT_WORK])
    return np.diff(np.vstack([np.zeros((1, len(CONTACT_WORK))), W]), axis=0)


def created_floor(model, traj, S: np.ndarray, work: np.ndarray, rise: np.ndarray) -> np.ndarray:
    """Per output row: the largest rise (J) of the contacts' work over the row that is no
    creation of energy,

        ``CREATED_FRACTION E_s + n max‖F‖₁ (ε max|q| + τ h (1 + max|v|))``,

    ``E_s`` the energy scale ``max(|E|, T, |V − V0|, |W|)`` so far, ``n`` the RATTLE steps
    of the row and the second term :func:`roundoff_energy`'s floor per step at the row's end
    (the round-off of the positions under the applied forces ``F``, and the work contacts
    holding them, ``|P| ≤ h ‖F‖₁``, can do within the solves' velocity tolerance ``τ (1 +
    max|U|)``: a block creeping with its friction pushing it), which matters where the
    energy scale is itself of round-off size.  The first term is the discretisation's: the
    impulses' work is a second-order rule over each step on the contact rows at its two
    ends, and the push-out lifts the loads by the gap the steps' second-order drift sank, so
    contacts that only take energy in the motion show small positive rises on the grid
    (measured over the contact tests, h = 1 ms, at most 9.1e-6 of ``E_s`` in an output row:
    tests/test_contact.py's box dropped with random spins, 2.9e-4 J of 32 J in 10 ms at an
    impact; box_stack's push-out at rest 3.1e-7; the A1 of examples/quadruped_standing.py,
    whose feet's rows turn as they roll, 6e-9 per 1 ms); :data:`CREATED_FRACTION` is 11
    times the largest, and 77 times below the 40 ms pyramid's (7.7e-3 in one step).
    ``rise``: the rows' increments (:func:`contact_work_rise` summed); the force term is
    computed only where the first does not cover them."""
    floor = CREATED_FRACTION * _energy_scale(traj, work)[1:len(S) + 1]
    if np.any(~(rise <= floor)):
        n = S[:, STATS.index("steps")] * traj.info.get("stages", 1)
        floor = floor + n * roundoff_energy(model, traj, S) / np.maximum(np.cumsum(n), 1)
    return floor


def created_rows(model, traj, S: np.ndarray, work: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(flags, rise, floor)``: per output row of a nonsmooth contact run, whether the
    contacts created energy there, their work's increments by class (:func:`contact_work_rise`)
    and the floor (:func:`created_floor`) their sum is measured against.  Contacts
    with restitution ``e ≤ 1`` and Coulomb friction only take energy, and the push-out only
    removes a penetration the step made, so a row where normal, friction and push-out work
    together rise above the floor is a step too large for the motion (an unstable stack whose
    push-out lifts the boxes it let sink).  The rule is on the sum: at an impact the push-out
    alone adds energy (it lifts the bodies out of the penetration of that step) and friction
    can too, while the normal impulse takes more."""
    rise = contact_work_rise(S)
    total = rise.sum(axis=1)
    floor = created_floor(model, traj, S, work, total)
    return ~(total <= floor), rise, floor


def check_fixed(model, traj, S: np.ndarray, h: float, substeps: int, contacts: bool, conservative: bool,
                after: str = "") -> None:
    """Raise :class:`~ncgen.errors.SimulationError` from the first output interval where a
    fixed-step run is untrustworthy (module docstring), with the trajectory before it;
    ``after``: what happened later (a failed step), added to the message."""
    bad = untrusted_row(model, traj, S, h, contacts=contacts)
    if bad is None:
        return
    row, reason = bad
    kept = traj.head(row + 1)          # the states before C row `row`
    message = (f"simulation of {model.name!r} with the stepper (fixed step h = {h:.3g} s) is not "
               f"trustworthy: {reason}.{after} The trajectory up to t = {kept.t[-1]:.6g} s, before the "
               f"problem showed, is attached to this error as .trajectory "
               f"(check=False returns the whole run unchecked).")
    work = np.concatenate([[0.0], S[:row, STATS.index("work")]])
    estimate = error_estimate(S[:row], substeps, traj.info.get("estimate"), kept.q, kept.v)
    kept.info.update(complete=False, message=message, error_estimate=estimate,
                     energy=energy_report(kept, work, conservative, S[:row]))
    raise SimulationError(message, time=float(kept.t[-1]), trajectory=kept)


def trusted_before_failure(model, traj, S: np.ndarray, eq: np.ndarray | None):
    """``(traj, reason)`` for the rows an error-controlled run accepted before it failed: each
    step met the tolerance, but a run away can be accepted step by step.  The head of
    ``traj`` before the first row whose energy error (change of a conservative model,
    balance ``E − E0 − W`` otherwise) passes :data:`ENERGY_FRACTION` of its scale or is not
    finite, or whose global estimate in q ``eq`` (from a shadow run, or None) passes
    :data:`ERROR_FRACTION` of the model's size, whichever comes first, and why (``(traj, "")``
    when none does)."""
    if not len(S):
        return traj, ""
    work = np.concatenate([[0.0], S[:, STATS.index("work")]])
    conservative = traj.info["energy"]["conservative"]
    e_rel = relative_energy_error(model, traj, work, conservative, S)
    bad_energy = ~(e_rel <= ENERGY_FRACTION)                       # NaN counts as bad
    row_energy = int(np.argmax(bad_energy)) if bad_energy.any() else len(S)
    row_error = len(S) if eq is None else untrusted_global_row(model, eq[:len(S)])
    row_error = len(S) if row_error is None else row_error
    row = min(row_energy, row_error)
    if row == len(S):
        return traj, ""
    t_row = float(traj.t[row + 1])
    if row_error < row_energy:
        why = (f"its estimated global error in q (against a shadow run at {SHADOW_FACTOR:g}x looser tolerances) "
               f"reached {eq[row]:.3g} m by t = {t_row:.6g} s, more than {ERROR_FRACTION:g} of the model's size")
    elif np.isfinite(e_rel[row]):
        why = (f"its energy error grew by {e_rel[row]:.3g} of its energy scale by t = {t_row:.6g} s "
               f"(more than {ENERGY_FRACTION:g})")
    else:
        why = f"its energy is no longer finite by t = {t_row:.6g} s"
    kept = traj.head(row + 1)
    kept.info["energy"] = energy_report(kept, work[:row + 1], conservative, S[:row])
    return kept, f" Before that, {why}, so only the rows before it are kept."


def check_global(model, traj, eq, rtol, atol):
    """Raise where the global estimate in q passes 1 % of the model's size (as for fixed
    steps), warn (:class:`~ncgen.errors.AccuracyWarning`) where it passes
    :data:`GLOBAL_FACTOR` × the tolerance."""
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
                      f"state matters (traj.info['error_estimate'])", AccuracyWarning,
                      stacklevel=user_stacklevel())


def warn_unconverged(model, report: dict) -> None:
    """Warnings when some contact solves stopped at the sweep limit, and when the push-out
    left a penetration deeper than ten times its tolerance (see
    :func:`~ncgen.runtime.stepper_checks.contact_report`)."""
    if report["penetration"] > 10 * report["penetration_tol"]:
        warnings.warn(f"simulate: contacts of {model.name!r} ended a step up to {report['penetration']:.3g} m inside "
                      f"(the push-out aims at {report['penetration_tol']:g} m and is repeated at most 4 times "
                      f"per step; info['contacts'])", stacklevel=user_stacklevel())
    if report["pgs_unconverged"]:
        warnings.warn(f"simulate: {report['pgs_unconverged']} contact solve(s) of {model.name!r} stopped at "
                      f"{report['pgs_max_sweeps']} projected Gauss-Seidel sweeps before the contact velocities "
                      f"settled to {report['pgs_tol']:g} (1 + max|U|) m/s; the last sweep still changed one by up to "
                      f"{report['pgs_residual']:.3g} (1 + max|U|) m/s (info['contacts']; redundant contacts, as under "
                      f"a body or a chain lying flat or in a pile, make it crawl, and friction can make it cycle)",
                      stacklevel=user_stacklevel())


def is_conservative(model, inputs: bool = True) -> bool:
    """True if the model's forces are conservative and its constraints scleronomic:
    ``Φ_t`` and ``∂V/∂t`` are structurally zero and ``F = −∇V`` at random states with random
    rates and inputs (so that dampers, drives and input forces all count; ``inputs=False``:
    with the inputs at zero, as in a run that does not drive them).  Kept in the model's data."""
    data = model_data(model)
    if not inputs:
        if data.conservative_idle is None:
            data.conservative_idle = _is_conservative(model, inputs=False)
        return data.conservative_idle
    if data.conservative is None:
        data.conservative = _is_conservative(model)
    return data.conservative


def _is_conservative(model, samples: int = 3, seed: int = 0, inputs: bool = True) -> bool:
    if dissipative_contacts(model) or depends_on_time(model):
        return False
    if np.any(np.asarray(model.functions["phi_t"](model.t0, model.q0, model.p0)) != 0):
        return False
    residual = potential_force_residual_function(model)
    rng = np.random.default_rng(seed)
    for _ in range(samples):
        qs = model.q0 + 0.1 * rng.standard_normal(model.nq)
        r, F_value = residual(model.t0 + rng.random(), qs, rng.standard_normal(model.nq),
                              rng.standard_normal(model.nu) if inputs else np.zeros(model.nu), model.p0)
        if np.max(np.abs(np.asarray(r)), initial=0.0) > 1e-9 * (1 + np.max(np.abs(np.asarray(F_value)), initial=0.0)):
            return False
    return True


def dissipative_contacts(model) -> bool:
    """Whether a contact can dissipate: friction, smooth damping, or an impact with e < 1
    (random states near q0 rarely touch, so contacts are judged by their parameters)."""
    smooth = getattr(model, "contact_model", "smooth") == "smooth"
    return any(c["mu"] > 0 or (c["damping"] > 0 if smooth else c["restitution"] < 1)
               for c in getattr(model, "contacts", ()) or ())


def global_estimates(S: np.ndarray, substeps: int | None) -> tuple[np.ndarray, np.ndarray]:
    """Estimated global error in q (m) and v (m/s) at the end of each output row, from the
    per-row statistics ``S`` of the C loops (columns :data:`STATS`); NaN where there is none."""
    eq, ev = S[:, STATS.index("error_q")].copy(), S[:, STATS.index("error_v")].copy()
    if substeps is None:                               # error control: sums of local estimates per row
        return np.cumsum(eq), np.cumsum(ev)
    for e in (eq, ev):                                 # fixed steps: the shadow run's estimates
        e[e < 0] = np.nan
    return eq, ev


def shadow_estimates(Q, V, shadow, rows: int) -> tuple[np.ndarray, np.ndarray]:
    """Global error estimates in q (m) and v (m/s) per output row of an error-controlled run
    ``(Q, V)`` from its shadow run at tolerances ``SHADOW_FACTOR`` times looser (the result
    of ``simulate_adaptive``): ``max |y − y_shadow| / SHADOW_FACTOR``, the error assumed
    proportional to the tolerance; NaN from where the shadow run failed."""
    Qs, Vs, _, _, _, rows_s, _ = shadow
    eq, ev = np.full(rows, np.nan), np.full(rows, np.nan)
    n = min(rows, rows_s)
    eq[:n] = np.max(np.abs(Q[:n] - Qs[:n]), axis=1) / SHADOW_FACTOR
    ev[:n] = np.max(np.abs(V[:n] - Vs[:n]), axis=1) / SHADOW_FACTOR
    return eq, ev


def roundoff_floor(steps: int, y: np.ndarray) -> float:
    """The least error an estimate claims: ``ε √steps max(1, max |y|)`` (ε the double
    precision's; the round-off of ``steps`` steps on values of size ``max |y|``)."""
    return float(np.finfo(float).eps * math.sqrt(max(steps, 1)) * max(1.0, float(np.max(np.abs(y), initial=0.0))))


def shadow_report(traj, eq: np.ndarray, ev: np.ndarray, rtol: float, atol: float, S: np.ndarray,
                  same_steps: bool = False) -> dict:
    """``info["error_estimate"]`` of an error-controlled run (see :func:`shadow_estimates`; at
    least the round-off floor of the steps counted in the per-row statistics ``S``, and, where
    the shadow run took the same steps (``same_steps``: its difference then says nothing), at
    least the sum of the local estimates), with
    ``exceeds_tolerance``: the end estimate above
    :data:`GLOBAL_FACTOR` × ``atol + rtol · max |y|`` (q and v separately, ``max |y|`` over
    the run)."""
    if not len(eq):
        return {"q": 0.0, "v": 0.0, "exceeds_tolerance": False}
    steps = int(S[:len(eq), STATS.index("steps")].sum())
    eq, ev = np.fmax(eq, roundoff_floor(steps, traj.q)), np.fmax(ev, roundoff_floor(steps, traj.v))
    if same_steps:      # the shadow run took the very same steps (both limited by the output grid)
        lq, lv = global_estimates(S[:len(eq)], None)
        eq, ev = np.fmax(eq, lq), np.fmax(ev, lv)
    tol_q = atol + rtol * float(np.max(np.abs(traj.q)))
    tol_v = atol + rtol * float(np.max(np.abs(traj.v)))
    exceeds = bool(eq[-1] > GLOBAL_FACTOR * tol_q or ev[-1] > GLOBAL_FACTOR * tol_v)
    return {"q": float(eq[-1]), "v": float(ev[-1]), "exceeds_tolerance": exceeds,
            "how": "global: |y(rtol) - y(10 rtol)| / 10 against a shadow run at 10x looser tolerances"}


def untrusted_global_row(model, eq: np.ndarray) -> int | None:
    """The first output row where the global estimate in q of an error-controlled run
    exceeds :data:`ERROR_FRACTION` of the model's size ``max |q0|``, or None."""
    size = max(float(np.max(np.abs(model.q0), initial=0.0)), 1e-9)
    bad = np.nan_to_num(eq) > ERROR_FRACTION * size
    return int(np.argmax(bad)) if bad.any() else None


def error_estimate(S: np.ndarray, substeps: int | None, mode: str | bool = "shadow", q=None, v=None,
                   grown: bool = True) -> dict:
    """``info["error_estimate"]``: the estimated error at the end (m, m/s; NaN when there
    is none, else at least :func:`roundoff_floor` of the run's ``q`` and ``v``) and how it
    was obtained; ``mode``: the fixed-step run's estimate (``"local"``, ``"shadow"`` or
    False); ``grown``: a local estimate scaled by the growth of RATTLE's errors (the
    fourth-order scheme's; RATTLE's own local estimate is not)."""
    if not len(S):
        return {"q": 0.0, "v": 0.0}
    gq, gv = global_estimates(S, substeps)
    if substeps is None:
        how = "sum of the local error estimates of the accepted steps (Richardson, halves against whole steps)"
    elif np.isnan(gq[-1]) and np.any(S[:, STATS.index("error_q")] == -2):
        how = "none: the shadow run with steps of 2h failed (Newton), the step is near its limit"
    elif np.isnan(gq[-1]) and np.any(S[:, STATS.index("error_q")] == NO_ESTIMATE):
        how = "none: the shadow run with steps of 2h failed (Newton), and so did the run with steps of h/2"
    elif np.isnan(gq[-1]):
        how = "none (estimate=False, or a single step)"
    elif mode == "local":
        how = ("local errors of one pair of steps in six against a step of 2h, |y_2h - y_pair| / (2^p - 1) "
               "(p: the scheme's order), summed" + (" and grown as a RATTLE shadow run's errors grow" if grown else
                                                    " without their growth") +
               " (cheap; too low where errors grow fast: estimate='shadow')")
    else:
        how = "Richardson: |y_h - y_2h| / (2^p - 1) against a shadow run with steps of 2h (p: the scheme's order)"
    eq, ev = float(gq[-1]), float(gv[-1])
    if np.isfinite(eq) and q is not None:
        steps = int(S[:, STATS.index("steps")].sum())
        eq, ev = max(eq, roundoff_floor(steps, q)), max(ev, roundoff_floor(steps, v))
    return {"q": eq, "v": ev, "how": how}


def _energy_scale(traj, work: np.ndarray) -> np.ndarray:
    E = traj.energy
    terms = np.abs(np.column_stack([E, traj.kinetic, traj.potential - traj.potential[0], work]))
    return np.maximum.accumulate(terms.max(axis=1))


def energy_error(traj, work: np.ndarray, conservative: bool) -> np.ndarray:
    """Per sample: ``|E − E0|`` (conservative) or ``|E − E0 − W|`` (J)."""
    E = traj.energy
    return np.abs(E - E[0] - (0.0 if conservative else work))


def roundoff_energy(model, traj, S: np.ndarray) -> np.ndarray:
    """Per output row (at its end): the energy error that the run's own round-off and, with
    nonsmooth contacts, the tolerance of its contact solves can make (J),

        ``N max‖F‖₁ (ε max|q| + τ h (1 + max|v|))``,

    where ``N`` is the number of RATTLE steps so far, ``F(t, q, v, u, p)`` the applied
    generalised forces, ``q`` and ``v`` the samples so far, ``h`` the step (s) and ``τ`` the
    contact solves' relative velocity tolerance (:data:`~ncgen.codegen.stepper_package.PGS_TOL`,
    ``REPEAT_TOL``; 0 without nonsmooth contacts).

    Positions: each step rounds ``q`` to within ``ε max|q|`` per coordinate, and ``E − E0 − W``
    changes by the work ``F · δq`` of the applied forces over that rounding (the kinetic
    energy comes from ``v``, which is not rounded with ``q``).  Contacts: a solve accepts
    impulses ``P`` whose contact velocities meet Signorini's and Coulomb's laws to
    ``τ (1 + max|U|)`` m/s, not exactly (a block at rest keeps the last step's friction
    impulse while the push reverses, and creeps at ~1e-13 m/s with friction pushing it), so
    over a step the contacts can do the positive work ``|P| τ (1 + max|U|)``; contacts that
    hold the applied forces take ``|P| ≤ h ‖F‖₁`` per step (``max|U|`` taken as ``max|v|``;
    an impact's impulse ``m |Δv|`` is not in it, which matters only at impact speeds below
    ~1e-10 m/s).  A motion whose energy is of this size (a block resting under 1e-15 N, at
    the origin under a push of 1e-12 N that reverses, a spring at rest pushed by 1e-10 N) is
    below what the energy can tell.  Zero where it is not finite (an overflowed state is
    judged by the energy error alone)."""
    if not len(S):
        return np.zeros(0)
    n = len(S) + 1
    tables = model_data(model).steppers.get(("tables", None)) if traj.info.get("kernels") == "tables" else None
    if tables is not None:                 # the tables' forces: no flat function on their path
        F = np.column_stack([tables.forces(traj.q[k], traj.v[k], traj.u[k]) for k in range(n)])
    else:
        F = np.asarray(model.functions["F"].map(n)(traj.t[:n], traj.q[:n].T, traj.v[:n].T, traj.u[:n].T,
                                                   np.asarray(traj.p, float)))
    force = np.maximum.accumulate(np.abs(F).sum(axis=0))[1:]
    size = np.maximum.accumulate(np.max(np.abs(traj.q[:n]), axis=1, initial=0.0))[1:]
    steps = np.cumsum(S[:, STATS.index("steps")]) * traj.info.get("stages", 1)
    with np.errstate(invalid="ignore", over="ignore"):
        creep = 0.0
        if nonsmooth(model):
            speed = np.maximum.accumulate(np.max(np.abs(traj.v[:n]), axis=1, initial=0.0))[1:]
            creep = max(PGS_TOL, REPEAT_TOL) * float(traj.info.get("h", 0.0)) * (1 + speed)
        floor = steps * force * (np.finfo(float).eps * size + creep)
    return np.where(np.isfinite(floor), floor, 0.0)


def energy_denominator(model, traj, work: np.ndarray, S: np.ndarray, error: np.ndarray) -> np.ndarray:
    """Per output row: what its energy error ``error`` (J, one per row) is measured against,
    the run's energy scale ``max(|E|, T, |V − V0|, |W|)`` so far, or, for rows where the
    error passes :data:`ENERGY_FRACTION` of it, at least :func:`roundoff_energy` (computed
    only then)."""
    scale = np.maximum(_energy_scale(traj, work)[1:len(S) + 1], 1e-300)
    if np.any(~(np.abs(error) <= ENERGY_FRACTION * scale)):
        scale = np.maximum(scale, roundoff_energy(model, traj, S))
    return scale


def relative_energy_error(model, traj, work: np.ndarray, conservative: bool, S: np.ndarray) -> np.ndarray:
    """:func:`energy_error` at the end of each output row over :func:`energy_denominator`."""
    error = energy_error(traj, work, conservative)[1:len(S) + 1]
    return error / energy_denominator(model, traj, work, S, error)


def energy_report(traj, work: np.ndarray, conservative: bool, S: np.ndarray | None = None) -> dict:
    """``info["energy"]``: energy drift of a conservative model, or the energy balance
    (work ``W`` of the non-conservative forces and drives, and ``max |E − E0 − W|``);
    ``relative`` against the energy scale at the end, or, given the run's statistics ``S``
    and above :data:`ENERGY_FRACTION`, against at least :func:`roundoff_energy` (as the
    check measures it)."""
    if not len(traj):
        return {"conservative": conservative}
    err = energy_error(traj, work, conservative)
    scale = float(_energy_scale(traj, work)[-1])
    if S is not None and len(S) and not err.max() <= ENERGY_FRACTION * scale and traj.model is not None:
        floor = roundoff_energy(traj.model, traj, S)
        scale = max(scale, float(floor[-1]) if len(floor) else 0.0)
    rel = float(err.max() / scale) if scale > 0 else 0.0
    if conservative:
        return {"conservative": True, "drift": float(err.max()), "relative": rel}
    return {"conservative": False, "work": float(work[-1]), "balance_error": float(err.max()), "relative": rel}


def contact_report(S: np.ndarray) -> dict:
    """``info["contacts"]`` of a fixed-step run with nonsmooth contacts: the contact solves
    whose projected Gauss–Seidel stopped at its sweep limit (``pgs_unconverged``) and the
    largest last-sweep change of a contact velocity among them, relative to 1 + max |U|
    (``pgs_residual``), beside the limit and the tolerance it did not reach; the deepest
    penetration left at the end of any step, after the push-out (``penetration``, m; the
    push-out aims at ``penetration_tol``); the largest residual of the contact laws at the
    impulses of any solved step (``cone_residual``: by how much a contact velocity misses
    Signorini's or Coulomb's law, m/s relative to 1 + max |U|; the solves aim at ``pgs_tol``)."""
    unconverged, residual, depth, law = (S[:, len(STATS) + CONTACT_STATS.index(k)] for k in CONTACT_STATS)
    return {"pgs_unconverged": int(unconverged.sum()), "pgs_residual": float(residual.max(initial=0.0)),
            "pgs_max_sweeps": PGS_MAX_ITER, "pgs_tol": PGS_TOL, "penetration": float(depth.max(initial=0.0)),
            "penetration_tol": PENETRATION_TOL, "cone_residual": float(law.max(initial=0.0))}


def row_flags(splits, iters, steps, stages: int, e_rel, gq, size: float, residual=None,
              error_q=None) -> dict[str, np.ndarray]:
    """The checks of :func:`untrusted_row`, per output row of the statistics (arrays of any
    shape, e.g. runs × rows): which rows each check flags.  ``e_rel``: the energy error over
    its scale; ``gq``: the global error estimate in q (m); ``size``: the largest |q0| (m);
    ``residual``: the contact solves' last sweep change (None: no contacts); ``error_q``:
    the statistics' column of that name (:data:`NO_ESTIMATE` flagged: from where the shadow
    run failed and so did the run with steps of h/2 that replaces its estimate,
    :func:`~ncgen.runtime.stepper.fine_estimates`)."""
    flags = {
        "splits": splits > 0,
        "newton": iters / np.maximum(steps * stages, 1) > NEWTON_LIMIT,
        "energy": e_rel > ENERGY_FRACTION,
        "error": np.nan_to_num(np.maximum(gq, 0.0)) > ERROR_FRACTION * size,
    }
    if error_q is not None:
        flags["shadow"] = error_q == NO_ESTIMATE
    if residual is not None:
        flags["contacts"] = residual > PGS_TRUST
    return flags


def untrusted_row(model, traj, S: np.ndarray, h: float, contacts: bool = False) -> tuple[int, str] | None:
    """``(row, reason)`` of the first output row where the fixed-step run stops being
    trustworthy (module docstring), or None; ``contacts``: a run of the nonsmooth contact
    stepper (one-sided energy check, contact solves checked)."""
    if not len(S):
        return None
    conservative = traj.info["energy"]["conservative"]
    work = np.concatenate([[0.0], S[:, STATS.index("work")]])
    steps, iters, splits = (S[:, STATS.index(k)] for k in ("steps", "newton_iterations", "splits"))
    stages = traj.info.get("stages", 1)                 # RATTLE steps per step
    gq, _ = global_estimates(S, traj.info.get("substeps"))
    size = max(float(np.max(np.abs(model.q0), initial=0.0)), 1e-9)
    e_rel, residual = _energy_errors(model, traj, S, work, contacts, conservative)
    dt = h * traj.info.get("substeps", 1)
    flags = row_flags(splits, iters, steps, stages, e_rel, gq, size, residual, S[:, STATS.index("error_q")])
    if contacts and not conservative:           # a conservative run's contact work is not tracked: E - E0 tells
        flags["created"], rise, floor = created_rows(model, traj, S, work)
    first = {k: int(np.argmax(f)) for k, f in flags.items() if f.any()}
    if not first:
        return None
    kind = min(first, key=first.get)
    row = first[kind]
    t_row = float(traj.t[row + 1])
    suggest = _suggestion(h, dt, gq[row], size, kind, adaptive=not getattr(model, "rolling", ()))
    if kind == "splits":
        reason = _splits_reason(int(splits.sum()), t_row)
    elif kind == "newton":
        reason = _newton_reason(iters[row] / max(steps[row] * stages, 1), t_row)
    elif kind == "energy":
        reason = _energy_reason(e_rel[row], t_row, contacts, conservative)
    elif kind == "created":
        depth = S[:row + 1, len(STATS) + CONTACT_STATS.index("penetration")].max()
        reason = _created_reason(rise[row], floor[row], float(_energy_scale(traj, work)[row + 1]), depth, t_row)
    elif kind == "contacts":
        reason = _contacts_reason(residual[row], t_row)
    elif kind == "shadow":
        reason = _shadow_reason(t_row)
    else:
        reason = _error_reason(gq[row], size, t_row)
    return row, f"{reason}. {suggest}"


def _energy_errors(model, traj, S: np.ndarray, work: np.ndarray, contacts: bool, conservative: bool):
    """Per output row, the energy error over its scale (inf where the state overflowed or is
    NaN) and the contact solves' last sweep change (None without contacts); a run with
    contacts counts only a gain, as contacts dissipate."""
    if contacts:
        E = traj.energy
        gain = (E - E[0] - created_work(S))[1:]         # E - E0 less the work of all but the contacts
        e_rel = gain / energy_denominator(model, traj, work, S, np.maximum(gain, 0.0))
        residual = S[:, len(STATS) + CONTACT_STATS.index("pgs_residual")]
    else:
        e_rel = relative_energy_error(model, traj, work, conservative, S)
        residual = None
    return np.where(np.isnan(e_rel), np.inf, e_rel), residual


def _splits_reason(count: int, t_row: float) -> str:
    return (f"{count} step(s) had to be split, the first by t = {t_row:.6g} s: Newton's method "
            f"does not converge at this step, which is far beyond the step the motion needs")


def _newton_reason(per_step: float, t_row: float) -> str:
    return (f"Newton's method needed {per_step:.3g} iterations per RATTLE step by "
            f"t = {t_row:.6g} s (more than {NEWTON_LIMIT}): the step is too large for this motion")


def _energy_reason(e_rel: float, t_row: float, contacts: bool, conservative: bool) -> str:
    if contacts:
        what = ("energy of this model rose through its contacts" if conservative else
                "energy balance E - E0 - W (W: work of its non-conservative forces and drives) rose through "
                "its contacts")
    else:
        what = ("energy of this conservative model changed" if conservative else
                "energy balance E - E0 - W (W: work of its non-conservative forces and drives) is off")
    return (f"the {what} by {e_rel:.3g} of its energy scale by t = {t_row:.6g} s (more than "
            f"{ENERGY_FRACTION:g})" if np.isfinite(e_rel) else
            f"the motion diverged: the energy is no longer finite by t = {t_row:.6g} s")


def _created_reason(rise: np.ndarray, floor: float, scale: float, depth: float, t_row: float) -> str:
    """``rise``: the contacts' normal, friction and push-out work gained over the interval (J);
    ``depth``: the deepest penetration left so far (m)."""
    parts = ", ".join(f"{name} {w:+.3g} J" for name, w in zip(("normal", "friction", "push-out"), rise))
    return (f"its contacts created energy: their work (normal + friction + push-out) rose by "
            f"{rise.sum():.3g} J ({rise.sum() / scale:.3g} of its energy scale {scale:.3g} J) over "
            f"the output interval to t = {t_row:.6g} s ({parts}), above its floor {floor:.3g} J "
            f"({CREATED_FRACTION:g} of the scale and round-off); contacts with restitution <= 1 and "
            f"Coulomb friction only take energy, and the push-out only removes what the step sank "
            f"(deepest penetration left so far {depth:.3g} m): the step is too large for this motion")


def _contacts_reason(residual: float, t_row: float) -> str:
    return (f"the contact impulses did not converge by t = {t_row:.6g} s: projected Gauss-Seidel stopped "
            f"at {PGS_MAX_ITER} sweeps with a last sweep still changing a contact velocity by "
            f"{residual:.3g} (1 + max|U|) m/s (more than {PGS_TRUST:g}; redundant contacts make "
            f"it crawl, and friction can make it cycle)")


def _shadow_reason(t_row: float) -> str:
    return (f"its shadow run with steps of 2h failed by t = {t_row:.6g} s (Newton's method did not converge at "
            f"2h), and so did the run with steps of h/2 that then gives the estimate: the run has no error "
            f"estimate from there on")


def _error_reason(gq: float, size: float, t_row: float) -> str:
    return (f"the estimated error in q reached {gq:.3g} m by t = {t_row:.6g} s, more than "
            f"{ERROR_FRACTION:g} of the model's size {size:.3g} m")


def _suggestion(h: float, dt: float, err: float, size: float, kind: str, adaptive: bool = True) -> str:
    if kind == "contacts":
        return ("A smaller step makes the contact problems smaller changes of the last one (warm start); "
                "check=False returns the run unchecked")
    return _step_suggestion(h, dt, err, size, kind, adaptive)


def _step_suggestion(h: float, dt: float, err: float, size: float, kind: str, adaptive: bool = True) -> str:
    """Which step to use instead: a quarter of ``h`` after split steps, exploding Newton
    iterations or an energy error, half of it after a large error estimate or a failed
    shadow run, and in every
    case no more than the step at which the estimate (∝ h²) would be 1 % of the size;
    ``adaptive``: error control (``rtol``) is offered too (not for rolling elements)."""
    h_new = h / 2 if kind in ("error", "shadow") else h / 4
    if err > 0 and math.isfinite(err):
        h_new = min(h_new, h * math.sqrt(0.1 * ERROR_FRACTION * size / err))
    substeps = max(1, math.ceil(dt / h_new - 1e-9))
    step = (f"Use a step of at most {dt / substeps:.3g} s ({option('substeps=', '--substeps ')}{substeps} with "
            f"{option('dt = ', '--dt ')}{dt:.3g} s)")
    return f"{step}, or {option('rtol=...', '--rtol RTOL')} to let the stepper choose its steps" if adaptive else step
