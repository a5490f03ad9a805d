"""``optimize_prestress``: the best member forces at a given shape, with CasADi and IPOPT.

The forces are those of :func:`~ncgen.analysis.inverse_statics.inverse_statics`,
``t = t_p + T α`` (``α``: the amplitudes of the states of self-stress), within the same bounds
``B t ≤ b`` (cable tensions in ``[cable_min, cable_max]``, strut compressions ≤ ``strut_max``,
capstan friction at pulleys).  Two objectives:

* ``"stiffness"``: maximise the smallest eigenvalue ``μ`` of the mechanisms' stiffness
  ``Q(t) = Mᵀ K_G(t) M`` (N/m, :mod:`ncgen.analysis.self_stress`), posed smoothly as
  ``max μ`` subject to ``Q(t) − μ I = L Lᵀ`` (``L`` lower triangular); ``Q`` is linear in
  ``t``, so ``cable_max`` (or ``strut_max``) must bound the prestress;
* ``"max_cable"``: minimise the largest cable tension ``z`` subject to ``t_c ≤ z`` (a linear
  programme; with ``cable_min`` > 0 it is the most even prestress).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ncgen.blas_threads import one_blas_thread
from ncgen.errors import NcgenError
from ncgen.analysis.inverse_statics import InverseStatics, least_norm, problem
from ncgen.analysis.self_stress import RANK_TOL

OBJECTIVES = ("stiffness", "max_cable")


@dataclass
class PrestressDesign(InverseStatics):
    """Result of :func:`optimize_prestress`: an :class:`InverseStatics` with the
    ``objective``, the smallest mechanism stiffness ``min_stiffness`` (N/m; ``nan`` without
    mechanisms), the largest cable tension ``max_cable`` (N), IPOPT's ``iterations`` and the
    ``solve_time`` (s, wall clock)."""

    objective: str = ""
    min_stiffness: float = float("nan")
    max_cable: float = float("nan")
    iterations: int = 0
    solve_time: float = 0.0


def _smallest_stiffness(pr, alpha, t, start: np.ndarray) -> tuple:
    """``(g, lbg, ubg, x, f, x0)`` of the objective ``"stiffness"``: the smallest eigenvalue
    ``μ`` of the prestress stiffness ``Q(α)`` on the mechanisms maximised, ``Q − μ I = L Lᵀ``
    with ``L`` lower triangular as equality constraints (``t``, the member forces, unused);
    started from the forces ``start`` with ``μ₀`` just below ``Q``'s smallest eigenvalue there."""
    import casadi as ca

    an, n_s = pr.analysis, pr.T.shape[1]
    nm = an.mechanisms.shape[1]
    Qs = [an.prestress_stiffness(pr.t_p)] + [an.prestress_stiffness(pr.T[:, i]) for i in range(n_s)]
    Q = ca.DM(Qs[0]) + sum((alpha[i] * ca.DM(Qs[1 + i]) for i in range(n_s)), ca.DM.zeros(nm, nm))
    low = [(i, j) for i in range(nm) for j in range(i + 1)]
    mu, ell = ca.MX.sym("mu"), ca.MX.sym("L", len(low))
    L = ca.MX.zeros(nm, nm)
    for k, (i, j) in enumerate(low):
        L[i, j] = ell[k]
    R = Q - mu * ca.DM.eye(nm) - ca.mtimes(L, L.T)
    Q0 = Qs[0] + sum(a * Qi for a, Qi in zip(start, Qs[1:]))
    mu0 = float(np.linalg.eigvalsh(Q0)[0]) - 1e-3 * max(1.0, float(np.abs(Q0).max()))
    L0 = np.linalg.cholesky(Q0 - mu0 * np.eye(nm))
    return (ca.vertcat(*[R[i, j] for i, j in low]), [0.0] * len(low), [0.0] * len(low), ca.vertcat(alpha, mu, ell),
            -mu, np.concatenate([start, [mu0], [L0[i, j] for i, j in low]]))


def _largest_cable_force(pr, alpha, t, start: np.ndarray) -> tuple:
    """``(g, lbg, ubg, x, f, x0)`` of the objective ``"max_cable"``: the largest cable force
    ``z`` minimised, ``t_cables ≤ z`` as constraints, started from the forces ``start``."""
    import casadi as ca

    nc = len(pr.framework.cables)
    z = ca.MX.sym("z")
    return (t[:nc] - z, [-np.inf] * nc, [0.0] * nc, ca.vertcat(alpha, z), z,
            np.concatenate([start, [float((pr.forces(start)[:nc]).max(initial=0.0))]]))


@one_blas_thread
def optimize_prestress(nodes, struts, cables, loads=None, supports=None, *, objective: str = "stiffness",
                       cable_min: float = 0.0, cable_max: float | None = None, strut_max: float | None = None,
                       clusters=None, friction=None, turns=None, bodies=None, tol: float = RANK_TOL,
                       ipopt_options: dict | None = None) -> PrestressDesign:
    """The member forces at the shape ``nodes`` under ``loads`` that are best for
    ``objective`` (module docstring); the other arguments as for
    :func:`~ncgen.analysis.inverse_statics.inverse_statics`."""
    import casadi as ca

    who = "optimize_prestress"
    if objective not in OBJECTIVES:
        raise NcgenError(f"{who}: objective: expected one of {', '.join(map(repr, OBJECTIVES))}, got {objective!r}")
    if objective == "stiffness" and cable_max is None and strut_max is None:
        raise NcgenError(f"{who}: objective 'stiffness' grows without bound with the prestress: give cable_max "
                         "or strut_max (N)")
    t0 = time.perf_counter()
    pr = problem(nodes, struts, cables, loads, supports, cable_min=cable_min, cable_max=cable_max,
                 strut_max=strut_max, clusters=clusters, friction=friction, turns=turns, bodies=bodies,
                 tol=tol, who=who)
    an, fw = pr.analysis, pr.framework
    n_s, nc = pr.T.shape[1], len(fw.cables)
    M = an.mechanisms
    if objective == "stiffness" and M.shape[1] == 0:
        raise NcgenError(f"{who}: objective 'stiffness': this configuration has no infinitesimal mechanism "
                         "(its stiffness does not depend on the prestress); use objective='max_cable'")
    if n_s == 0:
        raise NcgenError(f"{who}: the forces are unique (no state of self-stress): nothing to optimise; use "
                         "inverse_statics")
    alpha = ca.MX.sym("alpha", n_s)
    t = ca.DM(pr.t_p) + ca.mtimes(ca.DM(pr.T), alpha)
    g = [ca.mtimes(ca.DM(pr.B), t) - ca.DM(pr.b)]
    lbg, ubg = [-np.inf] * len(pr.b), [0.0] * len(pr.b)
    start = least_norm(pr, who)                    # inside the bounds
    objective_terms = _smallest_stiffness if objective == "stiffness" else _largest_cable_force
    g_o, lbg_o, ubg_o, x, f, x0 = objective_terms(pr, alpha, t, start)
    g.append(g_o)
    lbg += lbg_o
    ubg += ubg_o
    opts = {"print_time": False, "ipopt": {"print_level": 0, "sb": "yes", "tol": 1e-10,
                                           "bound_relax_factor": 0.0,
                                           **(ipopt_options or {})}}
    solver = ca.nlpsol(who, "ipopt", {"x": x, "f": f, "g": ca.vertcat(*g)}, opts)
    sol = solver(x0=x0, lbg=np.array(lbg), ubg=np.array(ubg))
    stats = solver.stats()
    if not stats["success"]:
        raise NcgenError(f"{who}: IPOPT did not converge ({stats['return_status']}); check that the bounds "
                         "admit forces (inverse_statics with the same bounds) and loosen them")
    a = np.array(sol["x"]).reshape(-1)[:n_s]
    forces = pr.forces(a)
    ev = np.linalg.eigvalsh(an.prestress_stiffness(forces)) if M.shape[1] else np.zeros(0)
    return pr.result(a, cls=PrestressDesign, objective=objective,
                     min_stiffness=float(ev[0]) if ev.size else float("nan"),
                     max_cable=float(forces[:nc].max()) if nc else float("nan"), iterations=int(stats["iter_count"]),
                     solve_time=time.perf_counter() - t0)
