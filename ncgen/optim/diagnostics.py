"""Diagnoses of a failed solve, and checks of a solved NLP.

* :func:`diagnose` — the message of a failed solve: IPOPT's status and, when a relaxed
  re-solve (elastic mode, bounded by a wall-clock budget) can tell, the condition that
  conflicts; otherwise it says it does not know and lists the largest violations at the
  last iterate as symptoms.

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

from ncgen.errors import OptimizationError

#: Constraint kinds relaxed by slacks when diagnosing a failure: the wishes (conditions and
#: path constraints), never the physics (dynamics, invariants) or the bounds.
RELAXABLE = ("initial", "final", "periodic", "path")
#: Default wall-clock budget (s) of the relaxed re-solve that names a conflicting condition.
DIAGNOSIS_BUDGET = 10.0

#: Iteration limit of that re-solve.
DIAGNOSIS_MAX_ITER = 300

SUCCESS = ("Solve_Succeeded", "Solved_To_Acceptable_Level")

HINTS = {"final": "check that the final conditions are reachable within the horizon and the bounds",
         "initial": "check that the initial conditions agree with the joints",
         "periodic": "check that a periodic motion exists within the bounds",
         "path": "the path constraint may contradict the initial or final conditions"}


def diagnose(nlp, value, result, *, tol: float, ipopt: dict, budget: float = DIAGNOSIS_BUDGET,
             linear_solver: str = "mumps") -> str:
    """A message naming IPOPT's status and, if it can be found, the condition that conflicts.

    The conflict is found in elastic mode: the problem is solved again from the last
    iterate with every condition and path constraint relaxed by slacks whose sum is
    minimised, dynamics, invariants and bounds kept, within ``budget`` seconds of wall
    time (0 or ``None``: not at all).  The conditions the nearest feasible motion still
    misses are the ones that cannot be met (with the inputs on their bounds, if any are
    saturated).  If the re-solve is skipped, fails or runs out of time, the message says
    that the cause is unknown and lists the largest violations at the last iterate."""
    status = result.stats.status
    lines = [f"IPOPT did not solve the problem: {status} after {result.stats.iterations} iterations."]
    if status == "Infeasible_Problem_Detected":
        lines.append("The constraints look infeasible (IPOPT converged to a point of minimal violation).")
    misses, why = elastic_misses(nlp, result, tol=tol, ipopt=ipopt, budget=budget, linear_solver=linear_solver)
    saturated = saturated_inputs(nlp, result)
    if misses:
        lines.append("With the conditions relaxed (dynamics and bounds kept), the nearest feasible motion misses "
                     + "; ".join(f"{label} by {miss:.3g}" for label, miss in misses[:3]) + ".")
        kind = next(g.kind for g in nlp.groups if g.label.split(" (")[0] == misses[0][0])
        conflict = misses[0][0] + (f" against the bounds on {', '.join(saturated)}" if saturated else "")
        lines.append(f"Likely culprit: {conflict} — {HINTS.get(kind, 'loosen it')}.")
    else:
        if why == "feasible":
            lines.append("Every condition can be met with the dynamics and bounds (a relaxed re-solve met them), "
                         "so this is a convergence failure, not a conflict.")
        else:
            lines.append(f"Which condition conflicts is not known ({why}).")
        ranked = sorted(((violation_of(value, g), g) for g in nlp.groups), key=lambda x: -x[0])
        worst = [(v, g) for v, g in ranked if v > 1e-6][:3]
        if worst:
            lines.append("Largest violations at the last iterate (symptoms, not necessarily the cause): " +
                         "; ".join(f"{g.label} ({v:.3g})" for v, g in worst) + ".")
    if saturated:
        lines.append("Inputs on their bounds in most intervals: " + ", ".join(saturated) + ".")
    if status == "Maximum_Iterations_Exceeded" and not misses:
        lines.append("Raise max_iter, warm start from a simulation or an easier problem's solution, or try "
                     "solve(coarse_start=True).")
    return "\n".join(lines)


def elastic_misses(nlp, result, *, tol: float, ipopt: dict, budget, linear_solver: str = "mumps"):
    """``([(label, largest slack)], why)``: the conditions the elastic problem cannot meet,
    largest first, and why the list is empty (``"feasible"``, or the reason the re-solve
    gave no answer)."""
    if not budget:
        return [], "the relaxed re-solve is off: solve(diagnose=seconds) turns it on"
    if not any(g.kind in RELAXABLE for g in nlp.groups):
        return [], "there are no conditions to relax"
    elastic = type(nlp)(nlp.ocp, elastic=True)      # the same NLP with its conditions relaxed
    try:
        elastic.build(result)
        value = elastic.solve(max_iter=DIAGNOSIS_MAX_ITER, tol=max(tol, 1e-8), verbose=False, ipopt=ipopt,
                              linear_solver=linear_solver, max_wall_time=float(budget))
    except (OptimizationError, RuntimeError) as exc:
        return [], f"the relaxed re-solve failed: {exc}"
    status = elastic.opti.stats().get("return_status")
    if status not in SUCCESS:
        return [], f"the relaxed re-solve ended with {status} within its budget of {float(budget):g} s"
    threshold = max(1e-6, 100 * tol)
    misses: dict[str, float] = {}
    for label, s in elastic.slacks.items():          # "final q (tangent components)" -> "final q"
        name = label.split(" (")[0]
        misses[name] = max(misses.get(name, 0.0), float(np.max(np.array(value(s)), initial=0.0)))
    out = sorted([(name, m) for name, m in misses.items() if m > threshold], key=lambda x: -x[1])
    return out, "feasible"


def violation_of(value, g) -> float:
    """Largest violation of the constraint group ``g`` where ``value`` evaluates."""
    x = np.array(value(g.expr)).reshape(-1)
    return float(np.max(np.maximum(g.lb - x, 0) + np.maximum(x - g.ub, 0), initial=0.0))


def saturated_inputs(nlp, result) -> list[str]:
    """Input components on a bound in more than half of the intervals."""
    ocp, out = nlp.ocp, []
    names = [n if s == 1 else f"{n}[{k}]" for n, s in zip(nlp.model.input_names, nlp.model.input_sizes)
             for k in range(s)]
    for i, name in enumerate(names):
        lo, hi = ocp.u_bounds[:, i]
        u = result.u[:-1, i]
        span = max(hi - lo, 1.0) if np.isfinite(hi - lo) else 1.0
        at = (np.abs(u - lo) < 1e-3 * span) | (np.abs(u - hi) < 1e-3 * span)
        if at.mean() > 0.5:
            out.append(name)
    return out


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
