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

import weakref

import casadi as ca
import numpy as np

PARTS = ("contacts", "dampers", "inputs", "drives")

_functions: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def power_function(model) -> ca.Function:
    """``(t, q, v, lam, u, p) -> [P, P_contacts, P_inputs, P_drives]`` (W), kept per model."""
    if model in _functions:
        return _functions[model]
    f = model.functions
    t, q, v = ca.SX.sym("t"), ca.SX.sym("q", model.nq), ca.SX.sym("v", model.nq)
    lam, u, p = ca.SX.sym("lam", model.nc), ca.SX.sym("u", model.nu), ca.SX.sym("p", model.np)
    V = ca.sum1(model.potential_terms(t, q, p))
    F = f["F"](t, q, v, u, p)
    F0 = f["F"](t, q, v, ca.DM.zeros(model.nu), p)
    drives = ca.dot(lam, ca.densify(f["phi_t"](t, q, p))) + ca.jacobian(V, t)
    total = ca.dot(v, F + ca.gradient(V, q)) + drives
    contacts = ca.SX(0)
    if getattr(model, "nk", 0) and getattr(model, "contact_model", "smooth") == "smooth":
        g = f["gap"](q, p)
        WN, WT = f["contact_jacobian"](q, p)
        fN, fT = f["contact_force"](t, q, v, p)
        rate = -ca.mtimes(WN, v)
        for k, c in enumerate(model.contacts):
            delta = ca.fmax(0, -g[k])
            spring = ca.if_else(delta > 0, c["stiffness"] * delta ** c["exponent"], 0)
            contacts += -rate[k] * (fN[k] - spring)
        contacts += ca.dot(fT, ca.mtimes(WT, v))
    out = ca.Function("power_parts", [t, q, v, lam, u, p], [total, contacts, ca.dot(v, F - F0), drives])
    _functions[model] = out
    return out


def works(model, t, q, v, lam, u, p) -> dict[str, np.ndarray]:
    """Work (J) of each of :data:`PARTS` and in all (``"total"``) from ``t[0]`` to each output time."""
    n = len(t)
    P = power_function(model).map(n)(np.asarray(t, float)[None, :], q.T, v.T, lam.T,
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
