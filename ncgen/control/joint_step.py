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

It is time-invariant; :func:`ncgen.control.ilqr.ilqr` takes it as it takes a natural-coordinate
step (Gauss–Newton: no second derivatives of this step; the parameters are those given here).

Only trees whose joint positions add (``q⁺ = q + h v``: hinges and slides, no quaternion) and
whose every rate is independent (no mimic joint) take it; others are refused by name.
"""
from __future__ import annotations

import numpy as np

from ncgen.control.step import StepFunction
from ncgen.errors import NcgenError
from ncgen.runtime.tree_algorithm_kernels import aba, aba_derivatives, buffers, kernel_of
from ncgen.validation import as_vector, positive


def joint_step_refusal(model) -> str | None:
    """Why ``model`` has no joint-space step of this module, or None."""
    js = getattr(model, "joint_space", None)
    if js is None:
        return f"model {model.name!r} has no joint space (not a tree of joints)"
    if js.nq != js.nv:
        return (f"model {model.name!r}: joint positions do not add (nq = {js.nq} ≠ nv = {js.nv}: "
                f"a quaternion joint); the step q⁺ = q + h v needs hinges and slides only")
    return None


class JointStep:
    """``x⁺ = step(x, τ)`` and ``(x⁺, A, B) = step.jacobians(x, τ)`` (module docstring) of
    ``model`` with the step ``h`` (s) and parameters ``p`` (None: the model's)."""

    #: iLQR runs Gauss–Newton on this step (:func:`ncgen.control.ilqr.ilqr`).
    second_derivatives = False

    def __init__(self, model, h: float, *, p=None):
        why = joint_step_refusal(model)
        if why is not None:
            raise NcgenError(f"JointStep: {why}")
        self.model, self.h, self.p = model, positive(h, "JointStep: h (the step, s)"), p
        self.n = model.joint_space.nv
        a, *_ = aba_derivatives(model, np.zeros(self.n), np.zeros(self.n), np.zeros(self.n), p=p)
        if a.shape != (self.n,):
            raise NcgenError(f"JointStep: model {model.name!r} has dependent joint rates (a mimic joint: "
                             f"{a.shape[0]} independent of {self.n}); lock or remove the follower joints")
        self.nx, self.nu = 2 * self.n, self.n
        n, h = self.n, self.h
        self._derivatives = kernel_of(model, "aba_derivatives", "auto")
        self._A0 = np.block([[np.eye(n), h * np.eye(n)], [np.zeros((n, n)), np.eye(n)]])

    def _split(self, x, tau):
        """``x, tau`` as float vectors of the right sizes (float64 vectors of those sizes pass
        as they are; their values are checked by the kernel in C)."""
        if not (type(x) is np.ndarray and x.dtype == np.float64 and x.shape == (self.nx,)):
            x = as_vector(x, self.nx, "x (joint positions and rates [q_j; v_j])")
        if not (type(tau) is np.ndarray and tau.dtype == np.float64 and tau.shape == (self.nu,)):
            tau = as_vector(tau, self.nu, "tau (efforts of the joint rates)")
        return x, tau

    def _same(self, p, what: str) -> None:
        if p is not None:
            raise NcgenError(f"JointStep.{what}: p: the parameters are fixed when the step is made "
                             f"(JointStep(model, h, p=...)); got p = {p!r}")

    def __call__(self, x, tau, p=None, t=None) -> np.ndarray:
        """``x⁺`` (``t``, s, is ignored: the step is time-invariant)."""
        self._same(p, "__call__")
        return self.unchecked(*self._split(x, tau))

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

    def unchecked(self, x: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """``x⁺`` of a float vector ``x`` and ``tau`` of the right sizes, unchecked (by ABA
        alone, without its derivatives)."""
        n, h = self.n, self.h
        v1 = x[n:] + h * aba(self.model, x[:n], x[n:], tau, p=self.p)
        return np.concatenate([x[:n] + h * v1, v1])

    def jacobians(self, x, tau, p=None, t=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(x⁺, A = ∂x⁺/∂x, B = ∂x⁺/∂τ)`` at ``(x, τ)`` (``t`` ignored)."""
        self._same(p, "jacobians")
        return self.unchecked_jacobians(*self._split(x, tau))

    def unchecked_jacobians(self, x: np.ndarray, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`jacobians` of a float vector ``x`` and ``tau`` of the right sizes, unchecked
        (the MPC's rollout; the kernel still refuses values that are not finite)."""
        h, n = self.h, self.n
        a, da_dq, da_dv, Minv = buffers(self.model, self._derivatives, (x[:n], x[n:], tau), self.p, 0.0)
        x1, A, B = np.empty(2 * n), np.empty((2 * n, 2 * n)), np.empty((2 * n, n))
        np.multiply(a, h, out=x1[n:])       # the kernel's buffers read once, written into the results
        x1[n:] += x[n:]                     # v⁺
        np.multiply(x1[n:], h, out=x1[:n])
        x1[:n] += x[:n]                     # q⁺
        Av, Bv = A[n:], B[n:]
        np.multiply(da_dq, h, out=Av[:, :n])
        np.multiply(da_dv, h, out=Av[:, n:])    # ∂v⁺/∂x − [0, I]
        np.multiply(Av, h, out=A[:n])
        A += self._A0
        np.multiply(Minv, h, out=Bv)
        np.multiply(Bv, h, out=B[:n])
        return x1, A, B
