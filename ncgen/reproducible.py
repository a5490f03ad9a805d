"""Small dense linear algebra whose results are the same on every CPU.

NumPy's ``@``, ``dot`` and ``linalg.norm``/``inv`` call BLAS and LAPACK, whose kernels are
chosen at run time for the CPU (AVX2, AVX-512, ...) and sum in different orders: the same
model then gave constants differing in the last bit on different machines, and since a
constant that should be 0 or 1 but is off by 1e-17 adds terms to an expression, the
generated C differed in structure too.  Every number that becomes a constant of a model's
functions (local coordinates of joint points and directions, bar lengths, local frames)
is computed with these instead: plain IEEE products and correctly rounded sums
(:func:`math.fsum`), so the kernels of a generated package do not depend on the CPU's BLAS.
(The consistent initial state stored as metadata still comes from sparse solves and may
differ in its last bits.)
"""
from __future__ import annotations

import math

import numpy as np

#: Affine coordinates within this of an integer are that integer (:func:`snap`).
SNAP_TOL = 1e-12


def dot(a, b) -> float:
    """``aᵀ b``, correctly rounded sum of the products."""
    return math.fsum(float(x) * float(y) for x, y in zip(np.ravel(a), np.ravel(b), strict=True))


def norm(a) -> float:
    """Euclidean norm ``|a|``."""
    return math.sqrt(math.fsum(float(x) * float(x) for x in np.ravel(a)))


def matvec(A, x) -> np.ndarray:
    """``A x`` for a 2-D ``A``."""
    A = np.asarray(A, dtype=float)
    return np.array([dot(row, x) for row in A], dtype=float).reshape(A.shape[0])


def matmul(A, B) -> np.ndarray:
    """``A B`` for 2-D ``A`` and ``B``."""
    A, B = np.asarray(A, dtype=float), np.asarray(B, dtype=float)
    return np.array([[dot(row, col) for col in B.T] for row in A], dtype=float).reshape(A.shape[0], B.shape[1])


def inv(A) -> np.ndarray:
    """Inverse of a small non-singular square matrix (Gauss–Jordan, partial pivoting, in
    Python floats).  Raises ``ValueError`` for a singular matrix."""
    A = np.asarray(A, dtype=float)
    n = A.shape[0]
    if A.shape != (n, n):
        raise ValueError(f"inv: expected a square matrix, got shape {A.shape}")
    aug = [[float(A[i, j]) for j in range(n)] + [1.0 if i == j else 0.0 for j in range(n)] for i in range(n)]
    for k in range(n):
        piv = max(range(k, n), key=lambda i: abs(aug[i][k]))
        if aug[piv][k] == 0.0:
            raise ValueError("inv: the matrix is singular")
        aug[k], aug[piv] = aug[piv], aug[k]
        pivot = aug[k][k]
        aug[k] = [x / pivot for x in aug[k]]
        for i in range(n):
            if i != k and aug[i][k] != 0.0:
                f = aug[i][k]
                aug[i] = [x - f * y for x, y in zip(aug[i], aug[k])]
    return np.array([row[n:] for row in aug], dtype=float).reshape(n, n)


def cholesky(A) -> np.ndarray:
    """The lower triangular ``L`` with ``L Lᵀ = A`` of a symmetric positive definite matrix
    (in Python floats, correctly rounded sums: an entry that a banded ``A`` leaves zero is
    exactly 0).  Raises ``ValueError`` where ``A`` is not positive definite."""
    A = np.asarray(A, dtype=float)
    n = A.shape[0]
    if A.shape != (n, n):
        raise ValueError(f"cholesky: expected a square matrix, got shape {A.shape}")
    L = np.zeros((n, n))
    for j in range(n):
        d = float(A[j, j]) - math.fsum(float(x) * float(x) for x in L[j, :j])
        if not d > 0:
            raise ValueError("cholesky: the matrix is not positive definite")
        L[j, j] = math.sqrt(d)
        for i in range(j + 1, n):
            L[i, j] = (float(A[i, j]) - math.fsum(float(x) * float(y) for x, y in zip(L[i, :j], L[j, :j]))) / L[j, j]
    return L


def snap(c, tol: float = SNAP_TOL) -> np.ndarray:
    """``c`` with every entry within ``tol`` of an integer replaced by that integer.

    For affine coordinates (dimensionless): a joint placed at a basic point or along a
    base vector gets exactly ``c = 0`` or ``1``, so its equations carry no round-off terms
    (and no spurious nonzeros in ``A``)."""
    c = np.array(c, dtype=float)
    r = np.round(c)
    return np.where(np.abs(c - r) <= tol, r, c) + 0.0


def perpendicular_basis(axis, *, unit: bool = False) -> list[np.ndarray]:
    """Unit vectors ``n`` completing ``a = axis/|axis|`` to a right-handed orthonormal basis:
    ``[n1]`` in 2D (``(a, n1)`` right-handed), ``[n1, a × n1]`` in 3D.  ``unit=True``: ``axis``
    is taken as unit already (not normalised again, so no round-off is added)."""
    a = np.asarray(axis, float)
    if not unit:
        a = a / norm(a)
    if len(a) == 2:
        return [np.array([-a[1], a[0]])]
    helper = np.eye(3)[int(np.argmin(np.abs(a)))]
    n1 = np.cross(a, helper)
    n1 /= norm(n1)
    return [n1, np.cross(a, n1)]


def frame_along(e1) -> np.ndarray:
    """A rotation matrix whose first column is the unit vector ``e1`` (columns ``e1``,
    ``n1`` in 2D; ``e1``, ``−(e1 × n1)``, ``n1`` in 3D, with ``n1`` of
    :func:`perpendicular_basis`)."""
    e1 = np.asarray(e1, float)
    n = perpendicular_basis(e1, unit=True)
    if len(e1) == 2:
        return np.column_stack([e1, n[0]])
    return np.column_stack([e1, -n[1], n[0]])
