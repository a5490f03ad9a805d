"""The energy balance of a run: where the energy of a non-conservative motion went.

Along a motion ``dE/dt = P`` with ``P = vᵀ(F + ∇V) + ∂V/∂t + λᵀΦ_t`` (W; ``E = T + V``,
:func:`ncgen.assembly.stepper_equations.power_function`).  ``P`` is split into

* ``contacts``: the smooth contacts' dissipation, ``Σ_k f_T·(W_T v) − δ̇ (f_N − k δⁿ)``
  (their springs ``k δⁿ`` are in ``V``);
* ``inputs``: ``vᵀ(F(u) − F(0))``, the work of the inputs;
* ``drives``: ``λᵀΦ_t + ∂V/∂t``, rheonomic constraints and time-dependent potentials;
* ``dampers``: the rest, ``vᵀ(F(0) + ∇V)`` less the contacts: dampers and every other
  non-conservative force.

The work of each is the trapezoidal integral of its power at the output times (``W(t0) =
0``), and the balance's **residual** ``max |E − E0 − W|`` measures the integration error
together with that quadrature's.  A model is conservative for a run when it is so with the
run's inputs (:func:`ncgen.runtime.stepper_checks.is_conservative`; zero inputs do no work);
its report is the energy drift instead.
"""
from __future__ import annotations

import numpy as np

from ncgen.assembly.derived import power_parts_function

PARTS = ("contacts", "dampers", "inputs", "drives")

def works(model, t, q, v, lam, u, p) -> dict[str, np.ndarray]:
    """Work (J) of each of :data:`PARTS` and in all (``"total"``) from ``t[0]`` to each output time."""
    n = len(t)
    P = power_parts_function(model).map(n)(np.asarray(t, float)[None, :], q.T, v.T, lam.T,
                                      np.asarray(u, float).reshape(n, model.nu).T, np.asarray(p, float))
    total, contacts, inputs, drives = (np.array(x).reshape(-1) for x in P)
    powers = {"total": total, "contacts": contacts, "inputs": inputs, "drives": drives,
              "dampers": total - contacts - inputs - drives}
    dt = np.diff(np.asarray(t, float))
    return {k: np.concatenate([[0.0], np.cumsum(0.5 * dt * (w[1:] + w[:-1]))]) for k, w in powers.items()}


def present_parts(model) -> list[str]:
    """The parts of :data:`PARTS` a model can have (contacts, inputs; dampers always)."""
    parts = ["contacts"] if getattr(model, "nk", 0) else []
    parts.append("dampers")
    if model.nu:
        parts.append("inputs")
    parts.append("drives")
    return parts


def balance_parts(model, traj) -> dict[str, float]:
    """Work of each part at the end of ``traj`` (J, trapezoidal rule at the output times);
    nonsmooth contacts, whose impacts are not in the power, get the balance's remainder
    (:func:`by_remainder`)."""
    w = works(model, traj.t, traj.q, traj.v, traj.lam, traj.u, traj.p)
    parts = {k: float(w[k][-1]) for k in present_parts(model)}
    if by_remainder(model):
        rest = sum(v for k, v in parts.items() if k != "contacts")
        parts["contacts"] = float(traj.energy[-1] - traj.energy[0] - rest)
    return parts


def by_remainder(model) -> bool:
    """Whether the contacts' work is the balance's remainder (nonsmooth contacts)."""
    return getattr(model, "contact_model", "smooth") == "nonsmooth" and bool(getattr(model, "nk", 0))


def idas_report(model, traj, conservative: bool) -> dict:
    """``info["energy"]`` of an IDAS run: drift (conservative) or balance with its parts."""
    from ncgen.runtime.stepper_checks import energy_report

    if not len(traj):
        return {"conservative": conservative}
    if conservative:
        return energy_report(traj, np.zeros(len(traj)), True)
    w = works(model, traj.t, traj.q, traj.v, traj.lam, traj.u, traj.p)
    report = energy_report(traj, w["total"], False)
    report["parts"] = {k: float(w[k][-1]) for k in present_parts(model)}
    return report
