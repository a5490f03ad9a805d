"""Coordinate types against the seed: Y, C(c), Φ, Φ_q, Hessians, counts and bad input."""
import numpy as np
import pytest
import sympy as sp

from natural_helpers import ALL_TYPES, IDS, SEED_YBAR, YBAR, random_member, seed_phi
from ncgen.errors import CoordinateTypeError, NcgenError
from ncgen.symbolic.coordinates import available_types, coordinate_type


def _kron_I(Ybar, d):
    return np.kron(np.array(Ybar, dtype=float), np.eye(d))


def test_every_type_is_covered():
    assert set(YBAR) == set(ALL_TYPES)
    assert len(SEED_YBAR) == 6          # the seed prints 4 body and 2 bar matrices
    assert available_types(2) == [(2, n) for n in ("ruv", "rrv", "rrr", "ru", "rr", "r")]


@pytest.mark.parametrize("dim,name", ALL_TYPES, ids=IDS)
def test_counts_match_the_seed_table(dim, name):
    ct = coordinate_type(name, dim)
    # seed table: 3D body 12 coordinates / 6 constraints / 6 DOF, 3D bar 6 / 1 / 5;
    # planar analogues: body 6 / 3 / 3, bar 4 / 1 / 3; a point has dim coordinates, no constraint
    expected = {("body", 3): (12, 6, 6), ("bar", 3): (6, 1, 5), ("point", 3): (3, 0, 3),
                ("body", 2): (6, 3, 3), ("bar", 2): (4, 1, 3), ("point", 2): (2, 0, 2)}
    assert (ct.nq, ct.n_phi, ct.dof) == expected[(ct.kind, dim)]


@pytest.mark.parametrize("dim,name", ALL_TYPES, ids=IDS)
def test_Y_is_the_seed_matrix(dim, name):
    D = coordinate_type(name, dim).derivation
    assert np.array_equal(np.array(D.Y, dtype=float), _kron_I(YBAR[(dim, name)], dim))
    assert D.Y * D.Y_inv == sp.eye(D.Y.shape[0])


def test_Y_hand_checked_entries():
    # q_ruvw = Y q_rrvw: u = r_j - r_i, so rows 3..5 (the u block) hold -I at the r_i columns
    # and +I at the r_j columns; v and w are copied (identity blocks).
    Y = coordinate_type("rrvw").derivation.Y
    assert Y[3:6, 0:3] == -sp.eye(3) and Y[3:6, 3:6] == sp.eye(3)
    assert Y[6:12, 6:12] == sp.eye(6)
    # rrrr: w = r_l - r_i, last block row [-1, 0, 0, 1] ⊗ I
    Y = coordinate_type("rrrr").derivation.Y
    assert Y[9:12, 0:3] == -sp.eye(3) and Y[9:12, 9:12] == sp.eye(3)


@pytest.mark.parametrize("dim,name", ALL_TYPES, ids=IDS)
def test_C_is_the_seed_transformation(dim, name):
    ct = coordinate_type(name, dim)
    D = ct.derivation
    assert D.C == D.C_kron
    rng = np.random.default_rng(1)
    c = rng.normal(size=ct.k)
    C = np.array(D.C.subs(dict(zip(D.c, c))), dtype=float)
    seed = np.kron(np.r_[1.0, c][None, :], np.eye(dim)) @ _kron_I(YBAR[(dim, name)], dim)
    np.testing.assert_allclose(C, seed, atol=1e-15)


def test_C_hand_checked():
    # rrvw: r = r_i + c1 (r_j - r_i) + c2 v + c3 w  =>  C = [(1 - c1) I, c1 I, c2 I, c3 I]
    D = coordinate_type("rrvw").derivation
    c1, c2, c3 = D.c
    expected = sp.Matrix.hstack((1 - c1) * sp.eye(3), c1 * sp.eye(3), c2 * sp.eye(3), c3 * sp.eye(3))
    assert (D.C - expected).applyfunc(sp.expand) == sp.zeros(3, 12)


@pytest.mark.parametrize("dim,name", ALL_TYPES, ids=IDS)
def test_phi_is_the_seed_constraint_set(dim, name):
    rng = np.random.default_rng(2)
    m, _ = random_member(rng, name, dim)
    for _ in range(3):
        q = rng.normal(size=m.ctype.nq)
        np.testing.assert_allclose(m.phi(q), seed_phi(name, dim, q, m.Xbar), rtol=1e-13, atol=1e-13)


def _fd_jacobian(f, q, h=1e-6):
    cols = []
    for j in range(q.size):
        e = np.zeros_like(q)
        e[j] = h
        cols.append((np.atleast_1d(f(q + e)) - np.atleast_1d(f(q - e))).reshape(-1) / (2 * h))
    return np.array(cols).T


@pytest.mark.parametrize("dim,name", [t for t in ALL_TYPES if t[1] != "r"], ids=[i for t, i in zip(ALL_TYPES, IDS) if t[1] != "r"])
def test_phi_q_and_hessians_match_finite_differences(dim, name):
    rng = np.random.default_rng(3)
    m, _ = random_member(rng, name, dim)
    nq, nphi = m.ctype.nq, m.ctype.n_phi
    for _ in range(2):
        q = rng.normal(size=nq)
        A = m.phi_q(q)
        # Φ is quadratic: the central difference is exact up to rounding
        np.testing.assert_allclose(A, _fd_jacobian(m.phi, q), atol=1e-8)
        fd_H = _fd_jacobian(lambda x: m.phi_q(x).reshape(-1), q).reshape(nphi, nq, nq)
        for k in range(nphi):
            np.testing.assert_allclose(m.hessians[k], fd_H[k], atol=1e-7)


@pytest.mark.parametrize("dim,name", ALL_TYPES, ids=IDS)
def test_hessians_are_constant_and_symmetric(dim, name):
    ct = coordinate_type(name, dim)
    D = ct.derivation
    assert len(D.hessians) == ct.n_phi
    for H in D.hessians:
        assert H.free_symbols == set()
        assert H == H.T
    if ct.n_phi:
        rng = np.random.default_rng(4)
        m, _ = random_member(rng, name, dim)
        fd = [_fd_jacobian(lambda x: m.phi_q(x).reshape(-1), rng.normal(size=ct.nq)) for _ in range(2)]
        np.testing.assert_allclose(fd[0], fd[1], atol=1e-7)
        # Φ_q(q) = [qᵀ H_k]_k: the Jacobian is linear in q with the constant Hessians
        q = rng.normal(size=ct.nq)
        np.testing.assert_allclose(m.phi_q(q), np.array([H @ q for H in m.hessians]), atol=1e-12)


@pytest.mark.parametrize("dim,name", [(3, "rrvw"), (2, "rr")])
def test_gamma_is_minus_qdot_H_qdot(dim, name):
    rng = np.random.default_rng(5)
    m, _ = random_member(rng, name, dim)
    qd = rng.normal(size=m.ctype.nq)
    # γ = −Ȧ q̇ with Ȧ = Φ_q(q̇) (Φ_q is linear in q)
    np.testing.assert_allclose(m.gamma(qd), -m.phi_q(qd) @ qd, atol=1e-12)


# ------------------------------------------------------------------------ bad input
def test_unknown_type_lists_valid_ones():
    with pytest.raises(CoordinateTypeError) as e:
        coordinate_type("ruvx")
    msg = str(e.value)
    assert "'ruvx'" in msg and "ruvw, rrvw, rrrw, rrrr, ru, rr, r" in msg and "dim=3" in msg
    assert isinstance(e.value, ValueError) and isinstance(e.value, NcgenError)


def test_type_of_the_other_dimension_is_named():
    with pytest.raises(CoordinateTypeError, match=r"'ruvw' exists in 3D"):
        coordinate_type("ruvw", 2)
    with pytest.raises(CoordinateTypeError, match=r"'rrv' exists in 2D"):
        coordinate_type("rrv", 3)


@pytest.mark.parametrize("dim", [1, 4, "3", None])
def test_wrong_dimension(dim):
    with pytest.raises(CoordinateTypeError, match=r"dimension: expected 2 or 3"):
        coordinate_type("ru", dim)


def test_float_dimension_reaches_the_cache_as_an_integer(monkeypatch):
    # regression: dim=3.0 passed the check (3.0 == 3) and, if first in the cache, gave a
    # type with float sizes
    import ncgen.symbolic.coordinates as coords
    seen = []
    monkeypatch.setattr(coords, "_coordinate_type", lambda name, dim: seen.append(dim))
    coordinate_type("ru", 3.0)
    assert seen == [3] and type(seen[0]) is int
