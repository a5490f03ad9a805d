"""The energy balance of a run: where the energy of a non-conservative motion went.

Along a motion ``dE/dt = P`` with ``P = vᵀ(F + ∇V) + ∂V/∂t + λᵀΦ_t`` (W; ``E = T + V``,
:func:`ncgen.assembly.stepper_equations.power_function`), and nonsmooth contacts change
``E`` by their impulses and their push-out.  The work ``W`` is split into the classes of
:data:`PARTS`:

* ``contacts``: the smooth contacts' normal dissipation ``−δ̇ (f_N − k δⁿ)`` (their springs
  ``k δⁿ`` are in ``V``), or the nonsmooth contacts' normal impulses;
* ``friction``: the smooth contacts' friction ``f_T·(W_T v)``, or the friction impulses;
* ``inputs``: ``vᵀ(F(u) − F(0))``, the work of the inputs;
* ``drives``: ``λᵀΦ_t + ∂V/∂t``, rheonomic constraints and time-dependent potentials;
* ``dampers``: the rest of ``P``, ``vᵀ(F(0) + ∇V)`` less the contacts: dampers, constant
  loads and every other non-conservative force;
* ``push_out``: the energy the push-out of penetrating nonsmooth contacts changed (a
  position correction of the contact stepper, ``runtime/ncgen_contact.h``).

The compiled stepper accumulates each class step by step inside its C loop (the forces'
work by the trapezoidal rule over each step with each end's own multipliers, second order as
RATTLE; an impulse ``P`` on the contact rows ``W0`` of the step's start and ``W`` of its free
end: ``¼ P·(W0 (v + w) + W (w + v⁺))`` exactly, the kinetic energy it adds to the step), so
the residual ``E − E0 − W`` is the integrator's own energy error.  An IDAS run integrates
the powers as quadrature states (:mod:`ncgen.runtime.idas`, :func:`interval_works`).  A model is
conservative for a run when it is so with the run's inputs
(:func:`ncgen.runtime.stepper_checks.is_conservative`); its report is the energy drift
instead.
"""
from __future__ import annotations

import numpy as np

from ncgen.assembly.derived import power_parts_function
from ncgen.codegen.stepper_package import STATS, WORK_PARTS

PARTS = WORK_PARTS


def present_parts(model) -> list[str]:
    """The classes of :data:`PARTS` a model can have (contacts and friction with contacts,
    inputs with inputs, the push-out with nonsmooth contacts; dampers and drives always)."""
    parts = ["contacts", "friction"] if getattr(model, "nk", 0) else []
    parts.append("dampers")
    if model.nu:
        parts.append("inputs")
    parts.append("drives")
    if nonsmooth_contacts(model):
        parts.append("push_out")
    return parts


def stepper_works(S: np.ndarray) -> dict[str, np.ndarray]:
    """Work (J) of each of :data:`PARTS` and in all (``"total"``) from the start of a
    compiled stepper's run to each output row, from its statistics ``S`` (columns
    :data:`~ncgen.codegen.stepper_package.STATS`), with 0 at the start prepended."""
    out = {"total": np.concatenate([[0.0], S[:, STATS.index("work")]])}
    for k in PARTS:
        out[k] = np.concatenate([[0.0], S[:, STATS.index(f"work_{k}")]])
    return out


def balance_report(model, report: dict, w: dict[str, np.ndarray]) -> dict:
    """``report`` (an energy report of a non-conservative run) with the work of each class
    at the end (``"parts"``) and at every output time (``"works"``: lists, J, ``"total"``
    and the classes the model can have) from ``w`` (:func:`stepper_works` or IDAS's)."""
    keys = [k for k in present_parts(model) if k in w]
    report["parts"] = {k: float(w[k][-1]) for k in keys}
    report["works"] = {k: [float(x) for x in w[k]] for k in ["total", *keys]}
    return report


def nonsmooth_contacts(model) -> bool:
    """Whether ``model`` has nonsmooth contacts (impulses, the contact stepper)."""
    return getattr(model, "contact_model", "smooth") == "nonsmooth" and bool(getattr(model, "nk", 0))


def interval_works(model, t, X, Z, U, p, W: np.ndarray) -> np.ndarray:
    """The work of each power of ``step_power`` from ``t[0]`` to each time of ``t`` (shape
    ``(len(t), 5)``), from ``W``, each interval's work in the row of its end (IDAS's
    quadratures; NaN for an interval IDAS did not integrate, bridged by RATTLE: there the
    trapezoidal rule over its two ends, states ``X = [q, v]``, ``Z = [a, λ]``, inputs ``U``)."""
    W = np.array(W, float)
    W[0] = 0.0
    missing = np.flatnonzero(np.isnan(W[:, 0]))
    if len(missing):
        nq = model.nq
        ends = np.unique(np.concatenate([missing - 1, missing]))
        P = np.array(power_parts_function(model).map(len(ends))(
            np.asarray(t, float)[ends][None, :], X[ends, :nq].T, X[ends, nq:].T, Z[ends, nq:].T,
            np.asarray(U, float)[ends].reshape(len(ends), model.nu).T, np.asarray(p, float))).T
        at = {int(i): P[j] for j, i in enumerate(ends)}
        for i in missing:
            W[i] = 0.5 * (t[i] - t[i - 1]) * (at[int(i) - 1] + at[int(i)])
    return np.cumsum(W, axis=0)


def idas_report(model, traj, conservative: bool, work: np.ndarray | None) -> dict:
    """``info["energy"]`` of an IDAS run: drift (conservative) or balance with its parts,
    from ``work`` (:func:`interval_works` at the output times; None for a conservative run)."""
    from ncgen.runtime.stepper_checks import energy_report

    if not len(traj):
        return {"conservative": conservative}
    if conservative:
        return energy_report(traj, np.zeros(len(traj)), True)
    total, contacts, friction, inputs, drives = np.asarray(work, float)[:len(traj)].T
    w = {"total": total, "contacts": contacts, "friction": friction, "inputs": inputs, "drives": drives,
         "dampers": total - contacts - friction - inputs - drives}
    report = balance_report(model, energy_report(traj, w["total"], False), w)
    report["quadrature"] = "integrated by IDAS as quadratures"
    return report
