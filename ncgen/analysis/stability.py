"""Stability of an equilibrium from the eigenvalues of its reduced tangent stiffness
(:func:`classify`), and the model's analysis functions built once (:func:`cached`).

The null-space basis, charts and tangent velocities are in :mod:`ncgen.assembly.manifold`.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from ncgen.model.data import model_data

#: Eigenvalues of the reduced stiffness within this times its largest |eigenvalue| are zero.
ZERO_TOL = 1e-8


def cached(model, key: str, make: Callable):
    """``make()`` once per model and key (CasADi functions built on demand, kept in
    ``model.data.functions``)."""
    store = model_data(model).functions
    if key not in store:
        store[key] = make()
    return store[key]


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


