"""ncgen.reproducible: CPU-independent small linear algebra, and the exact constants it gives
the model (no round-off terms, no spurious nonzeros in A)."""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.reproducible import dot, inv, matmul, matvec, norm, snap

ROOT = Path(__file__).resolve().parent.parent


def test_agrees_with_numpy_on_random_input():
    rng = np.random.default_rng(7)
    for n in (1, 2, 3, 4):
        A, B, x = rng.normal(size=(n, n)), rng.normal(size=(n, 3)), rng.normal(size=n)
        assert dot(x, x) == pytest.approx(float(x @ x), rel=1e-14)
        assert norm(x) == pytest.approx(float(np.linalg.norm(x)), rel=1e-14)
        np.testing.assert_allclose(matvec(A, x), A @ x, rtol=1e-13, atol=1e-14)
        np.testing.assert_allclose(matmul(A, B), A @ B, rtol=1e-13, atol=1e-14)
        np.testing.assert_allclose(inv(A) @ A, np.eye(n), atol=1e-12)


def test_sums_are_correctly_rounded():
    # A summation order that BLAS may use loses the 1 entirely; fsum does not.
    assert dot([1e16, 1.0, -1e16], [1.0, 1.0, 1.0]) == 1.0
    assert norm([3.0, 4.0]) == 5.0


def test_inverse_of_a_singular_matrix_is_refused():
    with pytest.raises(ValueError, match="singular"):
        inv([[1.0, 2.0], [2.0, 4.0]])
    with pytest.raises(ValueError, match="square"):
        inv(np.ones((2, 3)))


def test_snap_makes_near_integers_exact():
    out = snap([1.3877787807814457e-17, 0.9999999999999999, 0.5, -2.0000000000001, -0.0, 1e-9])
    assert out.tolist() == [0.0, 1.0, 0.5, -2.0, 0.0, 1e-9]
    assert not np.signbit(out[4])


def test_joint_at_a_basic_point_touches_only_that_point():
    """The rocker hinge of the 3D four-bar is at the rocker's basic point r_i: its three
    coincidence equations involve r_i alone, with coefficient exactly 1 (round-off in the
    local coordinates used to add 1e-17 r_j terms, extra nonzeros of A and instructions)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = nc.System.from_toml(ROOT / "examples" / "fourbar_3d.toml").build(share=False)   # the hinge as equations
    A = np.array(model.functions["A"](0.0, model.q0, model.p0).full())
    sp = model.functions["A"].sparsity_out(0)
    rows = [i for i, name in enumerate(model.constraint_names) if name.startswith("rocker_hinge.coincide")]
    assert len(rows) == 3
    for i in rows:
        cols = [model.coordinate_names[j] for j in range(model.nq) if sp.has_nz(i, j)]
        assert all(c.startswith("rocker.r_i.") for c in cols), (model.constraint_names[i], cols)
        assert sorted(np.abs(A[i, [model.coordinate_names.index(c) for c in cols]])) == [1.0]

