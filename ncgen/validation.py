"""Argument checks shared by every layer: shapes, finiteness, rotations.

Each check returns a clean float array and raises a :mod:`ncgen.errors` exception whose
message names the argument (``what``), what was expected and what was found.
"""
from __future__ import annotations

import math
import warnings

import numpy as np

from ncgen.errors import InertiaError, RotationError, ShapeError

ROTATION_TOL = 1e-9
#: Largest |RᵀR − 1| of a matrix accepted as a rotation given with printed precision (copied
#: from a paper or another tool, ~6 digits); it is projected to the nearest rotation.
PRINTED_ROTATION_TOL = 1e-5


class RotationProjected(UserWarning):
    """A rotation given with printed precision was replaced by the nearest rotation."""


def _shape_of(x) -> str:
    try:
        return "shape " + str(np.shape(x))
    except Exception:  # ragged input
        return f"{type(x).__name__} {x!r}"


def as_array(x, shape: tuple, what: str) -> np.ndarray:
    """``x`` as a finite float array of exactly ``shape``."""
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise ShapeError(f"{what}: expected numbers of shape {shape}, got {_shape_of(x)}") from None
    if a.shape != tuple(shape):
        if len(shape) == 1:
            raise ShapeError(f"{what}: expected {shape[0]} numbers, got {_describe(a)}")
        raise ShapeError(f"{what}: expected shape {tuple(shape)}, got {_describe(a)}")
    if not np.all(np.isfinite(a)):
        raise ShapeError(f"{what}: expected finite numbers, got {a.tolist()}")
    return a


def _describe(a: np.ndarray) -> str:
    if a.ndim == 1:
        return f"{a.shape[0]}"
    if a.ndim == 0:
        return "a scalar"
    return f"shape {a.shape}"


def as_vector(x, n: int, what: str) -> np.ndarray:
    return as_array(x, (n,), what)


def as_scalar(x, what: str) -> float:
    try:
        v = float(np.asarray(x, dtype=float).reshape(()))
    except (TypeError, ValueError):
        raise ShapeError(f"{what}: expected a number, got {x!r}") from None
    if not np.isfinite(v):
        raise ShapeError(f"{what}: expected a finite number, got {v}")
    return v


def positive(x, what: str) -> float:
    v = as_scalar(x, what)
    if v <= 0:
        raise InertiaError(f"{what}: expected a positive number, got {v}")
    return v


def rotation(R, dim: int, what: str = "rotation") -> np.ndarray:
    """A proper rotation matrix (``RᵀR = 1``, ``det R = +1`` to 1e-9); in 2D an angle is accepted."""
    if dim == 2 and np.ndim(R) == 0:
        a = as_scalar(R, what)
        c, s = math.cos(a), math.sin(a)        # libm, not NumPy's CPU-dependent SIMD loops
        return np.array([[c, -s], [s, c]])
    R = as_array(R, (dim, dim), what)
    err = np.max(np.abs(R.T @ R - np.eye(dim)))
    if err > PRINTED_ROTATION_TOL:
        raise RotationError(f"{what}: expected an orthonormal matrix, |RᵀR - 1| = {err:.3g} "
                            f"(up to {PRINTED_ROTATION_TOL:g} is projected to the nearest rotation)")
    det = np.linalg.det(R)
    if det < 0:
        raise RotationError(f"{what}: expected det = +1 (a proper rotation), got det = {det:.6g} (a reflection)")
    if err > ROTATION_TOL:
        U, _, Vt = np.linalg.svd(R)
        P = U @ Vt                                # the nearest rotation (polar factor), det +1 here
        warnings.warn(f"{what}: |RᵀR - 1| = {err:.3g}: projected to the nearest rotation "
                      f"(largest change of an entry {np.max(np.abs(P - R)):.3g})", RotationProjected, stacklevel=3)
        return P
    return R
