"""Checks of a solved NLP: rank of the equality constraints, derivatives IPOPT used.

* :func:`equality_rank` — the Jacobian of the equality constraints at the solution must
  have full row rank (LICQ for the equalities); :mod:`ncgen.optim.nlp` explains why the
  transcription keeps it so.  Dense SVD: meant for small problems and tests.
* :func:`derivative_check` — IPOPT's own derivative functions (``nlp_grad_f``,
  ``nlp_jac_g`` of the CasADi solver, i.e. after simple bounds were detected) against
  central finite differences of the objective and constraints.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np


@dataclass
class RankReport:
    """``rank`` of the ``n_equalities × n_variables`` equality Jacobian; ``singular_values``
    (descending); ``groups``: labels of the equality groups, in row order."""

    rank: int
    n_equalities: int
    n_variables: int
    singular_values: np.ndarray
    groups: list[str]

    @property
    def full_rank(self) -> bool:
        return self.rank == self.n_equalities

    @property
    def condition(self) -> float:
        s = self.singular_values
        return float(s[0] / s[-1]) if s.size and s[-1] > 0 else np.inf


def equality_rank(result, rtol: float = 1e-10) -> RankReport:
    """Rank of the Jacobian of the equality constraints of ``result.nlp`` at the solution."""
    nlp = result.nlp
    rows, labels = [], []
    for g in nlp.groups:
        if np.array_equal(g.lb, g.ub):
            rows.append(g.expr)
            labels.append(g.label)
    opti = nlp.opti
    G = ca.vertcat(*rows)
    J = ca.Function("J", [opti.x], [ca.jacobian(G, opti.x)])
    Jv = np.array(J(nlp.x_opt))
    s = np.linalg.svd(Jv, compute_uv=False)
    rank = int(np.sum(s > rtol * s[0])) if s.size else 0
    return RankReport(rank, Jv.shape[0], Jv.shape[1], s, labels)


@dataclass
class DerivativeReport:
    """Largest relative errors of IPOPT's gradient and constraint Jacobian against central
    differences (relative to ``max(1, |derivative|)``)."""

    gradient_error: float
    jacobian_error: float
    n_variables: int
    n_constraints: int


def derivative_check(result, x=None, step: float = 1e-6, columns=None) -> DerivativeReport:
    """Compare IPOPT's derivatives with central differences at ``x`` (default the solution)
    over ``columns`` (default every variable)."""
    solver = result.nlp.opti.debug.casadi_solver
    grad_f = solver.get_function("nlp_grad_f")
    jac_g = solver.get_function("nlp_jac_g")
    x = np.array(result.nlp.x_opt if x is None else x, dtype=float)
    p = np.zeros(grad_f.size1_in(1))
    _, g_x = (np.array(a) for a in grad_f(x, p))
    _, J = jac_g(x, p)
    J = np.array(ca.densify(J))
    g_x = g_x.reshape(-1)
    cols = range(x.size) if columns is None else columns
    err_g, err_J = 0.0, 0.0
    for i in cols:
        e = np.zeros_like(x)
        e[i] = step * max(1.0, abs(x[i]))
        f_p, f_m = float(grad_f(x + e, p)[0]), float(grad_f(x - e, p)[0])
        c_p = np.array(jac_g(x + e, p)[0]).reshape(-1)
        c_m = np.array(jac_g(x - e, p)[0]).reshape(-1)
        h = 2 * e[i]
        err_g = max(err_g, abs((f_p - f_m) / h - g_x[i]) / max(1.0, abs(g_x[i])))
        if c_p.size:
            err_J = max(err_J, float(np.max(np.abs((c_p - c_m) / h - J[:, i]) / np.maximum(1.0, np.abs(J[:, i])))))
    return DerivativeReport(err_g, err_J, x.size, J.shape[0])
