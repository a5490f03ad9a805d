"""The index-1 DAE of a model with nonholonomic elements, in IDAS's form, and its KKT
accelerations at any time, inputs and parameters.

For a :class:`~ncgen.assembly.nonholonomic.RollingSystem` (holonomic ``Φ̂(q, t) = 0``: the
model's constraints, drives included, and the elements' heights; all velocity rows
``Â(q, t) v = ĉ(q, t)``, ``Â = [∂Φ̂/∂q; B]``, ``ĉ = [−∂Φ̂/∂t; c]``, zero but for drives and
elements on a moving plane), with ``x = [q; v]``,
``z = [a; λ]``::

    q̇ = v,   v̇ = a,
    0 = M a + Âᵀ λ − F(t, q, v, u, p),
    0 = Â a − γ̂(q, v, t) + 2α (Â v − ĉ) + β² [Φ̂(q, t); 0]

``γ̂ = −∂(Â v − ĉ)/∂q v − ∂(Â v − ĉ)/∂t`` (:attr:`RollingSystem.gamma_t`): the acceleration level of
both kinds of rows, so the nonholonomic rows ``B v = c`` have their own multipliers (the
``.x``/``.y``/``.lateral`` entries of ``λ``) as the holonomic ones do.  ``(α, β)`` are the
model's Baumgarte coefficients (s⁻¹): the velocity rows are stabilised at first order, the
holonomic ones at second.  ``M`` enters as itself (a flat body's singular ``M`` is fine:
the KKT system is regular on the constraints).
"""
from __future__ import annotations

import casadi as ca


def rolling_dae(system) -> ca.Function:
    """``dae(t, x, z, u, p) -> (ode, alg)`` of ``system`` (module docstring; SX), the form of
    ``model.functions["dae"]`` with ``z = [a; λ]`` over all rows ``system.row_names``."""
    model, nq = system.model, system.nq
    alpha, beta = model.baumgarte
    m = system.n_holonomic + system.n_nonholonomic
    t, x, z = ca.SX.sym("t"), ca.SX.sym("x", 2 * nq), ca.SX.sym("z", nq + m)
    u, p = ca.SX.sym("u", model.nu), ca.SX.sym("p", len(model.p0))
    q, v, a, lam = x[:nq], x[nq:], z[:nq], z[nq:]
    A = system.A_at(q, t)
    level = ca.mtimes(A, v) - system.rate(q, t)
    position = ca.vertcat(system.phi_at(q, t), ca.SX.zeros(system.n_nonholonomic))
    alg = ca.vertcat(ca.mtimes(ca.DM(model.M), a) + ca.mtimes(A.T, lam) - model.functions["F"](t, q, v, u, p),
                     ca.mtimes(A, a) - system.gamma_t(q, v, t) + 2.0 * alpha * level + beta ** 2 * position)
    return ca.Function("rolling_dae", [t, x, z, u, p], [ca.vertcat(v, a), alg],
                       ["t", "x", "z", "u", "p"], ["ode", "alg"])


def rolling_kkt(system) -> ca.Function:
    """``(t, q, v, u, p) -> (a, λ)``: the KKT system ``[[M, Âᵀ], [Â, 0]] [a; λ] =
    [F(t, q, v, u, p); γ̂(q, v, t)]`` solved (no stabilisation terms: exact on the
    constraints; MX, sparse QR)."""
    model, nq = system.model, system.nq
    t, q, v = ca.MX.sym("t"), ca.MX.sym("q", nq), ca.MX.sym("v", nq)
    u, p = ca.MX.sym("u", model.nu), ca.MX.sym("p", len(model.p0))
    A = system.A_at(q, t)
    m = A.shape[0]
    K = ca.blockcat([[ca.MX(ca.DM(model.M)), A.T], [A, ca.MX(m, m)]])
    z = ca.solve(K, ca.vertcat(model.functions["F"](t, q, v, u, p), system.gamma_t(q, v, t)), "qr")
    return ca.Function("rolling_kkt", [t, q, v, u, p], [z[:nq], z[nq:]], ["t", "q", "v", "u", "p"], ["a", "lam"])
