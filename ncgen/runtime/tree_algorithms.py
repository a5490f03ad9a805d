"""Compiled rigid-body algorithms of trees, called from Python with ~1 µs overhead: RNEA,
CRBA, ABA and the derivatives of RNEA and ABA (SX functions of
:mod:`ncgen.assembly.tree_algorithms`, one small C library each, compiled on first use and
cached on disk by content, called through :class:`~ncgen.codegen.direct.DirectFunction`).

* :func:`rnea` — ``τ(qj, vj, aj)``;  :func:`crba` — ``M(qj)``;  :func:`aba` — ``aj(qj, vj, τ)``;
* :func:`rnea_derivatives` — ``(τ, ∂τ/∂q, ∂τ/∂v, ∂τ/∂a)``;
* :func:`aba_derivatives` — ``(aj, ∂a/∂q, ∂a/∂v, ∂a/∂τ)``;
* :func:`algorithm_kernel` — the compiled kernel itself (:class:`AlgorithmKernel`), for loops
  (``nc.linearize(model, qj, vj, u, space="joint")`` uses the ABA derivatives:
  :mod:`ncgen.analysis.joint_linearization`).

Conventions are Pinocchio's (``pinocchio.rnea``, ``crba``, ``aba``,
``computeRNEADerivatives``, ``computeABADerivatives``): joint positions ``qj`` and rates
``vj``, ``aj`` in ``model.joint_names`` order (a free joint: ``[x, y, z, qx, qy, qz, qw]`` and
``[v, ω]`` in its frame), efforts ``τ`` and every derivative per independent joint rate
(mimic followers left out), position derivatives in the tangent space, gravity and the
model's other passive forces included at inputs ``u = 0``.  Models: trees of joints with
coordinates, mimic joints allowed (:func:`~ncgen.runtime.tree_check.check_tree`), 3D.
"""
from __future__ import annotations

import ctypes

import numpy as np

from ncgen.codegen.fast_call import fast_caller
from ncgen.errors import ModelError
from ncgen.model.data import cached, model_data
from ncgen.runtime.tree_check import PIVOT_TOL, check_tree, compile_tree_function, unit_quaternions
from ncgen.validation import as_numbers, as_vector

#: ``name: (inputs after t before p, outputs)`` of every algorithm.
ALGORITHMS = {
    "rnea": (("qj", "vj", "aj"), ("tau",)),
    "crba": (("qj",), ("M",)),
    "aba": (("qj", "vj", "tau"), ("aj",)),
    "rnea_derivatives": (("qj", "vj", "aj"), ("tau", "dtau_dq", "dtau_dv", "dtau_da")),
    "aba_derivatives": (("qj", "vj", "tau"), ("aj", "da_dq", "da_dv", "da_dtau")),
}


class AlgorithmKernel:
    """``k(*args) -> outputs``: one compiled algorithm of a tree (:data:`ALGORITHMS`: ``args``
    are its inputs, ``qj`` with unit quaternions).  Time and parameters are ``model.t0``,
    ``model.p0`` until :meth:`set`.  Returns the output buffers (one array, or a tuple;
    overwritten by the next call: copy them to keep them; matrices are column-major views,
    shape ``(n, n)``).  ABA and its derivatives raise :class:`ModelError` for a singular mass
    matrix or a non-finite result.  Not thread-safe: one kernel per thread (:meth:`copy`)."""

    def __init__(self, model, name: str, direct):
        self.model, self.name, self.direct = model, name, direct
        self.input_names, out_names = ALGORITHMS[name]
        self._inputs = direct.inputs[1:1 + len(self.input_names)]
        self._p = direct.inputs[-1]
        self._sizes = [b.size for b in self._inputs]
        outs = []
        for o, f_out in zip(direct.outputs, range(len(out_names))):
            shape = direct.function.size_out(f_out)
            outs.append(o.reshape(shape[::-1]).T if shape[1] > 1 else o)
        self._outputs = outs[0] if len(outs) == 1 else tuple(outs)
        self._check = None
        if direct.function.n_out() > len(out_names):
            check = direct.outputs[-1]
            self._check = (ctypes.c_double * 2).from_address(check.ctypes.data)
        self._fn, self._args = direct._fn, direct._args
        self._fast = fast_caller(direct, len(self._inputs), first=1, result=self._outputs,
                                 check=None if self._check is None else direct.outputs[-1], tol=PIVOT_TOL)
        self.set(t=model.t0, p=model.p0)

    def copy(self) -> "AlgorithmKernel":
        """The same compiled kernel with buffers (and time, parameters) of its own."""
        k = AlgorithmKernel(self.model, self.name, self.direct.copy())
        k.set(t=float(self.direct.inputs[0][0]), p=self._p)
        return k

    def set(self, *, t=None, p=None) -> None:
        """Time ``t`` (s) and parameters ``p`` (``model.parameter_names`` order) of later calls."""
        if t is not None:
            self.direct.inputs[0][...] = float(t)
        if p is not None:
            self._p[...] = as_vector(p, self.model.np, "p")

    def __call__(self, *args):
        fast = self._fast
        if fast is not None:
            try:
                out = fast(*args)
            except (TypeError, ValueError):
                self._bad_arguments(args)
            if out is None:
                self._singular()
            return out
        inputs = self._inputs
        if len(args) != len(inputs) or [np.size(x) for x in args] != self._sizes:
            self._bad_arguments(args)
        for buf, x in zip(inputs, args):
            buf[...] = x
        if self._fn(*self._args):
            raise ModelError(f"{self.name}: the compiled kernel returned an error")
        check = self._check
        if check is not None and not (check[0] > PIVOT_TOL and check[1] - check[1] == 0.0):
            self._singular()
        return self._outputs

    def _bad_arguments(self, args):
        for name, x in zip(self.input_names, args):
            as_numbers(x, f"{self.name}: {name}", "a sequence of numbers")
        if [np.size(x) for x in args] == self._sizes:
            raise ModelError(f"{self.name}: {', '.join(self.input_names)} must be sequences of numbers")
        raise ModelError(f"{self.name}: expected {len(self._inputs)} arguments ({', '.join(self.input_names)}) "
                         f"of {', '.join(map(str, self._sizes))} values, got {len(args)} of "
                         f"{', '.join(str(np.size(x)) for x in args)}")

    def _singular(self):
        check = self._check
        if np.isfinite(check[0]) and not check[0] > PIVOT_TOL:
            raise ModelError(f"{self.name}: the joint-space mass matrix is singular at this state "
                             f"(smallest relative Cholesky pivot {check[0]:.3g})")
        raise ModelError(f"{self.name}: the result is not finite (non-finite qj, vj or tau?)")


def algorithm_kernel(model, name: str, *, cflags=None) -> AlgorithmKernel:
    """The compiled algorithm ``name`` (a key of :data:`ALGORITHMS`) of the tree ``model``,
    built once per model (the library is cached by content).  Raises :class:`ModelError` for a
    model that is not a tree (:func:`~ncgen.runtime.tree_check.check_tree`) or not 3D."""
    from ncgen.assembly import tree_algorithms

    if name not in ALGORITHMS:
        raise ModelError(f"algorithm_kernel: name: expected one of {', '.join(ALGORITHMS)}, got {name!r}")

    def build() -> AlgorithmKernel:
        check_tree(model)
        if model.joint_space.dim != 3:
            raise ModelError(f"{name}: compiled rigid-body algorithms take 3D models only")
        f = getattr(tree_algorithms, f"{name}_function")(model)
        return AlgorithmKernel(model, name, compile_tree_function(model, f, cflags, name))

    return cached(model_data(model).algorithm_kernels, (name, cflags), build)


def rnea_applies(model) -> list[int] | None:
    """The indices (in ``v_j``) of the independent joint rates of ``model`` when the compiled
    algorithms take it (a 3D tree, mimic joints allowed), else None (checked once per model)."""
    from ncgen.assembly.tree_dynamics import MimicMap

    data = model_data(model)
    if data.algorithm_rates is None:
        try:
            check_tree(model)
            data.algorithm_rates = (MimicMap(model).independent if model.joint_space.dim == 3 else None,)
        except ModelError:
            data.algorithm_rates = (None,)
    return data.algorithm_rates[0]


def _run(model, name: str, args: dict, p, t: float):
    js = model.joint_space
    k = algorithm_kernel(model, name)
    sizes = {"qj": js.nq, "vj": js.nv, "aj": js.nv, "tau": k._sizes[-1]}
    values = []
    for a in k.input_names:
        what = {"qj": "joint positions", "vj": "joint rates", "aj": "joint accelerations",
                "tau": "efforts of the independent joint rates"}[a]
        x = as_vector(args[a], sizes[a], f"{a} ({what}, joint_names order)")
        values.append(unit_quaternions(js, x) if a == "qj" else x)
    k.set(t=t, p=model.p0 if p is None else p)
    out = k(*values)
    return tuple(np.array(o) for o in out) if isinstance(out, tuple) else np.array(out)


def rnea(model, qj, vj, aj, *, p=None, t: float = 0.0) -> np.ndarray:
    """``τ``: the efforts of the independent joint rates giving accelerations ``aj`` at
    ``(qj, vj)`` (module docstring; Pinocchio's ``rnea``)."""
    return _run(model, "rnea", {"qj": qj, "vj": vj, "aj": aj}, p, t)


def crba(model, qj, *, p=None, t: float = 0.0) -> np.ndarray:
    """``M``: the joint-space mass matrix of the independent rates (Pinocchio's ``crba``, both triangles)."""
    return _run(model, "crba", {"qj": qj}, p, t)


def aba(model, qj, vj, tau, *, p=None, t: float = 0.0) -> np.ndarray:
    """``aj``: joint accelerations under the efforts ``tau`` of the independent rates (Pinocchio's ``aba``)."""
    return _run(model, "aba", {"qj": qj, "vj": vj, "tau": tau}, p, t)


def rnea_derivatives(model, qj, vj, aj, *, p=None, t: float = 0.0) -> tuple[np.ndarray, ...]:
    """``(τ, ∂τ/∂q, ∂τ/∂v, ∂τ/∂a)`` (Pinocchio's ``computeRNEADerivatives``; ∂τ/∂a = M)."""
    return _run(model, "rnea_derivatives", {"qj": qj, "vj": vj, "aj": aj}, p, t)


def aba_derivatives(model, qj, vj, tau, *, p=None, t: float = 0.0) -> tuple[np.ndarray, ...]:
    """``(aj, ∂a/∂q, ∂a/∂v, ∂a/∂τ)`` (Pinocchio's ``computeABADerivatives``; ∂a/∂τ = M⁻¹;
    rows per independent rate)."""
    return _run(model, "aba_derivatives", {"qj": qj, "vj": vj, "tau": tau}, p, t)
