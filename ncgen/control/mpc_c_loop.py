"""The SQP controller's whole control step in one C call: ``nc.MPC(ocp, loop="c")``.

The MPC's package (:func:`ncgen.control.mpc.mpc_functions`) is compiled with the exported
package's controller (``templates/c/mpc/mpc.c.j2`` around ``ncgen_mpc.h``, rendered with
``in_process``: no plant, the iterations per control step set at run time), so the iterations,
line searches, checks and the shift of the guess run in C, as in the package of
:func:`ncgen.control.export.export_mpc`, and Python makes one ctypes call per control step.
The controller's struct lives in a NumPy buffer; its first members are the guess ``X``
(nx × (N + 1), node by node), ``U`` (nu × N) and the last solution ``X_sol``, ``U_sol``
(``templates/c/mpc/mpc.h.j2``), read as views.  Every SQP controller's package holds this C, and
its ``mpc_condensed_qp`` gives the Python loop its QP (``ncgen_condense.h``: the one condensing);
where the QP solver is not generated (qpOASES) the package holds only that condensing.
"""
from __future__ import annotations

import ctypes

import numpy as np

from ncgen.codegen.c_binding import Signature, bind, open_library
from ncgen.errors import OptimizationError

#: The entry points (``{name}``: the package's name), as ``templates/c/mpc/mpc.h.j2`` declares them.
SIGNATURES = {
    "mpc_init": Signature("int", (("{name}_mpc *", "m"), ("const casadi_real *", "x"), ("casadi_real", "t"),
                                  ("int", "iterations"))),
    "mpc_step": Signature("int", (("{name}_mpc *", "m"), ("const casadi_real *", "x"), ("casadi_real", "t"),
                                  ("casadi_real *", "u_out"))),
    "mpc_free": Signature("void", (("{name}_mpc *", "m"),)),
    "mpc_sizeof": Signature("casadi_int", ()),
    "mpc_set_iterations": Signature("void", (("{name}_mpc *", "m"), ("int", "iterations"))),
    "mpc_report": Signature("void", (("const {name}_mpc *", "m"), ("int *", "qp_status"),
                                     ("casadi_real *", "alpha"))),
    "mpc_condensed_qp": Signature("int", (("{name}_mpc *", "m"), ("const casadi_real *", "x"), ("casadi_real", "t"),
                                         ("const casadi_real *", "X"), ("const casadi_real *", "U"),
                                         ("casadi_real * const *", "out"))),
}
#: The entry points of the condensing alone (the package of a QP solved in Python).
CONDENSING = ("mpc_sizeof", "mpc_condensed_qp")
#: Return codes of ``mpc_init`` and ``mpc_step`` (``templates/c/runtime/ncgen_mpc.h``).
OK, FAILED, BAD_INPUT = 0, 1, 2


class CompiledLoop:
    """The controller of the package ``name`` in ``library`` for states of ``nx`` and inputs
    of ``nu`` values on ``N`` intervals, with ``n_rows`` general rows in its QP:
    :meth:`condensed_qp` (every loop's QP data), and with ``controller`` (the QP solved in C)
    :meth:`start` (``reset``), :meth:`step` (one control step); ``X``, ``U``: the guess,
    ``X_sol``, ``U_sol``: the last solution (views of the struct, (N + 1) × nx and N × nu)."""

    def __init__(self, library, name: str, nx: int, nu: int, N: int, n_rows: int = 0, controller: bool = True):
        self._lib = open_library(library)
        self._fn = {k: bind(self._lib, f"{name}_{k}", s, name=name, addresses=True) for k, s in SIGNATURES.items()
                    if controller or k in CONDENSING}
        size = int(self._fn["mpc_sizeof"]())
        self._struct = np.zeros(size // 8 + 1)          # 8-byte aligned: doubles, ints and pointers
        self._m = self._struct.ctypes.data
        nxs, nus = nx * (N + 1), nu * N
        views = np.split(self._struct[:2 * (nxs + nus)], np.cumsum([nxs, nus, nxs]))
        self.X, self.U, self.X_sol, self.U_sol = (v.reshape(-1, n) for v, n in zip(views, (nx, nu, nx, nu)))
        self._u = np.zeros(max(nu, 1))
        self._status, self._alpha = ctypes.c_int(0), ctypes.c_double(0.0)
        self._started = False
        nU = nu * N
        self._qp = [np.zeros(max(n, 1)) for n in (nU * nU, nU, n_rows * nU, n_rows, n_rows, nU, nU, nxs, nxs * nU,
                                                    1, 1, 1)]
        self._qp_out = (ctypes.c_void_p * len(self._qp))(*(a.ctypes.data for a in self._qp))
        self._qp_arrays = [a[:n] for a, n in zip(self._qp, (nU * nU, nU, n_rows * nU, n_rows, n_rows, nU, nU, nxs,
                                                             nxs * nU, 1, 1, 1))]

    def condensed_qp(self, x: np.ndarray, t: np.ndarray, X: np.ndarray, U: np.ndarray) -> list[np.ndarray]:
        """The condensed QP at the guess ``(X, U)`` (float64, contiguous, node by node) from the
        controller's C (``ncgen_condense.h``): ``H, g, A, lba, uba, lbx, ubx, Xs, S, J, c, res``
        (:func:`ncgen.control.mpc.mpc_functions`) as flat arrays (column-major), overwritten by the next call;
        :class:`OptimizationError` when a step along the guess fails.  ``t``: a 1-array."""
        if self._fn["mpc_condensed_qp"](self._m, x.ctypes.data, float(t[0]), X.ctypes.data, U.ctypes.data,
                                        ctypes.addressof(self._qp_out)):
            raise OptimizationError("the compiled controller's QP data: a step along the guess failed")
        return self._qp_arrays

    def start(self, x: np.ndarray, t: float, iterations: int, per_step: int) -> int:
        """The guess set to ``x`` held with the inputs at rest, then ``iterations`` solves at
        ``(x, t)``; ``per_step``: SQP iterations of each later :meth:`step`.  The status."""
        if self._started:
            self._fn["mpc_free"](self._m)
        self._fn["mpc_set_iterations"](self._m, per_step)
        self._started = True
        return int(self._fn["mpc_init"](self._m, x.ctypes.data, t, iterations))

    def step(self, x: np.ndarray, t: float) -> tuple[int, np.ndarray]:
        """``(status, u)``: one control step at the measured state ``x`` (float64, contiguous)
        and time ``t``; ``u`` is overwritten by the next call."""
        return int(self._fn["mpc_step"](self._m, x.ctypes.data, t, self._u.ctypes.data)), self._u

    def report(self) -> tuple[int, float]:
        """``(qp_status, alpha)`` of the last SQP iteration."""
        self._fn["mpc_report"](self._m, ctypes.addressof(self._status), ctypes.addressof(self._alpha))
        return self._status.value, self._alpha.value

    def __del__(self):
        if getattr(self, "_started", False):
            self._fn["mpc_free"](self._m)


def loop_refusal(solver: str, qp_solver: str, problem) -> str | None:
    """Why ``loop="c"`` cannot run this controller, or ``None``: the C controller is the
    exported package's (qrqp generated into it; the guess shifted by repeating its last node and
    input, not from a reference)."""
    for reason, bad in (("solver='fatrop'", solver != "sqp"), (f"qp_solver={qp_solver!r}", qp_solver != "qrqp"),
                        ("a reference", problem.reference is not None)):
        if bad:
            return reason
    return None


def check_loop(loop) -> str:
    """``loop``: ``"python"`` or ``"c"``."""
    if not isinstance(loop, str) or loop not in ("python", "c"):
        raise OptimizationError(f"MPC: loop: expected 'python' or 'c', got {loop!r}")
    return loop
