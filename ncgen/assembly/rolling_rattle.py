"""The equations of one RATTLE step with velocity constraints (a model with nonholonomic
elements, :class:`~ncgen.assembly.nonholonomic.RollingSystem`), as CasADi functions whose
zeros :mod:`ncgen.runtime.rolling_stepper` finds by Newton's method.

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

:func:`step_function` is the whole step as one CasADi function (the KKT solve for ``μ``, both
Newton solves by CasADi's ``fast_newton`` rootfinder with sparse QR, which C code generation
supports), which :mod:`ncgen.runtime.rolling_stepper` compiles.
"""
from __future__ import annotations

import casadi as ca

from ncgen.assembly.rolling_dae import rolling_kkt


def rattle_functions(system) -> dict[str, ca.Function]:
    """``{"drift": ..., "kick": ...}`` of ``system`` (module docstring; SX).

    ``drift(y, q, v, mu, t, h, u, p) -> (r, J)``: ``y = [v½; λ]``, residual
    ``r = [M (v½ − v) − h/2 (F − Φ̂_qᵀ λ − Bᵀ μ); Φ̂(q + h v½)]`` and ``J = ∂r/∂y``;
    ``kick(y, q, vh, t, h, u, p) -> (r, J)``: ``y = [v⁺; ν]`` at ``q = q⁺``,
    ``r = [M (v⁺ − v½) − h/2 (F(t + h, q, v⁺) − Â(q, t + h)ᵀ ν); Â(q, t + h) v⁺ − ĉ(q, t + h)]``."""
    out = {}
    for name, f in _residual_functions(system).items():
        x = f.sx_in()
        r = f(*x)
        out[name] = ca.Function(f.name(), x, [r, ca.jacobian(r, x[0])], f.name_in(), ["r", "J"])
    return out


def _residual_functions(system) -> dict[str, ca.Function]:
    """The residuals ``r`` of :func:`rattle_functions` alone (SX, same inputs)."""
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
    return {"drift": ca.Function("rolling_rattle_drift", [y1, q, v, mu, t, h, u, p], [r1],
                                 ["y", "q", "v", "mu", "t", "h", "u", "p"], ["r"]),
            "kick": ca.Function("rolling_rattle_kick", [y2, q, vh, t, h, u, p], [r2],
                                ["y", "q", "vh", "t", "h", "u", "p"], ["r"])}


def step_function(system, tol: float, max_iter: int) -> ca.Function:
    """``(q, v, t, h, u0, u1, p) -> (q⁺, v⁺, ν, res)``: one step from ``(q, v)`` at ``t`` over
    ``h`` (s), inputs ``u0`` in the first half kick and ``u1`` in the second (MX).  Each
    Newton solve runs from ``v`` (or ``v½``) with zero multipliers until the residual's
    max-norm is ≤ ``tol`` (at most ``max_iter`` iterations), then takes one more Newton
    correction; ``res`` is the larger of the two solves' residuals before that correction
    (above ``tol``: a solve did not converge).  The same iterates as
    :func:`ncgen.runtime.rolling_stepper.rattle_step`."""
    model, nq, nh = system.model, system.nq, system.n_holonomic
    residuals, newton_systems = _residual_functions(system), rattle_functions(system)
    kkt = rolling_kkt(system)
    q, v, t, h = ca.MX.sym("q", nq), ca.MX.sym("v", nq), ca.MX.sym("t"), ca.MX.sym("h")
    u0, u1, p = ca.MX.sym("u0", model.nu), ca.MX.sym("u1", model.nu), ca.MX.sym("p", len(model.p0))
    opts = {"abstol": tol, "abstolStep": 0.0, "max_iter": max_iter}

    def solve(name, y0, args):
        """``(y, |r|∞ before the last correction)`` of ``residuals[name](y, *args) = 0``."""
        y = ca.rootfinder(f"rolling_rattle_{name}_newton", "fast_newton", residuals[name], opts)(y0, *args)
        r, J = newton_systems[name](y, *args)
        return y - ca.solve(J, r, "qr"), ca.norm_inf(r)

    mu = kkt(t, q, v, u0, p)[1][nh:]
    y1, res1 = solve("drift", ca.vertcat(v, ca.MX.zeros(nh)), [q, v, mu, t, h, u0, p])
    v_half = y1[:nq]
    q_next = q + h * v_half
    y2, res2 = solve("kick", ca.vertcat(v_half, ca.MX.zeros(len(system.row_names))), [q_next, v_half, t, h, u1, p])
    return ca.Function("rolling_rattle_step", [q, v, t, h, u0, u1, p],
                       [q_next, y2[:nq], y2[nq:], ca.fmax(res1, res2)],
                       ["q", "v", "t", "h", "u0", "u1", "p"], ["q_next", "v_next", "nu", "res"])
