"""Compiled joint-space forward dynamics of trees, called from Python with ~1 µs overhead.

* :func:`joint_forward_dynamics` — ``a_j`` from joint positions, rates and inputs (joint
  space in and out, ``model.joint_names`` order); by default the compiled kernel below for
  trees (mimic joints included), else (closed loops, drives) ``from_joint_space`` → the exact KKT
  solve (:func:`~ncgen.runtime.dynamics_at_state.forward_dynamics`) → ``to_joint_space``.
* :func:`joint_forward_dynamics_kernel` — the compiled kernel as a callable
  ``k(qj, vj, u) -> a_j`` (:class:`JointDynamicsKernel`): the recursive form of
  :func:`~ncgen.assembly.tree_dynamics.recursive_dynamics_function` for 3D trees (the
  projected form :func:`~ncgen.assembly.tree_dynamics.tree_dynamics_function` in 2D), one C
  function called through ctypes (:class:`~ncgen.codegen.direct.DirectFunction`), compiled
  once per model and cached on disk by content.

A model is a tree for this purpose when its members hang from the ground through joints
with coordinates (and Fixed joints) and it has no other constraints than mimic joints
(:class:`~ncgen.assembly.tree_dynamics.MimicMap`: a follower's entries of ``qj``, ``vj`` are
set from its leader's, and its acceleration follows): checked when the kernel is built, at a
random state (the tree map satisfies every constraint, and the model has exactly as many
degrees of freedom as independent joint rates).
"""
from __future__ import annotations

import ctypes

import numpy as np

from ncgen.codegen.fast_call import fast_caller
from ncgen.errors import ModelError
from ncgen.model.data import cached, model_data
from ncgen.runtime.dynamics_at_state import forward_dynamics
from ncgen.codegen.tree_check import (PIVOT_TOL, check_tree, compile_tree_function, quaternion_offsets,
                                      unit_quaternions)
from ncgen.runtime.kernel_time_parameters import TimeAndParameters
from ncgen.validation import MAX_MAGNITUDE, as_numbers, as_vector, write_out

METHODS = ("auto", "recursive", "projection")


class JointDynamicsKernel(TimeAndParameters):
    """``k(qj, vj, u=None) -> a_j``: the compiled joint-space forward dynamics of a tree.

    ``qj``, ``vj``: joint positions and rates (``model.joint_names`` order, a free base's
    quaternion normalised by the caller), ``u`` the inputs (``model.input_names`` order;
    None: zero).  Time and parameters are ``t = model.t0`` and ``p = model.p0`` until
    :meth:`set` changes them.  Returns the output buffer (overwritten by the next call; copy
    it to keep it).  Raises :class:`ModelError` when ``M_j`` is singular at the state.
    Not thread-safe: one kernel per thread."""

    def __init__(self, model, direct, method: str):
        self.model, self.direct, self.method = model, direct, method
        self.nq, self.nv, self.nu = model.joint_space.nq, model.joint_space.nv, model.nu
        t, self._qj, self._vj, self._u, self._p = direct.inputs
        self._aj, check = direct.outputs
        self._check = (ctypes.c_double * 2).from_address(check.ctypes.data)    # Python floats on indexing
        self._keep = check
        self._fn, self._args = direct._fn, direct._args
        self._zero_u = np.zeros(self.nu)
        self._fast = fast_caller(direct, 3, first=1, check=check, tol=PIVOT_TOL, result=self._aj)
        js = model.joint_space
        #: ``nc.joint_forward_dynamics``' door: non-finite or too large inputs refused, quaternions
        #: normalised, a fresh ``a_j`` returned or ``out`` written, in C
        self._door = fast_caller(direct, 3, first=1, check=check, tol=PIVOT_TOL, bound=MAX_MAGNITUDE,
                                 outputs=[(self._aj, self.nv, 0)], quaternions=quaternion_offsets(js))
        self.set(t=model.t0, p=model.p0)

    def copy(self) -> "JointDynamicsKernel":
        """The same compiled kernel with buffers (and time, parameters) of its own."""
        k = JointDynamicsKernel(self.model, self.direct.copy(), self.method)
        k.set(t=float(self.direct.inputs[0][0]), p=self._p)
        return k

    def __call__(self, qj, vj, u=None) -> np.ndarray:
        fast = self._fast
        if fast is not None:
            try:
                out = fast(qj, vj, self._zero_u if u is None else u)
            except (TypeError, ValueError):
                self._bad_sizes(qj, vj, u)
            if out is None:
                self._singular()
            return out
        if len(qj) != self.nq or len(vj) != self.nv or (u is not None and len(u) != self.nu):
            self._bad_sizes(qj, vj, u)
        self._qj[...] = qj
        self._vj[...] = vj
        self._u[...] = 0.0 if u is None else u
        check = self._check
        if self._fn(*self._args) or not (check[0] > PIVOT_TOL and check[1] - check[1] == 0.0):
            self._singular()
        return self._aj

    def _bad_sizes(self, qj, vj, u):
        for name, x in (("qj", qj), ("vj", vj), ("u", u)):
            if x is not None:
                as_numbers(x, f"joint forward dynamics: {name}", "a sequence of numbers")
        sizes = [np.size(qj), np.size(vj), self.nu if u is None else np.size(u)]
        if sizes == [self.nq, self.nv, self.nu]:
            raise ModelError("joint forward dynamics: qj, vj and u must be sequences of numbers")
        raise ModelError(f"joint forward dynamics: expected qj of {self.nq}, vj of {self.nv} and u of "
                         f"{self.nu} values; got {len(qj)}, {len(vj)} and {'None' if u is None else len(u)}")

    def _singular(self):
        if np.isfinite(self._check[0]) and not self._check[0] > PIVOT_TOL:
            raise ModelError(f"joint forward dynamics: the joint-space mass matrix is singular at this state "
                             f"(smallest relative Cholesky pivot {self._check[0]:.3g}: a motion without inertia)")
        raise ModelError("joint forward dynamics: the accelerations are not finite (non-finite qj, vj or u?)")


def joint_forward_dynamics_kernel(model, *, method: str = "auto", cflags=None) -> JointDynamicsKernel:
    """The compiled joint-space forward dynamics of the tree ``model`` (built once per model
    and method; the library is cached by content; ``cflags`` as for
    :func:`~ncgen.codegen.compile_cache.compile_package`, by default -O2, or -O1 up to
    :data:`~ncgen.codegen.tree_check.O1_INSTRUCTIONS` and the package's large-source flags (-O1)
    beyond for long kernels).  ``method``: ``"recursive"`` (3D),
    ``"projection"`` (``M_j = Gᵀ M G`` by AD of the tree map) or ``"auto"`` (recursive in
    3D when every member is a rigid body, else projection).  Raises :class:`ModelError` for
    a model that is not a tree (:func:`check_tree`)."""
    from ncgen.assembly.tree_dynamics import mimic_relations, recursive_dynamics_function, tree_dynamics_function

    if method not in METHODS:
        raise ModelError(f"joint_forward_dynamics_kernel: method: expected one of {', '.join(METHODS)}, got {method!r}")

    def build() -> JointDynamicsKernel:
        check_tree(model)
        if mimic_relations(model) and (method == "projection" or model.joint_space.dim != 3):
            raise ModelError("joint_forward_dynamics_kernel: mimic joints need the recursive form "
                             "(method='recursive' or 'auto', 3D models)")
        if method == "projection" or (method == "auto" and model.joint_space.dim != 3):
            f, used = tree_dynamics_function(model), "projection"
        else:
            try:
                f, used = recursive_dynamics_function(model), "recursive"
            except ModelError:
                if method == "recursive" or mimic_relations(model):
                    raise
                f, used = tree_dynamics_function(model), "projection"
        return JointDynamicsKernel(model, compile_tree_function(model, f, cflags, "jfd_tree"), used)

    return cached(model_data(model).tree_kernels, (method, cflags), build)


def joint_forward_dynamics(model, qj, vj, u=None, p=None, t: float = 0.0, *, backend: str = "compiled",
                           out=None) -> np.ndarray:
    """Joint accelerations ``a_j`` (``model.joint_names`` order; a free base: ``[a, α]`` in
    its frame) at joint positions ``qj`` and rates ``vj`` with inputs ``u`` (default zero)
    and parameters ``p`` (default ``model.p0``).  ``backend="compiled"``: the kernel of
    :func:`joint_forward_dynamics_kernel` for trees, mimic joints included (built on first
    use), else the ``"numpy"`` path: ``from_joint_space``, the KKT solve of
    :func:`~ncgen.runtime.dynamics_at_state.forward_dynamics`, ``to_joint_space``.
    ``out``: an array of ``nv`` values written and returned (float64, C-contiguous)."""
    try:
        k = model._data.tree_kernel
    except AttributeError:                  # not a model: model_data names what it is
        k = model_data(model).tree_kernel
    if backend == "compiled" and k and k._door is not None:
        k._at(t, p)                 # arguments straight to C, checked there; the messages below only on failure
        try:
            a = k._door(qj, vj, k._zero_u if u is None else u, out)
        except (TypeError, ValueError, OverflowError):
            a = False
        if a is None:
            k._singular()
        if a is not False:
            return a
    if backend not in ("compiled", "numpy"):
        raise ModelError(f"joint_forward_dynamics: backend: expected 'compiled' or 'numpy', got {backend!r}")
    js = model.joint_space
    qj = as_vector(qj, js.nq, "qj (joint positions, joint_names order)")
    vj = as_vector(vj, js.nv, "vj (joint rates, joint_names order)")
    u = np.zeros(model.nu) if u is None else as_vector(u, model.nu, "u (model.input_names order)")
    p = model.p0 if p is None else as_vector(p, model.np, "p")
    qj = unit_quaternions(js, qj)
    if backend == "compiled":
        data = model_data(model)
        if data.tree_kernel is None:
            try:
                data.tree_kernel = joint_forward_dynamics_kernel(model).copy()
            except ModelError:
                data.tree_kernel = False
        k = data.tree_kernel
        if k:
            k.set(t=t, p=p)
            a = k(qj, vj, u).copy()
            return a if out is None else write_out(out, a, "joint_forward_dynamics")
    q, v = model.from_joint_space(qj, vj, t=t, p=p)
    a, _ = forward_dynamics(model, q, v, u=u, p=p, t=t)
    a = model.to_joint_space(q, v, a)[2]
    return a if out is None else write_out(out, a, "joint_forward_dynamics")
