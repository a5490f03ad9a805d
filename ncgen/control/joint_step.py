"""The discrete step of a tree robot in joint space, with its exact Jacobians, for the
joint-space MPC (:mod:`ncgen.control.joint_mpc`).

State ``x = [q_j; v_j]`` (joint positions and rates, ``model.joint_names`` order; rad or m,
rad/s or m/s), input ``τ`` (the efforts of the joint rates, N·m or N: Pinocchio's ``tau``,
for a URDF robot its input ``tau``).  One step of length ``h`` (s) is semi-implicit
(symplectic) Euler on the articulated-body algorithm's accelerations ``a = ABA(q, v, τ)``::

    v⁺ = v + h a(q, v, τ),        q⁺ = q + h v⁺

and its Jacobians follow from ABA's derivatives (:func:`ncgen.runtime.tree_algorithm_kernels.aba_derivatives`:
``∂a/∂q``, ``∂a/∂v``, ``∂a/∂τ = M⁻¹``, compiled C)::

    ∂v⁺/∂x = [h ∂a/∂q,  I + h ∂a/∂v],      ∂v⁺/∂τ = h M⁻¹,
    ∂q⁺/∂x = [I, 0] + h ∂v⁺/∂x,            ∂q⁺/∂τ = h ∂v⁺/∂τ.

These formulas are :func:`step_jacobians_function`, compiled once per ``n`` (cached by content)
and called in one C call on the kernel's output buffers, returning fresh ``(x⁺, A, B)`` or
writing them into ``out=`` (:func:`~ncgen.codegen.fast_call.fast_caller`'s door: a call costs
the kernel and about 1 µs); without a C compiler, the extension or a flat kernel, CasADi
evaluates the same function.  A call (``x⁺`` alone) is ABA's kernel and the first of those
formulas, :func:`step_function_of_n`, compiled the same way (one more C call on ABA's output
buffer; ``out=`` too); without it NumPy computes them.

It is time-invariant; :func:`ncgen.control.ilqr.ilqr` takes it as it takes a natural-coordinate
step (Gauss–Newton: no second derivatives of this step; the parameters are those given here).

Only trees whose joint positions add (``q⁺ = q + h v``: hinges and slides, no quaternion) and
whose every rate is independent (no mimic joint) take it; others are refused by name.
"""
from __future__ import annotations

import ctypes
import functools
import os

import casadi as ca
import numpy as np

from ncgen.control.step import StepFunction
from ncgen.errors import CompilerNotFound, NcgenError
from ncgen.runtime.tree_algorithm_kernels import KERNELS, AlgorithmKernel, aba, aba_derivatives, buffers, kernel_of
from ncgen.codegen.tree_check import ALGORITHMS, PIVOT_TOL
from ncgen.validation import MAX_MAGNITUDE, as_vector, positive, write_out


def joint_step_refusal(model) -> str | None:
    """Why ``model`` has no joint-space step of this module, or None."""
    js = getattr(model, "joint_space", None)
    if js is None:
        return f"model {model.name!r} has no joint space (not a tree of joints)"
    if js.nq != js.nv:
        return (f"model {model.name!r}: joint positions do not add (nq = {js.nq} ≠ nv = {js.nv}: "
                f"a quaternion joint); the step q⁺ = q + h v needs hinges and slides only")
    return None


def _next_state(h, a, x, n: int):
    """``x⁺ = [q + h v⁺; v⁺]`` with ``v⁺ = v + h a`` (module docstring), one expression for the
    step and its Jacobians (so that both give the same ``x⁺`` to the last bit)."""
    v1 = a * h + x[n:]
    return ca.vertcat(v1 * h + x[:n], v1)


def step_function_of_n(n: int) -> ca.Function:
    """``(h, a, x) -> x⁺``: the step (module docstring) from ABA's accelerations at ``x = [q; v]``."""
    h, a, x = ca.SX.sym("h"), ca.SX.sym("a", n), ca.SX.sym("x", 2 * n)
    return ca.Function("joint_step", [h, a, x], [_next_state(h, a, x, n)], ["h", "a", "x"], ["x1"])


def step_jacobians_function(n: int) -> ca.Function:
    """``(h, a, da_dq, da_dv, Minv, x) -> (x⁺, A, B)``: the step and its Jacobians (module
    docstring) from ABA's outputs at ``x = [q; v]`` (``n`` rates; matrices ``n × n``, stored
    column-major as the kernel writes them)."""
    h, a, x = ca.SX.sym("h"), ca.SX.sym("a", n), ca.SX.sym("x", 2 * n)
    da_dq, da_dv, Minv = (ca.SX.sym(name, n, n) for name in ("da_dq", "da_dv", "Minv"))
    eye, zero = ca.SX.eye(n), ca.SX.zeros(n, n)
    Av = ca.horzcat(da_dq * h, da_dv * h)                  # ∂v⁺/∂x − [0, I]
    A = ca.vertcat(Av * h + ca.horzcat(eye, h * eye), Av + ca.horzcat(zero, eye))
    B = ca.vertcat(Minv * h * h, Minv * h)
    return ca.Function("joint_step_jacobians", [h, a, da_dq, da_dv, Minv, x],
                       [_next_state(h, a, x, n), ca.densify(A), ca.densify(B)],
                       ["h", "a", "da_dq", "da_dv", "Minv", "x"], ["x1", "A", "B"])


#: ``{(n, $NCGEN_CFLAGS): DirectFunction}``: :func:`step_jacobians_function` compiled, per process.
_COMPILED: dict = {}
#: ``{(n, $NCGEN_CFLAGS): DirectFunction}``: :func:`step_function_of_n` compiled, per process.
_COMPILED_STEP: dict = {}


def compiled_step(n: int, h: float):
    """``step(a, x)`` or ``step(a, x, out)``: ``x⁺`` from ABA's accelerations ``a`` at ``x`` in
    one C call, a fresh array or written into ``out`` (a ValueError for a bad ``out``); None
    without a C compiler or the extension."""
    from ncgen.codegen.fast_call import fast_caller

    direct = _compiled_copy(_COMPILED_STEP, "joint_step", step_function_of_n, n, h)
    return None if direct is None else fast_caller(direct, 2, first=1, outputs=[(direct.outputs[0], 2 * n, 0)])


def _compiled_copy(compiled: dict, name: str, make, n: int, h: float):
    """``make(n)`` (a function of ``(h, ...)``) compiled once per ``n`` and ``$NCGEN_CFLAGS``
    (kept in ``compiled``), as a copy with buffers of its own and its ``h`` set; None without a
    C compiler."""
    from ncgen.codegen.direct import compile_direct

    key = n, os.environ.get("NCGEN_CFLAGS")
    if key not in compiled:
        try:
            compiled[key] = compile_direct(f"{name}_{n}", make(n))
        except CompilerNotFound:
            compiled[key] = None
    if compiled[key] is None:
        return None
    direct = compiled[key].copy()
    direct.inputs[0][0] = h
    return direct


def joined_caller(model, k, p):
    """``call(x, tau)``: the flat kernel ``k`` (ABA or its derivatives) of ``model`` at
    ``x = [q; v]`` (one buffer of 2n values whose halves are the kernel's ``qj`` and ``vj``: no
    slicing in Python), ``t = 0`` and the parameters ``p`` (None: the model's), on buffers of
    its own (:meth:`~ncgen.codegen.direct.DirectFunction.copy`), every value checked in C
    (finite, magnitude at most :data:`~ncgen.validation.MAX_MAGNITUDE`) and the pivot check
    too: returns the output buffers (None when the check fails, a TypeError or ValueError for
    what it refuses), with them: ``(call, outputs)``; None for a kernel on the tree tables,
    with quaternions, or without the extension."""
    from ncgen.codegen.fast_call import fast_caller
    from ncgen.runtime.tree_library import _Direct

    if not isinstance(k, AlgorithmKernel) or k._fast is None or k._quaternions:
        return None
    d, n = k.direct.copy(), model.joint_space.nv
    d.inputs[-1][...] = model.p0 if p is None else as_vector(p, model.np, "p")
    x = np.zeros(2 * n)
    arg = (ctypes.c_void_p * len(d._arg))(*(ctypes.cast(a, ctypes.c_void_p).value for a in d._arg))
    arg[1], arg[2] = x.ctypes.data, x.ctypes.data + 8 * n              # qj, vj: the halves of x
    names = ALGORITHMS[k.name][1]
    outs = d.outputs[:len(names)]
    check = d.outputs[-1] if d.function.n_out() > len(names) else None
    shim = _Direct([d.inputs[0], x, d.inputs[3]], d._fn, (ctypes.addressof(arg), *d._args[1:]), (d, arg, x))
    call = fast_caller(shim, 2, first=1, check=check, tol=PIVOT_TOL, bound=MAX_MAGNITUDE,
                       result=outs[0] if len(outs) == 1 else tuple(outs))
    return None if call is None else (call, outs)


def compiled_assembly(kernel, n: int, h: float, buffers=None):
    """``assemble(x)`` or ``assemble(x, out)``: ``(x⁺, A, B)`` from the output buffers of the
    flat ABA-derivatives ``kernel`` (just called at ``x``; ``buffers``: other buffers of its
    four outputs, those of a :func:`joined_caller`) in one C call, fresh arrays or
    written into ``out`` (a ValueError for a bad ``out``); None for a kernel on the tree tables,
    without a C compiler or without the extension."""
    from ncgen.codegen.fast_call import fast_caller

    if not isinstance(kernel, AlgorithmKernel):
        return None
    direct = _compiled_copy(_COMPILED, "joint_step_jacobians", step_jacobians_function, n, h)
    if direct is None:
        return None
    x1, A, B = direct.outputs
    fast = fast_caller(direct, 5, first=1, outputs=[(x1, 2 * n, 0), (A, 2 * n, 2 * n), (B, 2 * n, n)])
    return None if fast is None else functools.partial(fast, *(kernel.direct.outputs[:4] if buffers is None
                                                               else buffers))


class JointStep:
    """``x⁺ = step(x, τ)`` and ``(x⁺, A, B) = step.jacobians(x, τ)`` (module docstring) of
    ``model`` with the step ``h`` (s) and parameters ``p`` (None: the model's); ``kernels``:
    those of ABA's derivatives (:func:`~ncgen.runtime.tree_algorithm_kernels.algorithm_kernels`)."""

    #: iLQR runs Gauss–Newton on this step (:func:`ncgen.control.ilqr.ilqr`).
    second_derivatives = False

    def __init__(self, model, h: float, *, p=None, kernels: str = "auto"):
        why = joint_step_refusal(model)
        if why is not None:
            raise NcgenError(f"JointStep: {why}")
        self.model, self.h, self.p = model, positive(h, "JointStep: h (the step, s)"), p
        self.n = model.joint_space.nv
        if kernels not in KERNELS:
            raise NcgenError(f"JointStep: kernels: expected one of {', '.join(map(repr, KERNELS))}, got {kernels!r}")
        a, *_ = aba_derivatives(model, np.zeros(self.n), np.zeros(self.n), np.zeros(self.n), p=p, kernels=kernels)
        if a.shape != (self.n,):
            raise NcgenError(f"JointStep: model {model.name!r} has dependent joint rates (a mimic joint: "
                             f"{a.shape[0]} independent of {self.n}); lock or remove the follower joints")
        self.nx, self.nu = 2 * self.n, self.n
        n, h = self.n, self.h
        self._derivatives = kernel_of(model, "aba_derivatives", kernels)
        self._assemble = compiled_assembly(self._derivatives, n, h)
        self._function = None if self._assemble is not None else step_jacobians_function(n)
        self._aba = kernel_of(model, "aba", kernels)
        self._step = compiled_step(n, h)
        # a call and jacobians straight to C (flat kernels and the compiled formulas): ABA (its
        # derivatives) on x whole through a joined caller, then the formulas on its buffers
        joined = joined_caller(model, self._aba, p) if self._step is not None else None
        self._straight_call = None if joined is None else joined[0]
        joined = joined_caller(model, self._derivatives, p) if self._assemble is not None else None
        self._straight_jacobians = None if joined is None else (
            joined[0], compiled_assembly(self._derivatives, n, h, joined[1]))

    def _split(self, x, tau):
        """``x, tau`` as finite float vectors of the right sizes, else the error naming the
        argument (the checked path: a call the C callers take never comes here)."""
        return (as_vector(x, self.nx, "x (joint positions and rates [q_j; v_j])"),
                as_vector(tau, self.nu, "tau (efforts of the joint rates)"))

    def _same(self, p, what: str) -> None:
        if p is not None:
            raise NcgenError(f"JointStep.{what}: p: the parameters are fixed when the step is made "
                             f"(JointStep(model, h, p=...)); got p = {p!r}")

    def __call__(self, x, tau, p=None, t=None, *, out=None) -> np.ndarray:
        """``x⁺`` (``t``, s, is ignored: the step is time-invariant); ``out``: a writable
        C-contiguous float64 array of ``2n`` values, written and returned."""
        aba = self._straight_call
        if aba is not None and p is None:       # every check in C; whatever it refuses: the checked path
            try:
                a = aba(x, tau)
                if a is not None:
                    return self._step(a, x) if out is None else self._step(a, x, out)
            except (TypeError, ValueError, OverflowError):
                pass
        self._same(p, "__call__")
        return self.unchecked(*self._split(x, tau), out=out)

    _inputs = StepFunction._inputs         # U: (N, nu) finite, checked as a natural-coordinate step's

    def rollout(self, x0, U, p=None, t0=None) -> np.ndarray:
        """States after each of the ``N = len(U)`` steps, shape ``(N, nx)`` (``U``: ``(N, nu)``)."""
        self._same(p, "rollout")
        U = self._inputs(U)
        x = self._split(x0, U[0])[0]
        X = np.empty((U.shape[0], self.nx))
        for k in range(U.shape[0]):
            x = X[k] = self.unchecked(x, U[k])
        return X

    def ilqr_start(self, x0, U0, p, t0):
        """``(x0, U, p, t0)`` of :func:`ncgen.control.ilqr.ilqr` for this step: ``x0`` checked,
        ``U`` a float copy of ``U0`` (N × nu), ``t0`` 0 (the step is time-invariant)."""
        self._same(p, "ilqr")
        U = self._inputs(U0).copy()
        return self._split(x0, U[0])[0], U, None, 0.0

    def unchecked(self, x: np.ndarray, tau: np.ndarray, *, out=None) -> np.ndarray:
        """``x⁺`` of a float vector ``x`` and ``tau`` of the right sizes, unchecked (by ABA
        alone, without its derivatives; the kernel still refuses values that are not finite)."""
        n, h, step = self.n, self.h, self._step
        if step is not None:
            a = buffers(self.model, self._aba, (x[:n], x[n:], tau), self.p, 0.0)
            if out is None:
                return step(a, x)
            try:
                return step(a, x, out)
            except ValueError:              # a bad out: write_out names what is wrong with it
                return write_out(out, step(a, x), "JointStep")
        v1 = x[n:] + h * aba(self.model, x[:n], x[n:], tau, p=self.p)
        x1 = np.concatenate([x[:n] + h * v1, v1])
        return x1 if out is None else write_out(out, x1, "JointStep")

    def jacobians(self, x, tau, p=None, t=None, *, out=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(x⁺, A = ∂x⁺/∂x, B = ∂x⁺/∂τ)`` at ``(x, τ)`` (``t`` ignored); ``out``: a tuple of
        three writable C-contiguous float64 arrays of shapes ``(2n,)``, ``(2n, 2n)``, ``(2n, n)``,
        written and returned."""
        straight = self._straight_jacobians
        if straight is not None and p is None:  # every check in C; whatever it refuses: the checked path
            try:
                if straight[0](x, tau) is not None:
                    return straight[1](x) if out is None else straight[1](x, out)
            except (TypeError, ValueError, OverflowError):
                pass
        self._same(p, "jacobians")
        return self.unchecked_jacobians(*self._split(x, tau), out=out)

    def unchecked_jacobians(self, x: np.ndarray, tau: np.ndarray, *,
                            out=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`jacobians` of a float vector ``x`` and ``tau`` of the right sizes, unchecked
        (the MPC's rollout; the kernel still refuses values that are not finite)."""
        n = self.n
        outputs = buffers(self.model, self._derivatives, (x[:n], x[n:], tau), self.p, 0.0)
        assemble = self._assemble
        if assemble is not None:
            if out is None:
                return assemble(x)
            try:
                return assemble(x, out)
            except ValueError:              # a bad out: write_out names what is wrong with it
                return write_out(out, assemble(x), "JointStep.jacobians")
        result = tuple(np.array(r) for r in self._function(self.h, *outputs, x))
        result = (result[0].reshape(-1), *result[1:])
        return result if out is None else write_out(out, result, "JointStep.jacobians")
