"""Direct collocation at Legendre–Gauss–Radau points (Radau IIA), the default transcription.

On interval ``k`` the coordinates ``q`` are the polynomial of degree ``d`` through the node
``q_k`` (τ = 0) and the collocation values ``q_{k,j}`` at the Radau points
``0 < τ_1 < … < τ_d = 1``; the velocities are its derivative there and the velocity
polynomial through ``v_k`` and ``v_{k,j}`` is collocated in turn:

    v_{k,j} = (1/h) Σ_r C_rj q_{k,r},     M (1/h) Σ_r C_rj v_{k,r} + Aᵀ λ_{k,j} = F,

with ``C_rj = ℓ_r'(τ_j)`` the derivatives of the Lagrange basis.  Two forms of the
constraints (``form``):

* ``"index3"`` (default): ``Φ(q_{k,j}) = 0`` at every collocation point — Radau IIA on the
  index-3 equations of motion (Hairer & Wanner, *Solving ODEs II*, VII.4).  The unknowns
  are ``q_{k,j}`` and ``λ_{k,j}`` only (``v`` and ``q̈`` are expressions of them), so one
  collocation point carries ``nq + nc`` unknowns and as many equations; the positions
  satisfy the joints exactly at every point (no drift for the optimiser to exploit), the
  velocity invariant ``A v = 0`` to the order of the method.
* ``"index1"``: the index-1 DAE with Baumgarte terms, ``A q̈ = γ − 2α Φ̇ − β² Φ``, and
  ``v``, ``q̈`` as unknowns: ``3 nq + nc`` unknowns per point.  The positions drift off
  ``Φ = 0`` between the nodes' exact start and the end (measured on the benchmark 3D arm at
  N = 10: max |Φ| = 0.08 m², and the optimum exploited it); kept for comparison.

Either way the equations of one interval are square in its own unknowns, with Jacobian
``C ⊗ I`` coupled to the KKT block ``[[M, Aᵀ], [A, 0]]`` (index 1) or to ``[[M/h², Aᵀ],
[A, 0]]`` (index 3): nonsingular for small ``h`` when ``A`` has full rank, so the dynamics
rows never cost the NLP rank.

Why Radau: order ``2d − 1`` at the nodes (5 for the default ``d = 3``) for the positions,
stiffly accurate and L-stable (stiff springs), the constraints enforced at the interval
ends, so every node is a consistent state.  Since τ_d = 1 the last collocation value is the
next node (no separate continuity constraint); the multipliers at nodes 1..N are
collocation unknowns.  Inputs piecewise constant per interval, as in multiple shooting.
"""
from __future__ import annotations

from typing import NamedTuple

import casadi as ca
import numpy as np

from ncgen.optim.transcription import Discretisation, Horizon, Transcription, guess_times, node_times

#: The constraint forms (see the module docstring).
FORMS = ("ggl", "index3", "index1")


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
    """Radau IIA collocation of degree ``degree`` (1 = implicit Euler, 3 = default) on the
    ``form`` of the constraints (``"index3"``, default, or ``"index1"``)."""

    def __init__(self, degree: int = 3, form: str = "ggl"):
        if not isinstance(degree, int) or not 1 <= degree <= 9:
            raise ValueError(f"collocation degree: expected an integer 1..9, got {degree!r}")
        if form not in FORMS:
            raise ValueError(f"collocation form: expected one of {', '.join(FORMS)}, got {form!r}")
        self.degree = degree
        self.form = form

    def describe(self) -> str:
        return f"Radau IIA collocation, degree {self.degree}, {self.form.replace('index', 'index-')} form"

    def build(self, opti: ca.Opti, model, hz: Horizon) -> Discretisation:
        d, N, nq, nc, nu = self.degree, hz.N, model.nq, model.nc, model.nu
        tau, C, b = radau_coefficients(d)
        h = hz.T / N
        t = node_times(hz, tau[1:])
        Q = opti.variable(nq, N * d)
        L = opti.variable(nc, N * d)
        U = opti.variable(nu, N)
        Urep = ca.reshape(ca.repmat(U, d, 1), nu, N * d)   # column k·d + j holds u_k
        points = _Points(t=t, Q=Q, L=L, Urep=Urep, C=ca.DM(C), h=h, d=d)
        if self.form in ("index3", "ggl"):
            (V, Mu, defects), Acc = self._second_order(opti, model, hz, points), None
        else:
            (V, Acc, defects), Mu = self._first_order(opti, model, hz, points), None
        last = list(range(d - 1, N * d, d))
        q_nodes = ca.horzcat(hz.q0, Q[:, last])
        v_nodes = ca.horzcat(hz.v0, V[:, last])
        w = ca.repmat(ca.DM(b).T, 1, N) * h

        def set_guess(o: ca.Opti, g):
            tg = guess_times(hz, g.T, tau[1:])
            o.set_initial(Q, g.q(tg).T)
            if Acc is not None:
                o.set_initial(V, g.v(tg).T)
                o.set_initial(Acc, g.a(tg).T)
            if nc:
                o.set_initial(L, g.lam(tg).T)
            if Mu is not None:
                o.set_initial(Mu, 0)
            if nu:
                o.set_initial(U, g.u(guess_times(hz, g.T, [0.0])).T)

        return Discretisation(q=q_nodes, v=v_nodes, lam=L[:, last], U=U, path_t=t, path_q=Q, path_v=V,
                              quad_t=t, quad_q=Q, quad_v=V, quad_w=w, defects=defects,
                              set_guess=set_guess, expandable=True)

    def _second_order(self, opti: ca.Opti, model, hz: Horizon, x: "_Points"):
        """The index-3 and GGL forms: positions collocated, ``v = q̇`` (GGL: ``q̇ − Aᵀμ``, with
        multipliers ``μ``), ``M q̈ + Aᵀλ = F`` and ``Φ = 0`` (GGL: also ``A v + Φ_t = 0``) at
        the collocation points; ``(V, μ or None, defects)``."""
        N, d, Cm, h = hz.N, x.d, x.C, x.h
        Mu = opti.variable(model.nc, N * d) if self.form == "ggl" else None
        Qdot = []                                  # (1/h) Σ_r C_rj q_{k,r}
        q_start = hz.q0
        for k in range(N):
            Qdot.append(ca.mtimes(ca.horzcat(q_start, x.Q[:, k * d:(k + 1) * d]), Cm) / h)
            q_start = x.Q[:, k * d + d - 1]
        Qdot = ca.horzcat(*Qdot)
        V = Qdot if Mu is None else ggl_velocity(model).map(N * d)(x.t, x.Q, Qdot, Mu, hz.p)
        Vdot, v_start = [], hz.v0                  # Σ_r C_rj v_{k,r} = h q̈_{k,j}
        for k in range(N):
            Vk = V[:, k * d:(k + 1) * d]
            Vdot.append(ca.mtimes(ca.horzcat(v_start, Vk), Cm))
            v_start = Vk[:, d - 1]
        eom, con = kkt_residuals(model, "index3").map(N * d)(x.t, x.Q, V, ca.horzcat(*Vdot), x.L, x.Urep, hz.p, h)
        defects = [("dynamics (equations of motion M q̈ + Aᵀλ = F)", ca.vec(eom)),
                   ("dynamics (joints Φ(q) = 0 at the collocation points)", ca.vec(con))]
        if Mu is not None:
            vel = velocity_constraint(model).map(N * d)(x.t, x.Q, V, hz.p)
            defects.append(("dynamics (joint velocities A v + Φ_t = 0 at the collocation points)", ca.vec(vel)))
        return V, Mu, defects

    @staticmethod
    def _first_order(opti: ca.Opti, model, hz: Horizon, x: "_Points"):
        """The index-1 form: ``[q; v]`` collocated with the accelerations as unknowns, ``M a +
        Aᵀλ = F`` and the Baumgarte-stabilised acceleration constraints; ``(V, Acc, defects)``."""
        N, d, h = hz.N, x.d, x.h
        V = opti.variable(model.nq, N * d)
        Acc = opti.variable(model.nq, N * d)
        eom, con = kkt_residuals(model, "index1").map(N * d)(x.t, x.Q, V, Acc, x.L, x.Urep, hz.p, h)
        X, Xdot = ca.vertcat(x.Q, V), ca.vertcat(V, Acc)
        x_start = ca.vertcat(hz.q0, hz.v0)
        defects = []
        for k in range(N):
            cols = slice(k * d, (k + 1) * d)
            res = ca.mtimes(ca.horzcat(x_start, X[:, cols]), x.C) - h * Xdot[:, cols]
            defects.append((f"dynamics (collocation, interval {k})", ca.vec(res)))
            x_start = X[:, k * d + d - 1]
        defects.append(("dynamics (equations of motion M a + Aᵀλ = F)", ca.vec(eom)))
        defects.append(("dynamics (acceleration constraints, Baumgarte)", ca.vec(con)))
        return V, Acc, defects


class _Points(NamedTuple):
    """The collocation points' times ``t``, positions ``Q``, multipliers ``L``, inputs
    ``Urep`` (column k·d + j holds u_k), the collocation matrix ``C`` (DM), the step ``h``
    and the degree ``d``."""

    t: object
    Q: object
    L: object
    Urep: object
    C: object
    h: object
    d: int


def kkt_residuals(model, form: str = "index1") -> ca.Function:
    """``(t, q, v, a, λ, u, p, h) -> (eom, con)``: the equations of motion with the
    accelerations and multipliers as unknowns (no M⁻¹, so the rows stay sparse and well
    scaled) and the constraint rows.  ``"index1"``: ``eom = M a + Aᵀ λ − F``,
    ``con = A a − γ + 2α Φ̇ + β² Φ`` (Baumgarte); ``"index3"``: ``a`` is ``h q̈``,
    ``eom = M a / h + Aᵀ λ − F`` and ``con = Φ(q)``."""
    f = model.functions
    alpha, beta = model.baumgarte
    nq, nc, nu, npar = model.nq, model.nc, model.nu, model.np
    t, q, v, a = ca.SX.sym("t"), ca.SX.sym("q", nq), ca.SX.sym("v", nq), ca.SX.sym("a", nq)
    lam, u, p, h = ca.SX.sym("lam", nc), ca.SX.sym("u", nu), ca.SX.sym("p", npar), ca.SX.sym("h")
    A = f["A"](t, q, p)
    acc = a / h if form == "index3" else a
    eom = ca.mtimes(ca.DM(model.M), acc) + ca.mtimes(A.T, lam) - f["F"](t, q, v, u, p)
    if form == "index3":
        con = f["phi"](t, q, p)
    else:
        phidot = ca.mtimes(A, v) + f["phi_t"](t, q, p)
        con = ca.mtimes(A, a) - f["gamma"](t, q, v, p) + 2 * alpha * phidot + beta ** 2 * f["phi"](t, q, p)
    return ca.Function("kkt_residuals", [t, q, v, a, lam, u, p, h], [eom, con],
                       ["t", "q", "v", "a", "lam", "u", "p", "h"], ["eom", "con"])


def ggl_velocity(model) -> ca.Function:
    """``(t, q, q̇_c, μ, p) -> v = q̇_c − Aᵀ μ``: the velocity of the stabilised (GGL) form,
    ``q̇ = v + Aᵀ μ``, from the derivative ``q̇_c`` of the collocation polynomial."""
    f = model.functions
    t, q, qdot = ca.SX.sym("t"), ca.SX.sym("q", model.nq), ca.SX.sym("qdot", model.nq)
    mu, p = ca.SX.sym("mu", model.nc), ca.SX.sym("p", model.np)
    v = qdot - ca.mtimes(f["A"](t, q, p).T, mu)
    return ca.Function("ggl_velocity", [t, q, qdot, mu, p], [v], ["t", "q", "qdot", "mu", "p"], ["v"])


def velocity_constraint(model) -> ca.Function:
    """``(t, q, v, p) -> A(q) v + Φ_t``."""
    f = model.functions
    t, q, v, p = ca.SX.sym("t"), ca.SX.sym("q", model.nq), ca.SX.sym("v", model.nq), ca.SX.sym("p", model.np)
    return ca.Function("velocity_constraint", [t, q, v, p], [ca.mtimes(f["A"](t, q, p), v) + f["phi_t"](t, q, p)],
                       ["t", "q", "v", "p"], ["phidot"])
