"""Linear algebra shared by statics, modes and linearisation: a null-space basis of the
constraint Jacobian, the reduced tangent stiffness and its classification, and points of
the constraint manifold in a local chart.

Convention: ``N`` (nq × dof) is an orthonormal basis of ``null A(q)`` (``A N = 0``,
``Nᵀ N = I``) from the SVD of ``A``, each column's largest entry made positive so that the
basis is reproducible; the independent coordinates are ``z = Nᵀ (q − q*)`` unless the
user gives other ones (``G``, dof × nq, with ``G N`` invertible: then ``N ← N (G N)⁻¹``).
"""
from __future__ import annotations

import weakref
from typing import Callable

import numpy as np

from ncgen.errors import NcgenError

#: Singular values of A below this times the largest one count as zero.
RANK_TOL = 1e-10
#: Eigenvalues of the reduced stiffness within this times its largest |eigenvalue| are zero.
ZERO_TOL = 1e-8

_CACHE: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def cached(model, key: str, make: Callable):
    """``make()`` once per model and key (CasADi functions built on demand)."""
    store = _CACHE.setdefault(model, {})
    if key not in store:
        store[key] = make()
    return store[key]


def null_basis(A: np.ndarray, nq: int, tol: float = RANK_TOL) -> np.ndarray:
    """Orthonormal basis of ``null A`` (nq × dof), columns signed reproducibly; singular
    values below ``tol`` × the largest count as zero."""
    A = np.asarray(A, float).reshape(-1, nq)
    if A.shape[0] == 0:
        return np.eye(nq)
    _, s, Vt = np.linalg.svd(A)
    rank = int(np.sum(s > tol * max(s.max(), 1e-300))) if s.size else 0
    N = Vt[rank:].T.copy()
    for j in range(N.shape[1]):
        i = int(np.argmax(np.abs(N[:, j])))
        if N[i, j] < 0:
            N[:, j] = -N[:, j]
    return N


def coordinate_basis(A: np.ndarray, nq: int, G=None) -> tuple[np.ndarray, np.ndarray]:
    """``(N, G)``: a tangent basis and the independent coordinates' functional, ``A N = 0``,
    ``G N = I``.  ``G=None``: ``N`` orthonormal, ``G = Nᵀ``."""
    N = null_basis(A, nq)
    if G is None:
        return N, N.T.copy()
    G = np.asarray(G, float)
    if G.shape != (N.shape[1], nq):
        raise NcgenError(f"coordinates: expected a {N.shape[1]} × {nq} matrix (one row per degree of "
                         f"freedom, one column per natural coordinate), got shape {G.shape}")
    GN = G @ N
    if np.linalg.matrix_rank(GN) < N.shape[1]:
        raise NcgenError("coordinates: the rows of G do not determine the configuration "
                         "(G N is singular: some motion allowed by the constraints leaves them unchanged)")
    return N @ np.linalg.inv(GN), G


def classify(eigenvalues: np.ndarray, scale: float = 0.0) -> tuple[str, int, int]:
    """``(stability, n_zero, n_negative)`` of a symmetric matrix with these eigenvalues:
    ``"stable"`` (positive definite), ``"neutral"`` (positive semi-definite, singular) or
    ``"unstable"`` (a negative eigenvalue)."""
    ev = np.asarray(eigenvalues, float)
    if ev.size == 0:
        return "stable", 0, 0
    tol = ZERO_TOL * max(np.abs(ev).max(), scale)
    n_neg = int(np.sum(ev < -tol))
    n_zero = int(np.sum(np.abs(ev) <= tol))
    return ("unstable" if n_neg else "neutral" if n_zero else "stable"), n_zero, n_neg


def manifold_point(phi: Callable, jac: Callable, q_ref: np.ndarray, N: np.ndarray, G: np.ndarray,
                   z: np.ndarray, *, tol: float = 1e-13, max_iter: int = 30) -> np.ndarray:
    """The configuration ``q`` with ``Φ(q) = 0`` and ``G (q − q_ref) = z`` (Newton from
    ``q_ref + N z``): the point of independent coordinates ``z`` in the chart at ``q_ref``."""
    q = q_ref + N @ z
    size = max(1.0, float(np.abs(q_ref).max()) if q_ref.size else 1.0)
    for _ in range(max_iter):
        r = np.concatenate([phi(q), G @ (q - q_ref) - z])
        if np.abs(r).max() <= tol * size**2:
            return q
        J = np.vstack([jac(q), G])
        q = q - np.linalg.lstsq(J, r, rcond=None)[0]
    raise NcgenError(f"no configuration with independent coordinates z = {np.round(z, 6)} near the "
                     "reference: the perturbation is too large for the chart")


def tangent_velocity(A: np.ndarray, G: np.ndarray, w: np.ndarray, phi_t=None) -> np.ndarray:
    """The rates ``v`` with ``A v + Φ_t = 0`` and ``G v = w``."""
    nc = A.shape[0]
    rhs = np.concatenate([np.zeros(nc) if phi_t is None else -np.asarray(phi_t, float), w])
    return np.linalg.lstsq(np.vstack([A, G]), rhs, rcond=None)[0]
