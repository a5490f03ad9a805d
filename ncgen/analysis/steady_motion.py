"""Linearisation of a rolling system about a steady motion, in chosen coordinates.

A steady motion (relative equilibrium) moves the system along its symmetries: rigid
translations along the plane (shifts of the points' coordinates) and spins of axisymmetric
wheels about their axles (linear maps of the natural coordinates).  With ``x = [q; v]``, the reference is
``x(t) = (G(t) q₀ + t T, G(t) v₀)``, ``G(t) = exp(t K)`` (``K``: the spins' generator,
``T``: the translation velocity), so ``v₀ = T + K q₀`` and ``a(q₀, v₀) = K² q₀``.  Writing a
perturbation as ``δx = diag(G, G) ξ`` gives the time-invariant ``ξ̇ = (J − diag(K, K)) ξ``,
``J = ∂[v; a]/∂x`` at ``x₀``, on the tangent space of the constraint manifold.

Chosen coordinates ``y(q)`` invariant under the symmetries (a lean, a steer angle) obey
on that space closed equations ``M ÿ + C ẏ + K y = f``, where ``f`` is the generalised
force conjugate to ``y`` (the natural-coordinate force ``(∂y/∂q)ᵀ f``).  They are found
from the state matrix of ``[y; ẏ]`` (``ẏ = y_q v``) restricted to the tangent space, and
``M⁻¹ = ∂ÿ/∂f``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import null_space

from ncgen.assembly.manifold import RANK_TOL
from ncgen.errors import ModelError, NcgenError


@dataclass(frozen=True)
class SecondOrder:
    """``M ÿ + C ẏ + K y = f`` about a steady motion, and how well its premises held:
    ``closure`` (largest residual of the closed equations of ``[y; ẏ]`` on the tangent
    space, relative), ``reference`` (``|a(q₀, v₀) − K_spin² q₀|∞``, m/s²) and
    ``constraints`` (``|Φ̂(q₀)|∞``, ``|Â(q₀) v₀|∞``)."""
    M: np.ndarray
    C: np.ndarray
    K: np.ndarray
    closure: float
    reference: float
    constraints: tuple[float, float]

    def state_matrix(self) -> np.ndarray:
        """``d/dt [y; ẏ] = S [y; ẏ]`` with ``f = 0``."""
        m = self.M.shape[0]
        Mi = np.linalg.inv(self.M)
        return np.block([[np.zeros((m, m)), np.eye(m)], [-Mi @ self.K, -Mi @ self.C]])

    def eigenvalues(self) -> np.ndarray:
        """Eigenvalues of :meth:`state_matrix` (1/s), sorted by real part then imaginary part."""
        lam = np.linalg.eigvals(self.state_matrix())
        return lam[np.lexsort((lam.imag, lam.real))]


def _tangent_basis(G: np.ndarray, n_holonomic: int, nq: int) -> np.ndarray:
    """A basis of the null space of ``G = [[Φ̂_q, 0], [D, Â]]`` (the Jacobian of ``[Φ̂; Â v]``
    by ``[q; v]``): ``δq`` in the null space of ``Φ̂_q``, ``δv = −Â⁺ D δq`` plus the null
    space of ``Â`` (two small decompositions instead of one of twice the size)."""
    Nq = null_space(G[:n_holonomic, :nq], rcond=RANK_TOL)
    D, A = G[n_holonomic:, :nq], G[n_holonomic:, nq:]
    Nv = null_space(A, rcond=RANK_TOL)
    dv = -np.linalg.lstsq(A, D @ Nq, rcond=None)[0]
    return np.block([[Nq, np.zeros((nq, Nv.shape[1]))], [dv, Nv]])


def linearize_steady(system, q0, v0, K_spin, coordinates, tol: float = 1e-8) -> SecondOrder:
    """:class:`SecondOrder` equations of ``coordinates`` (from
    :func:`ncgen.assembly.nonholonomic.coordinate_function`)
    about the steady motion of ``system`` (:class:`ncgen.assembly.nonholonomic.RollingSystem`)
    through ``(q0, v0)``, whose spins have the generator ``K_spin`` (nq × nq).  Raises when
    the state is off the constraints or not a steady motion (beyond ``tol``, relative) or the
    coordinates' equations are not closed, or an element's plane moves."""
    if getattr(system, "driven", False):
        raise NcgenError("linearize_steady: the model has drives (time-dependent constraints); steady motions "
                         "are taken about scleronomic models only")
    if getattr(system, "rheonomic", False):
        raise NcgenError("linearize_steady: the system has elements on a moving plane (plane_velocity); steady "
                         "motions are linearised on a plane at rest only")
    nq = system.nq
    q0, v0 = np.asarray(q0, float), np.asarray(v0, float)
    K_spin = np.asarray(K_spin, float)
    zero = np.zeros(nq)
    J, a_f = (np.asarray(x) for x in system.jacobians(q0, v0, zero))
    a0 = np.asarray(system.accel(q0, v0, zero)[0]).ravel()
    reference = float(np.max(np.abs(a0 - K_spin @ (K_spin @ q0))))
    constraints = system.residuals(q0, v0)
    if max(constraints) > tol * max(1.0, np.max(np.abs(q0)), np.max(np.abs(v0))):
        raise NcgenError(f"linearize_steady: the reference state is off the constraints (|Φ̂| = "
                         f"{constraints[0]:.3g}, |Â v| = {constraints[1]:.3g}); give a consistent (q0, v0)")
    if reference > tol * max(1.0, np.max(np.abs(a0))):
        raise NcgenError(f"linearize_steady: (q0, v0) is not a steady motion of these spins: "
                         f"|a(q0, v0) − K_spin² q0| = {reference:.3g} m/s²")
    Jc = J - np.kron(np.eye(2), K_spin)
    N = _tangent_basis(np.asarray(system.tangent(q0, v0)), system.n_holonomic, nq)
    _, Yq, Y = (np.asarray(x) for x in coordinates(q0, v0))
    m = Yq.shape[0]
    YN = Y @ N
    if np.linalg.matrix_rank(YN, tol=RANK_TOL * np.linalg.norm(YN)) < 2 * m:
        raise NcgenError(f"linearize_steady: the {m} coordinates and their rates are not independent "
                         "on the constraint manifold at this state; choose other coordinates")
    rates = Y @ Jc @ N
    S = rates @ np.linalg.pinv(YN)
    closure = float(np.max(np.abs(rates - S @ YN)) / max(1.0, np.max(np.abs(rates))))
    if closure > tol:
        raise NcgenError(f"linearize_steady: the {m} coordinates do not obey closed equations about "
                         f"this motion (residual {closure:.3g}); add the coordinates they couple to")
    M = np.linalg.inv(Yq @ a_f @ Yq.T)
    return SecondOrder(M=M, C=-M @ S[m:, m:], K=-M @ S[m:, :m], closure=closure, reference=reference,
                       constraints=constraints)


def spin_generator(model, body: str, axle) -> np.ndarray:
    """``K`` (nq × nq): the rate of the natural coordinates when ``body`` (coordinates
    ``ruvw``) spins at 1 rad/s about ``axle`` (body axes) through its centre of mass,
    everything else still; linear in q, so ``K q`` is that velocity at any q."""
    idx = model.layout.member_indices(body)
    if len(idx) != 12 or any(i is None for i in idx):
        raise ModelError(f"spin_generator: body {body!r}: expected a body with its own 12 "
                         "coordinates (ruvw)")
    R0, p0 = (np.asarray(x) for x in model.functions["poses"](model.q0))
    k = model.member_names.index(body)
    R0, p0 = R0[:, 3 * k:3 * k + 3], p0[:, k]
    q = model.q0[idx]
    Xbar = R0.T @ q[3:].reshape(3, 3, order="F")
    rbar = R0.T @ (q[:3] - p0)
    a = np.asarray(axle, float) / np.linalg.norm(axle)
    hat = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    Xi = np.linalg.inv(Xbar)
    G, g_r = Xi @ hat @ Xbar, Xi @ hat @ rbar
    K = np.zeros((model.nq, model.nq))
    I3 = np.eye(3)
    for j in range(3):
        cols = idx[3 + 3 * j:6 + 3 * j]
        K[np.ix_(idx[:3], cols)] = g_r[j] * I3
        for m in range(3):
            K[np.ix_(idx[3 + 3 * m:6 + 3 * m], cols)] = G[j, m] * I3
    return K


def translation_rate(model, direction) -> np.ndarray:
    """The natural coordinates' rate when every member translates at unit velocity along
    ``direction`` (points move, vectors do not)."""
    d = np.asarray(direction, float)
    rate = np.zeros(model.nq)
    for i, name in enumerate(model.coordinate_names):
        _, slot, axis = name.rsplit(".", 2)
        if slot.startswith("r"):
            rate[i] = d["xyz".index(axis)]
    return rate
