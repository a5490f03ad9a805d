"""The cables' pull as a path constraint: ``P_i ≥ T_min`` keeps every cable taut.

``P = k (l − l₀) + c l̇`` (N) is a cable's pull before the cut at zero (its tension is
``max(P, 0)``, :mod:`ncgen.assembly.springs`; a clustered cable's ``l`` is its whole length).
Where every ``P_i > 0`` the dynamics are a smooth function of the state and the inputs, so an
optimiser that keeps ``P_i ≥ T_min > 0`` never crosses the kink of ``max(P, 0)``.  One source
for :meth:`ncgen.optim.problem.OptimalControl.min_tension` (the plan) and
``nc.MPC(..., min_tension=…)`` (:mod:`ncgen.control.mpc_problem`).
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.errors import OptimizationError
from ncgen.validation import as_scalar


def cable_indices(model, who: str) -> list[int]:
    """The springs of ``model`` that are cables (``Spring(cable=True)``, ``ClusteredCable``, a
    ``CapstanCable``'s sides); refused by name (``who``: the option asking) when there is none."""
    table = model.springs
    cables = [] if table is None else [i for i, c in enumerate(table.cable) if c]
    if not cables:
        raise OptimizationError(f"{who}: the model {model.name!r} has no cables (Spring(cable=True) or "
                                "ClusteredCable) to keep taut")
    return cables


def tension_floor(T_min, who: str) -> float:
    """``T_min`` (N) checked: a finite number ≥ 0."""
    value = as_scalar(T_min, who)
    if not np.isfinite(value) or value < 0:
        raise OptimizationError(f"{who}: expected a finite tension >= 0 in N, got {T_min!r}")
    return value


def cable_pull_function(model, who: str) -> ca.Function:
    """``cable_pull: (t, q, v, u, p) -> P``: the pull of each cable (N, in the order of
    ``model.springs``' cables), SX."""
    cables = cable_indices(model, who)
    t, q, v = ca.SX.sym("t"), ca.SX.sym("q", model.nq), ca.SX.sym("v", model.nq)
    u, p = ca.SX.sym("u", model.nu), ca.SX.sym("p", model.np)
    P = model.springs.function(t, q, v, u, p)[2][cables]
    return ca.Function("cable_pull", [t, q, v, u, p], [P], ["t", "q", "v", "u", "p"], ["P"])
