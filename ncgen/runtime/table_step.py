"""One step of the table-driven stepper and its Jacobians, with no compiler call: the element
library's ``ncgen_elements_step_jacobians`` (``templates/c/runtime/ncgen_table_jacobians.h``)
on a model's :class:`~ncgen.runtime.table_stepper.TableStepper`.

The step is RATTLE from ``x = [q; v]`` with inputs ``u`` held over it (no splitting); its
Jacobians ``∂x⁺/∂x`` (2nq × 2nq) and ``∂x⁺/∂u`` (2nq × nu) come from the implicit function
theorem on the stepper's own two Newton systems, each factored once (the C file's header
comment gives the equations).  :class:`TableStep` is what
:class:`ncgen.control.step.StepFunction` calls with ``kernels="tables"``, through
:meth:`TableStep.door` (the library's ``ncgen_elements_step_one``: one C call from Python,
checks and fresh outputs or ``out=`` included).
"""
from __future__ import annotations

import ctypes

import numpy as np

from ncgen.codegen import c_binding
from ncgen.codegen.element_kernels import PACKAGE
from ncgen.codegen.stepper_abi import StepOptions
from ncgen.runtime.table_stepper import TableStepper

#: The stepper's status codes other than 0 (templates/c/stepper.c.j2), as a step reports them.
STATUS = {1: "no convergence within max_iter", 2: "NaN or inf", 3: "the velocity constraints not met",
          4: "a kernel failed or the Newton matrix is singular", 5: "bad input or out of memory"}
#: ``ncgen_elements_step_jacobians``'s arguments after the stepper tables.
SIGNATURE = c_binding.Signature("int", (
    ("const ncgen_stepper_tables *", "S"), ("const casadi_real *", "q"), ("const casadi_real *", "v"),
    ("casadi_real", "t"),
    ("const casadi_real *", "u"), ("const casadi_real *", "p"), ("casadi_real", "h"),
    ("const ncgen_elements_step_options *", "options"), ("const int *", "d_colind"), ("const int *", "d_row"),
    ("const double *", "d_val"), ("casadi_real *", "q_next"),
    ("casadi_real *", "v_next"), ("casadi_real *", "Jx"), ("casadi_real *", "Ju"), ("casadi_real *", "res"),
    ("int *", "iterations")))


def constraint_hessians(stepper: TableStepper) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``D`` (a_nnz × nq, CSC ``(colind, row, val)``, int32/float64): column ``i`` the nonzeros
    of ``A(e_i) − A(0)``.  Every covered constraint is quadratic in q, so ``A`` is affine and
    ``A(q + d) − A(q) = D d`` for every q: the constant second derivatives the step's
    Jacobians need (``Σ_k ν_k H_k d = (D d)ᵀ ν``).  Computed by the element library."""
    from ncgen.runtime.table_library import TableFunctions

    T = stepper.tables.tables
    tf = TableFunctions(T, stepper.library_object)
    nq = T.nq
    A0 = tf.A(np.zeros(nq))
    rows, vals, counts = [], [], []
    for i in range(nq):
        e = np.zeros(nq)
        e[i] = 1.0
        d = tf.A(e) - A0
        nz = np.flatnonzero(d)
        rows.append(nz)
        vals.append(d[nz])
        counts.append(nz.size)
    colind = np.concatenate([[0], np.cumsum(counts)]).astype(np.int32)
    row = np.concatenate(rows).astype(np.int32) if rows else np.zeros(0, np.int32)
    val = np.concatenate(vals) if vals else np.zeros(0)
    return colind, np.ascontiguousarray(row), np.ascontiguousarray(val, dtype=float)


class StepDoorArguments(ctypes.Structure):
    """``ncgen_elements_step_door`` (templates/c/element_tables.c.j2): the fixed arguments of ``_step_one``."""

    _fields_ = [("S", ctypes.c_void_p), ("options", ctypes.c_void_p), ("d_colind", ctypes.c_void_p),
                ("d_row", ctypes.c_void_p), ("d_val", ctypes.c_void_p), ("p", ctypes.c_void_p),
                ("h", ctypes.c_double), ("res_tol", ctypes.c_double), ("nq", ctypes.c_long), ("nu", ctypes.c_long)]


class StepDoor:
    """``door(x, u)`` or ``door(x, u, out)``: one step (and its Jacobians when made with
    ``jacobians``) of a :class:`TableStep` in one C call through
    :func:`~ncgen.codegen.fast_call.fast_caller`: ``x`` (2nq) and ``u`` (nu) checked finite and of
    magnitude at most :data:`~ncgen.validation.MAX_MAGNITUDE` while copied, the step, its
    convergence (the stepper's status and the residual at most ``res_tol``) and finite results
    checked in C, fresh ``x⁺`` (and ``A``, ``B``; without inputs ``x⁺`` and ``A`` only) returned
    or written into ``out``.  None when the step did not converge, a TypeError or ValueError
    for what it refuses: the caller's checked path names the reason.  ``t``: the time input
    (s), :meth:`at` sets it."""

    __slots__ = ("call", "t", "_t", "_keep")

    def __init__(self, call, t_buffer: np.ndarray, keep):
        self.call, self._t, self._keep = call, t_buffer, keep
        self.t = float(t_buffer[0])

    def at(self, t: float) -> None:
        """The time (s) of the next steps."""
        self._t[0] = self.t = t


class TableStep:
    """``step(x, u, t, jacobians)`` of one model through its table stepper: RATTLE with step
    ``h`` (s), Newton tolerance ``tol`` (the stepper's test: ``‖Φ(q⁺)‖∞ ≤ tol`` and the
    momentum rows ``≤ tol max|M_ij| (1 + ‖w‖∞)``) and at most ``max_iter`` iterations.  Not
    thread-safe (one set of output buffers): one object per thread."""

    def __init__(self, stepper: TableStepper, h: float, *, tol: float, max_iter: int):
        self.stepper, self.h = stepper, float(h)
        self.nq, self.nu = stepper.nq, stepper.nu
        fn = c_binding.bind(stepper._lib, f"{PACKAGE}_step_jacobians", SIGNATURE, name=PACKAGE,
                            structs={f"{PACKAGE}_step_options": StepOptions}, addresses=True)
        self._S = ctypes.addressof(stepper._S)
        self._fn = fn
        self._options = StepOptions(tol=tol, max_iter=max_iter, max_halvings=0, scheme=0, stop=None)
        self._opt = ctypes.addressof(self._options)
        nx = 2 * self.nq
        self._q1, self._v1 = np.zeros(self.nq), np.zeros(self.nq)
        self._Jx, self._Ju = np.zeros((nx, nx), order="F"), np.zeros((nx, self.nu), order="F")
        self._res, self._it = np.zeros(1), np.zeros(1, dtype=np.intc)
        self._p = np.zeros(1)
        self._D = constraint_hessians(stepper)
        # the addresses of the fixed arrays, looked up once (the calls pass only x's and u's)
        self._fixed = (*(a.ctypes.data for a in self._D), self._q1.ctypes.data, self._v1.ctypes.data)
        self._jac = (self._Jx.ctypes.data, self._Ju.ctypes.data if self.nu else None)
        self._out = (self._res.ctypes.data, self._it.ctypes.data)
        self._p_at = self._p.ctypes.data

    def door(self, jacobians: bool, res_tol: float):
        """The :class:`StepDoor` of this step (with its Jacobians when ``jacobians``; a step
        whose residual exceeds ``res_tol`` is refused), or None without the fast-call extension
        or the library's ``_step_one``."""
        from ncgen.codegen.fast_call import fast_caller
        from ncgen.runtime.tree_library import _Direct
        from ncgen.validation import MAX_MAGNITUDE

        one = getattr(self.stepper._lib, f"{PACKAGE}_step_one", None)
        if one is None:
            return None
        nq, nu = self.nq, self.nu
        nx = 2 * nq
        fixed = StepDoorArguments(self._S, self._opt, *self._fixed[:3], self._p_at, self.h, float(res_tol), nq, nu)
        x, u, t = np.zeros(nx), np.zeros(nu), np.zeros(1)
        x1, check, info = np.zeros(nx), np.zeros(2), np.zeros(3)
        Jx, Ju = (np.zeros(nx * nx), np.zeros(nx * nu)) if jacobians else (None, None)
        arg = (ctypes.c_void_p * 4)(ctypes.addressof(fixed), x.ctypes.data, u.ctypes.data if nu else None,
                                    t.ctypes.data)
        res = (ctypes.c_void_p * 5)(x1.ctypes.data, None if Jx is None else Jx.ctypes.data,
                                    Ju.ctypes.data if jacobians and nu else None, check.ctypes.data, info.ctypes.data)
        keep = (fixed, arg, res, x, u, t, x1, Jx, Ju, check, info, self)
        shim = _Direct([None, x, u], one, (ctypes.addressof(arg), ctypes.addressof(res), 0, 0, 0), keep)
        outputs = [(x1, nx, 0)] + ([(Jx, nx, nx)] + ([(Ju, nx, nu)] if nu else []) if jacobians else [])
        call = fast_caller(shim, 2, first=1, check=check, tol=0.5, bound=MAX_MAGNITUDE, outputs=outputs)
        return None if call is None else StepDoor(call, t, keep)

    def __call__(self, x: np.ndarray, u: np.ndarray, t: float, jacobians: bool):
        """``(status, x1, res, iterations, A, B)`` (``A``, ``B`` None unless ``jacobians``;
        fresh arrays).  ``status``: the stepper's code (0 when the step converged)."""
        x = np.ascontiguousarray(x, dtype=float)
        u = np.ascontiguousarray(u, dtype=float) if self.nu else self._p
        at = x.ctypes.data
        status = self._fn(self._S, at, at + 8 * self.nq, float(t), u.ctypes.data, self._p_at, self.h, self._opt,
                          *self._fixed, *(self._jac if jacobians else (None, None)), *self._out)
        x1 = np.concatenate((self._q1, self._v1))
        A = self._Jx.copy() if jacobians else None
        B = self._Ju.copy() if jacobians else None
        return int(status), x1, float(self._res[0]), int(self._it[0]), A, B
