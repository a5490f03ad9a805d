"""Multiple shooting: one integrator call per interval, continuity of the node states.

Decision variables are the node states ``x_k = [q_k; v_k]`` (k = 1..N; node 0 belongs to
the builder) and the inputs ``u_k``; the constraints are ``x_{k+1} = Ψ(x_k, u_k, p, t_k, h)``
where ``Ψ`` integrates the model's index-1 DAE over one interval.  The invariants
``Φ = 0``, ``A v + Φ_t = 0`` are imposed at node 0 only (the builder does it): the
integrator keeps them, to its tolerance, along the whole horizon.

Integrators are pluggable: :func:`register_integrator` adds a factory
``factory(model, **options) -> casadi.Function`` whose function maps
``(x0[2nq], u[nu], p[np], t0, h) -> (xf[2nq], lamf[nc])`` (one interval of length ``h``
seconds from time ``t0``, inputs constant, ``lamf`` the multipliers at the end).  IDAS is
built in, and so is ``"rattle"``: the scheme of the compiled fixed-step stepper
(``ncgen.assembly.stepper_equations``) written with CasADi's rootfinder, because IPOPT needs
derivatives and the generated C stepper has none.  A factory for the C stepper itself
would need its step's Jacobians (a ``casadi.external`` with ``jac_`` functions).
"""
from __future__ import annotations

from typing import Callable

import casadi as ca
import numpy as np

from ncgen.errors import OptimizationError
from ncgen.optim.transcription import Discretisation, Horizon, Transcription, guess_times, node_times

INTEGRATORS: dict[str, Callable] = {}

#: IDAS tolerances used for shooting (relative, absolute): tight, because the shooting
#: defects and their sensitivities are only as accurate as the integration.
IDAS_TOLERANCES = (1e-10, 1e-10)


def register_integrator(name: str, factory: Callable) -> None:
    """Make ``OptimalControl(..., method="shooting", integrator=name)`` use ``factory``."""
    if not isinstance(name, str) or not name:
        raise ValueError(f"integrator name: expected a non-empty string, got {name!r}")
    INTEGRATORS[name] = factory


def idas_interval(model, *, rtol: float = IDAS_TOLERANCES[0], atol: float = IDAS_TOLERANCES[1],
                  **options) -> ca.Function:
    """IDAS on the model's index-1 DAE in KKT form (``functions["dae"]``: ``x = [q; v]``,
    ``z = [a; λ]``) over one interval, in the scaled time τ ∈ [0, 1] (``t = t0 + h τ``), so
    that ``h`` may be a decision variable (free final time)."""
    nq, nc, nu, npar = model.nq, model.nc, model.nu, model.np
    x = ca.SX.sym("x", 2 * nq)
    z = ca.SX.sym("z", nq + nc)
    u = ca.SX.sym("u", nu)
    p = ca.SX.sym("p", npar)
    t0, h, tau = ca.SX.sym("t0"), ca.SX.sym("h"), ca.SX.sym("tau")
    ode, alg = model.functions["dae"](t0 + h * tau, x, z, u, p)
    dae = {"x": x, "z": z, "p": ca.vertcat(u, p, t0, h), "t": tau, "ode": h * ode, "alg": alg}
    integ = ca.integrator("interval", "idas", dae, 0.0, 1.0, {"reltol": rtol, "abstol": atol, **options})
    X0, U, P = ca.MX.sym("x0", 2 * nq), ca.MX.sym("u", nu), ca.MX.sym("p", npar)
    T0, H = ca.MX.sym("t0"), ca.MX.sym("h")
    res = integ(x0=X0, p=ca.vertcat(U, P, T0, H))
    return ca.Function("interval", [X0, U, P, T0, H], [res["xf"], res["zf"][nq:]],
                       ["x0", "u", "p", "t0", "h"], ["xf", "lamf"])


def rattle_interval(model, *, substeps: int = 4, tol: float = 1e-12, max_iter: int = 20) -> ca.Function:
    """The compiled stepper's scheme (RATTLE, :mod:`ncgen.assembly.stepper_equations`) over one
    interval: ``substeps`` fixed steps of ``h / substeps``, each a Newton solve of the
    first half-step (CasADi ``rootfinder``, derivatives by the implicit function theorem)
    and the linear KKT solve of the second.  The same equations as the generated C stepper,
    differentiable for IPOPT; both constraint levels hold at every node."""
    from ncgen.assembly.stepper_equations import stepper_functions

    if not isinstance(substeps, int) or substeps < 1:
        raise OptimizationError(f"rattle: substeps: expected a positive integer, got {substeps!r}")
    newton, velocity = stepper_functions(model)[:2]
    nq, nc, nu, npar = model.nq, model.nc, model.nu, model.np
    x = ca.SX.sym("x", nq + nc)
    t, h = ca.SX.sym("t"), ca.SX.sym("h")
    q, v, u, p = ca.SX.sym("q", nq), ca.SX.sym("v", nq), ca.SX.sym("u", nu), ca.SX.sym("p", npar)
    args = ca.vertcat(t, q, v, u, p, h)
    residual = ca.Function("residual", [x, args], [newton(t, q, v, u, p, h, x[:nq], x[nq:])[0]])
    half_step = ca.rootfinder("rattle_half_step", "newton", residual, {"abstol": tol, "max_iter": max_iter})
    X0, U, P = ca.MX.sym("x0", 2 * nq), ca.MX.sym("u", nu), ca.MX.sym("p", npar)
    T0, H = ca.MX.sym("t0"), ca.MX.sym("h")
    hs = H / substeps
    qk, vk, lam = X0[:nq], X0[nq:], ca.MX(nc, 1)
    for k in range(substeps):
        tk = T0 + k * hs
        w = half_step(ca.vertcat(vk, ca.MX(nc, 1)), ca.vertcat(tk, qk, vk, U, P, hs))[:nq]
        qk = qk + hs * w
        b, K = velocity(tk + hs, qk, w, U, P, hs)
        y = ca.solve(K, b, "qr")
        vk, lam = y[:nq], 2 * y[nq:] / hs
    return ca.Function("interval", [X0, U, P, T0, H], [ca.vertcat(qk, vk), lam],
                       ["x0", "u", "p", "t0", "h"], ["xf", "lamf"])


register_integrator("idas", idas_interval)
register_integrator("rattle", rattle_interval)


class MultipleShooting(Transcription):
    """Multiple shooting with a registered integrator (default ``"idas"``).  The NLP is
    solved with a limited-memory Hessian: exact second-order integrator sensitivities cost
    more than they save."""

    hessian = "limited-memory"

    def __init__(self, integrator: str = "idas", **options):
        if integrator not in INTEGRATORS:
            raise OptimizationError(f"integrator {integrator!r} is not available; registered: "
                                    f"{', '.join(sorted(INTEGRATORS))}")
        self.integrator = integrator
        self.options = options

    def describe(self) -> str:
        return f"multiple shooting ({self.integrator})"

    def build(self, opti: ca.Opti, model, hz: Horizon) -> Discretisation:
        N, nq, nu = hz.N, model.nq, model.nu
        try:
            step = INTEGRATORS[self.integrator](model, **self.options)
        except (TypeError, RuntimeError) as exc:
            raise OptimizationError(f"integrator {self.integrator!r} with options {self.options}: {exc}") from None
        Q = opti.variable(nq, N)
        V = opti.variable(nq, N)
        U = opti.variable(nu, N)
        h = hz.T / N
        t_start = node_times(hz, [0.0])
        q = ca.horzcat(hz.q0, Q)
        v = ca.horzcat(hz.v0, V)
        xf, lamf = step.map(N)(ca.vertcat(q[:, :N], v[:, :N]), U, hz.p, t_start, h)
        defects = [("dynamics (shooting continuity)", ca.vec(ca.vertcat(Q, V) - xf))]
        w = np.full(N + 1, 1.0)
        w[[0, -1]] = 0.5
        t_nodes = hz.t0 + hz.T * ca.DM(np.arange(N + 1) / N).T

        def set_guess(o: ca.Opti, g):
            tg = guess_times(hz, g.T, [1.0])
            o.set_initial(Q, g.q(tg).T)
            o.set_initial(V, g.v(tg).T)
            if nu:
                o.set_initial(U, g.u(guess_times(hz, g.T, [0.0])).T)

        return Discretisation(q=q, v=v, lam=lamf, U=U, path_t=t_nodes[:, 1:], path_q=Q, path_v=V,
                              quad_t=t_nodes, quad_q=q, quad_v=v, quad_w=h * ca.DM(w).T, defects=defects,
                              set_guess=set_guess, expandable=False)
