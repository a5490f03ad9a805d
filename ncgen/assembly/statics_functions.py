"""CasADi functions of statics, built from a model's system functions
(:mod:`ncgen.assembly.functions`; nothing is derived again).

At rest (``v = 0``) the equations of motion reduce to

    G(q, λ) = F(t, q, 0, u, p) − A(q)ᵀ λ = 0,    Φ(t, q) = 0,

and the *tangent stiffness* is ``K = −∂G/∂q = −∂F/∂q + Σ_k λ_k H_k`` (N/m): the stiffness
of the force elements, geometric stiffness of prestressed springs and cables included
(``∂F/∂q`` of a tensioned spring holds ``T/l (I − e eᵀ)``), plus the curvature of the
constraints weighted by their multipliers (``H_k = ∂²Φ_k/∂q²``).

``statics: t, q, lam, u, p -> G, phi, K, A``.
"""
from __future__ import annotations

import casadi as ca


def statics_function(f: dict) -> ca.Function:
    """``statics`` (see the module docstring) from the system functions ``f``."""
    nq = f["A"].size2_out(0)
    nc = f["A"].size1_out(0)
    nu, npar = f["F"].numel_in(3), f["F"].numel_in(4)
    t, q, lam = ca.SX.sym("t"), ca.SX.sym("q", nq), ca.SX.sym("lam", nc)
    u, p = ca.SX.sym("u", nu), ca.SX.sym("p", npar)
    A = f["A"](t, q, p)
    G = f["F"](t, q, ca.SX.zeros(nq), u, p) - ca.mtimes(A.T, lam)
    K = -ca.jacobian(G, q)
    return ca.Function("statics", [t, q, lam, u, p], [G, f["phi"](t, q, p), K, A],
                       ["t", "q", "lam", "u", "p"], ["G", "phi", "K", "A"])
