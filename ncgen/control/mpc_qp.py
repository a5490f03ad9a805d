"""The QP solver of the MPC's SQP iteration (:mod:`ncgen.control.mpc`): its condensed QP
``min ½ δUᵀ H δU + gᵀ δU  s.t.  lba ≤ A δU ≤ uba, lbx ≤ δU ≤ ubx`` by a CasADi ``conic`` plugin.

* ``"qrqp"`` (default): CasADi's active-set solver, generated into C with the other functions
  (so ``nc.export_mpc`` writes it too);
* ``"qpoases"``: qpOASES (online active set, dense), from CasADi's own library in this
  process: Python only (CasADi cannot generate it into self-contained C; ``nc.export_mpc``
  writes ``qrqp`` and has no such option).  It solves the tensegrity tower's condensed QPs with the cables' pull rows
  (Hessian eigenvalues spread over 1e7), on which ``qrqp`` stops short.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.errors import OptimizationError

#: The plugins and their options (the iteration limit filled in from ``qp_max_iter``).
QP_SOLVERS = {
    "qrqp": lambda n: {"print_iter": False, "print_header": False, "print_info": False, "max_iter": n,
                       "error_on_fail": False},
    "qpoases": lambda n: {"printLevel": "none", "nWSR": n, "error_on_fail": False},
}
#: The plugins generated into C with the rest of the iteration.
GENERATED = ("qrqp",)


def check_qp_solver(qp_solver, who: str = "MPC") -> str:
    """``qp_solver`` checked against :data:`QP_SOLVERS` (and available in this CasADi)."""
    if not isinstance(qp_solver, str) or qp_solver not in QP_SOLVERS:
        raise OptimizationError(f"{who}: qp_solver: expected one of {', '.join(QP_SOLVERS)}, got {qp_solver!r}")
    if not ca.has_conic(qp_solver):
        raise OptimizationError(f"{who}: qp_solver: CasADi {ca.__version__} has no {qp_solver!r} plugin here")
    return qp_solver


def qp_function(qp_solver: str, n_vars: int, n_rows: int, max_iter: int) -> ca.Function:
    """``mpc_qp``: the ``conic`` of ``qp_solver`` on a dense QP of ``n_vars`` variables and
    ``n_rows`` general rows."""
    return ca.conic("mpc_qp", qp_solver, {"h": ca.Sparsity.dense(n_vars, n_vars),
                                          "a": ca.Sparsity.dense(n_rows, n_vars)}, QP_SOLVERS[qp_solver](max_iter))


class InProcessQP:
    """A CasADi QP ``Function`` called in this process with the interface of a compiled
    kernel's :meth:`~ncgen.codegen.direct.DirectFunction.status_call`: the status (0: the
    plugin reports success) and :attr:`outputs` (``x``, ``cost``, ``lam_a``, ``lam_x``); the
    arguments are the inputs' nonzeros (column-major), as for the compiled kernel; inputs left
    out are zero."""

    def __init__(self, function: ca.Function):
        self.function = function
        self.name = function.name()
        self.outputs: list[np.ndarray] = []

    def status_call(self, *args) -> int:
        f = self.function
        given = [ca.DM(f.sparsity_in(i), np.asarray(a, float).reshape(-1)) for i, a in enumerate(args)]
        out = f.call(given + [ca.DM(f.sparsity_in(i)) for i in range(len(args), f.n_in())])
        self.outputs = [np.asarray(o, float).reshape(-1) for o in out]
        return 0 if self.function.stats().get("success", False) else 1
