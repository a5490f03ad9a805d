"""The equations of one RATTLE step with velocity constraints (a model with nonholonomic
elements, :class:`~ncgen.assembly.nonholonomic.RollingSystem`), as CasADi functions whose
zeros :mod:`ncgen.runtime.rolling_rattle` finds by Newton's method.

From ``(q, v)`` at ``t`` over a step ``h`` (s), with ``Φ̂`` the holonomic rows (the model's
constraints and the elements' heights), ``Â = [∂Φ̂/∂q; B]`` all velocity rows, ``ĉ(q, t)``
their right side (zero but on a moving plane) and ``F(t, q, v, u, p)`` the applied force:

1. a half kick and a drift, ``M (v½ − v) = h/2 (F(t, q, v) − Φ̂_q(q, t)ᵀ λ − B(q)ᵀ μ)``,
   ``q⁺ = q + h v½``, ``Φ̂(q⁺, t + h) = 0`` (a drive's rows at the step's end): unknowns ``(v½, λ)``; ``μ`` is the nonholonomic rows'
   multiplier of the KKT system at ``(q, v)`` (the exact constraint force at the step's
   start, given);
2. a half kick ending on both constraint levels, ``M (v⁺ − v½) = h/2 (F(t + h, q⁺, v⁺) −
   Â(q⁺, t + h)ᵀ ν)``, ``Â(q⁺, t + h) v⁺ = ĉ(q⁺, t + h)``: unknowns ``(v⁺, ν)``.

On holonomic rows alone this is RATTLE; the nonholonomic force is taken by the trapezoidal
rule between the exact one at the start and the implicit one at the end, so the scheme is of
order 2 (measured on the rolling disc, ``tests/test_rolling_rattle.py``) and both constraint
levels hold at every step's end to the Newton tolerance.  It is not symplectic (nonholonomic
motions have no symplectic structure); its energy error stays of order h².
"""
from __future__ import annotations

import casadi as ca


def rattle_functions(system) -> dict[str, ca.Function]:
    """``{"drift": ..., "kick": ...}`` of ``system`` (module docstring; SX).

    ``drift(y, q, v, mu, t, h, u, p) -> (r, J)``: ``y = [v½; λ]``, residual
    ``r = [M (v½ − v) − h/2 (F − Φ̂_qᵀ λ − Bᵀ μ); Φ̂(q + h v½)]`` and ``J = ∂r/∂y``;
    ``kick(y, q, vh, t, h, u, p) -> (r, J)``: ``y = [v⁺; ν]`` at ``q = q⁺``,
    ``r = [M (v⁺ − v½) − h/2 (F(t + h, q, v⁺) − Â(q, t + h)ᵀ ν); Â(q, t + h) v⁺ − ĉ(q, t + h)]``."""
    model, nq = system.model, system.nq
    nh, nn = system.n_holonomic, system.n_nonholonomic
    M = ca.DM(model.M)
    F = model.functions["F"]
    q, v, vh = ca.SX.sym("q", nq), ca.SX.sym("v", nq), ca.SX.sym("vh", nq)
    t, h = ca.SX.sym("t"), ca.SX.sym("h")
    u, p = ca.SX.sym("u", model.nu), ca.SX.sym("p", len(model.p0))
    mu = ca.SX.sym("mu", nn)
    A, A_end = system.A_at(q, t), system.A_at(q, t + h)
    y1 = ca.SX.sym("y", nq + nh)
    v_half, lam = y1[:nq], y1[nq:]
    r1 = ca.vertcat(ca.mtimes(M, v_half - v) - h / 2 * (F(t, q, v, u, p) - ca.mtimes(A.T, ca.vertcat(lam, mu))),
                    system.phi_at(q + h * v_half, t + h))
    y2 = ca.SX.sym("y", nq + nh + nn)
    v_end, nu_ = y2[:nq], y2[nq:]
    r2 = ca.vertcat(ca.mtimes(M, v_end - vh) - h / 2 * (F(t + h, q, v_end, u, p) - ca.mtimes(A_end.T, nu_)),
                    ca.mtimes(A_end, v_end) - system.rate(q, t + h))
    return {"drift": ca.Function("rolling_rattle_drift", [y1, q, v, mu, t, h, u, p], [r1, ca.jacobian(r1, y1)],
                                 ["y", "q", "v", "mu", "t", "h", "u", "p"], ["r", "J"]),
            "kick": ca.Function("rolling_rattle_kick", [y2, q, vh, t, h, u, p], [r2, ca.jacobian(r2, y2)],
                                ["y", "q", "vh", "t", "h", "u", "p"], ["r", "J"])}
