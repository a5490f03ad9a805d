"""Direct collocation at Legendre–Gauss–Radau points (Radau IIA), the default transcription.

On interval ``k`` the state ``x = [q; v]`` is the polynomial of degree ``d`` through the
node ``x_k`` (τ = 0) and the collocation states ``x_{k,j}`` at the Radau points
``0 < τ_1 < … < τ_d = 1``.  At every collocation point the index-1 DAE of the model
(:mod:`ncgen.assembly.functions`, Baumgarte terms included) holds:

    Σ_r C_rj x_{k,r} = h [v_{k,j}; a_{k,j}],
    M a_{k,j} + Aᵀ λ_{k,j} = F,   A a_{k,j} = γ − 2α Φ̇ − β² Φ,

with ``C_rj = ℓ_r'(τ_j)`` the derivatives of the Lagrange basis.  The accelerations and
multipliers are unknowns at every collocation point, defined by the equations of motion in
KKT form, ``M a + Aᵀ λ = F`` and ``A a = γ − 2α Φ̇ − β² Φ`` (the index-1 DAE of
:mod:`ncgen.assembly.functions` without forming ``M⁻¹``: sparser rows, and no ``1/m``
amplification for light members).  Since τ_d = 1 the last
collocation state is the next node (``x_{k+1} = x_{k,d}``: no separate continuity
constraint) and the multipliers at nodes 1..N are collocation unknowns.

Why Radau: order ``2d − 1`` at the nodes (5 for the default ``d = 3``), stiffly accurate
and L-stable (stiff springs, large Baumgarte gains), and the algebraic equations are
enforced at the interval ends, so every node is a consistent DAE state; inputs piecewise
constant per interval, as in multiple shooting.  The Jacobian of one interval's
collocation and algebraic equations with respect to its own unknowns ``(x_{k,j}, λ_{k,j})``
``(x_{k,j}, a_{k,j}, λ_{k,j})`` couples ``C ⊗ I`` with the KKT block ``[[M, Aᵀ], [A, 0]]``:
nonsingular for small ``h`` when ``A`` has full rank, so the dynamics rows never cost the
NLP rank.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.optim.transcription import Discretisation, Horizon, Transcription, guess_times, node_times


def radau_coefficients(d: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(tau, C, b)``: points ``[0, τ_1..τ_d]``, derivative matrix ``C`` ((d+1) × d,
    ``C[r, j] = ℓ_r'(τ_{j+1})``) and quadrature weights ``b`` on ``τ_1..τ_d`` (sum 1)."""
    tau = np.array([0.0] + list(ca.collocation_points(d, "radau")))
    C = np.zeros((d + 1, d))
    for r in range(d + 1):
        others = np.delete(tau, r)
        ell = np.poly1d(np.poly(others)) / np.prod(tau[r] - others)
        C[r] = np.polyder(ell)(tau[1:])
    b = np.zeros(d)
    for j in range(d):
        others = np.delete(tau[1:], j)
        ell = np.poly1d(np.poly(others)) / np.prod(tau[1 + j] - others)
        P = np.polyint(ell)
        b[j] = P(1.0) - P(0.0)
    return tau, C, b


class RadauCollocation(Transcription):
    """Radau IIA collocation of degree ``degree`` (1 = implicit Euler, 3 = default)."""

    def __init__(self, degree: int = 3):
        if not isinstance(degree, int) or not 1 <= degree <= 9:
            raise ValueError(f"collocation degree: expected an integer 1..9, got {degree!r}")
        self.degree = degree

    def describe(self) -> str:
        return f"Radau IIA collocation, degree {self.degree}"

    def build(self, opti: ca.Opti, model, hz: Horizon) -> Discretisation:
        d, N, nq, nc, nu = self.degree, hz.N, model.nq, model.nc, model.nu
        tau, C, b = radau_coefficients(d)
        Q = opti.variable(nq, N * d)
        V = opti.variable(nq, N * d)
        Acc = opti.variable(nq, N * d)
        L = opti.variable(nc, N * d)
        U = opti.variable(nu, N)
        h = hz.T / N
        t = node_times(hz, tau[1:])
        Urep = ca.reshape(ca.repmat(U, d, 1), nu, N * d)   # column k·d + j holds u_k
        eom, alg = kkt_residuals(model).map(N * d)(t, Q, V, Acc, L, Urep, hz.p)
        X = ca.vertcat(Q, V)
        Xdot = ca.vertcat(V, Acc)
        x_start = ca.vertcat(hz.q0, hz.v0)
        defects = []
        Cm = ca.DM(C)
        for k in range(N):
            cols = slice(k * d, (k + 1) * d)
            Xk = ca.horzcat(x_start, X[:, cols])
            res = ca.mtimes(Xk, Cm) - h * Xdot[:, cols]
            defects.append((f"dynamics (collocation, interval {k})", ca.vec(res)))
            x_start = X[:, k * d + d - 1]
        defects.append(("dynamics (equations of motion M a + Aᵀλ = F)", ca.vec(eom)))
        defects.append(("dynamics (acceleration constraints, Baumgarte)", ca.vec(alg)))
        last = list(range(d - 1, N * d, d))
        q_nodes = ca.horzcat(hz.q0, Q[:, last])
        v_nodes = ca.horzcat(hz.v0, V[:, last])
        w = ca.repmat(ca.DM(b).T, 1, N) * h

        def set_guess(o: ca.Opti, g):
            tg = guess_times(hz, g.T, tau[1:])
            o.set_initial(Q, g.q(tg).T)
            o.set_initial(V, g.v(tg).T)
            o.set_initial(Acc, g.a(tg).T)
            if nc:
                o.set_initial(L, g.lam(tg).T)
            if nu:
                o.set_initial(U, g.u(guess_times(hz, g.T, [0.0])).T)

        return Discretisation(q=q_nodes, v=v_nodes, lam=L[:, last], U=U, path_t=t, path_q=Q, path_v=V,
                              quad_t=t, quad_q=Q, quad_v=V, quad_w=w, defects=defects,
                              set_guess=set_guess, expandable=True)


def kkt_residuals(model) -> ca.Function:
    """``(t, q, v, a, λ, u, p) -> (M a + Aᵀ λ − F, A a − γ + 2α Φ̇ + β² Φ)``: the equations of
    motion and the Baumgarte-stabilised acceleration constraints, with the accelerations
    and multipliers as unknowns (no M⁻¹, so the rows stay sparse and well scaled)."""
    f = model.functions
    alpha, beta = model.baumgarte
    nq, nc, nu, npar = model.nq, model.nc, model.nu, model.np
    t, q, v, a = ca.SX.sym("t"), ca.SX.sym("q", nq), ca.SX.sym("v", nq), ca.SX.sym("a", nq)
    lam, u, p = ca.SX.sym("lam", nc), ca.SX.sym("u", nu), ca.SX.sym("p", npar)
    A = f["A"](t, q, p)
    phidot = ca.mtimes(A, v) + f["phi_t"](t, q, p)
    eom = ca.mtimes(ca.DM(model.M), a) + ca.mtimes(A.T, lam) - f["F"](t, q, v, u, p)
    acc = ca.mtimes(A, a) - f["gamma"](t, q, v, p) + 2 * alpha * phidot + beta ** 2 * f["phi"](t, q, p)
    return ca.Function("kkt_residuals", [t, q, v, a, lam, u, p], [eom, acc],
                       ["t", "q", "v", "a", "lam", "u", "p"], ["eom", "acc"])
