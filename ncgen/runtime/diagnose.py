"""Why did IDAS stop?  A readable cause from its return flag and the last good state."""
from __future__ import annotations

import re

import numpy as np

#: ``σ_min/σ_max`` of ``A`` below which the constraints count as (nearly) dependent.
SINGULAR_RATIO = 1e-7

_FLAG = re.compile(r'returned "(\w+)"')
_TIME = re.compile(r"t = ([-+0-9.eE]+)")

_CAUSES = {
    "IDA_TOO_MUCH_WORK": "IDAS needed more than max_steps steps within one output interval: the "
                         "motion is extremely fast or stiff there (a blow-up, huge or singular forces). "
                         "Check the forces and inputs near that time, or raise max_steps",
    "IDA_ERR_FAIL": "the error test failed repeatedly: the solution changes faster than the tolerances "
                    "allow (a singularity, a blow-up of the forces or a very stiff element). If the model "
                    "is right there, try a larger rtol/atol",
    "IDA_CONV_FAIL": "the Newton iteration failed repeatedly: the DAE Jacobian is singular or badly "
                     "conditioned (a singular configuration or redundant constraints) or the system is "
                     "very stiff; if it is only stiffness, a smaller rtol/atol (smaller steps) can help",
    "IDA_LSETUP_FAIL": "the linear solver could not factorise the DAE Jacobian: it is singular (a "
                       "singular configuration or redundant constraints) or not finite",
    "IDA_LSOLVE_FAIL": "the linear solve with the DAE Jacobian failed: it is singular (a singular "
                       "configuration or redundant constraints) or not finite",
    "IDA_RES_FAIL": "the DAE residual could not be evaluated (non-finite forces or inputs)",
    "IDA_REP_RES_ERR": "the DAE residual repeatedly returned errors (non-finite forces or inputs)",
    "KKT_FAIL": "the accelerations and multipliers (the KKT system) are not finite at the start of the "
                "interval, even by least squares: the forces, inputs or constraint functions are not finite",
    "RATTLE_FAIL": "IDAS cannot cross this interval next to a singular configuration and the RATTLE "
                   "steps that stand in for it failed too (see the message; a larger rtol/atol can help)",
    "IDA_TOO_MUCH_ACC": "the tolerances are too small for double precision: use a larger rtol/atol",
}


def idas_flag(error: Exception) -> str:
    """The IDAS return flag named in a CasADi error (``"IDA_ERR_FAIL"``...), or ``""``."""
    m = _FLAG.search(str(error))
    return m.group(1) if m else ""


def shift_time(message: str, t_s: float) -> tuple[str, float | None]:
    """IDAS's message with its time (relative to the chunk start ``t_s``, as IDAS integrates
    in shifted time) made absolute, and that absolute time (None if the message has none)."""
    m = _TIME.search(message)
    try:
        t = t_s + float(m.group(1).rstrip(",.")) if m else None
    except ValueError:
        return message, None
    if t is None:
        return message, None
    return message[:m.start(1)] + f"{t:.6g}" + message[m.end(1):], t


def explain(model, flag: str, t: float, q, v, lam, u, p, dae) -> str:
    """The likely cause of a failure right after the state ``(t, q, v, lam)``; ``flag`` is
    IDAS's return flag (``""``: only describe the state)."""
    notes = []
    x = np.concatenate([q, v])
    accel = np.array(model.functions["ode"](t, q, v, lam, u, p)[1]).reshape(-1)   # M⁻¹(F − Aᵀλ)
    ode, alg = (np.array(a).reshape(-1) for a in dae(t, x, np.concatenate([accel, lam]), u, p))
    if not (np.all(np.isfinite(ode)) and np.all(np.isfinite(alg))):
        bad = [model.coordinate_names[i] for i in np.flatnonzero(~np.isfinite(ode[model.nq:]))[:3]]
        notes.append("the accelerations are not finite" + (f" (at {', '.join(bad)})" if bad else "")
                     + ": a force law is singular there (e.g. a spring of zero length) or an input is")
    A = model.A(q, t=t, p=p)
    if A.size:
        U, s, _ = np.linalg.svd(A, full_matrices=False)
        ratio = s[-1] / s[0] if s[0] > 0 else 0.0
        if ratio < SINGULAR_RATIO:
            worst = np.argsort(-np.abs(U[:, -1]))[:4]
            names = ", ".join(model.constraint_names[i] for i in worst if abs(U[i, -1]) > 1e-3)
            notes.append(f"the constraint Jacobian is nearly singular (sigma_min/sigma_max = {ratio:.1e}): "
                         f"a singular configuration (e.g. a linkage passing a dead point) or redundant "
                         f"constraints; constraints involved: {names}")
    if flag and lam.size and np.all(np.isfinite(lam)):
        notes.append(f"max |lambda| = {np.max(np.abs(lam)):.3g}")
    if not flag:
        return "; ".join(notes) or "no obvious cause at this state"
    cause = _CAUSES.get(flag, f"IDAS stopped ({flag})")
    return cause + (". At the last good state: " + "; ".join(notes) if notes else "")
