"""``step_solve`` of a block-diagonal KKT pattern (free bodies coupled only by contacts) solves
each diagonal block alone: its result against a dense LU solve (numpy) of the whole matrix,
with the blocks' rows interleaved (each block's in order, as a body's coordinates), blocks of several patterns (1×1, equal
5×5 ones sharing one mapped solve, 7×7, 8×8), and the block functions present."""
import casadi as ca
import pytest
import numpy as np

import ncgen.assembly.stepper_equations as kernels


def _block_diagonal(rng, sizes):
    n = sum(sizes)
    D, start, key = np.zeros((n, n)), 0, []
    for k, s in enumerate(sizes):
        key += [(i, k) for i in range(s)]
        B = rng.standard_normal((s, s)) + 3 * np.eye(s)
        if s == 5:
            B[0, 4] = B[4, 0] = 0               # the same structural zeros in every 5×5 block
        D[start:start + s, start:start + s] = B
        start += s
    perm = sorted(range(n), key=key.__getitem__)   # interleaved: row i of every block, then i + 1
    return ca.sparsify(ca.DM(D[np.ix_(perm, perm)]))


def test_block_diagonal_kkt_is_solved_block_by_block(monkeypatch):
    rng = np.random.default_rng(3)
    K = _block_diagonal(rng, [1, 1, 5, 5, 5, 8, 7])
    monkeypatch.setattr(kernels, "SX_QR_MAX_NNZ", 100)       # the whole matrix's factors exceed it
    solve = kernels.solve_function(K.sparsity())
    names = {f.name() for f in solve.find_functions()}
    assert {"map3_step_solve_block1", "map2_step_solve_block0"} <= names, names
    assert solve.find_function("step_solve_block1").is_a("SXFunction")     # 5×5: unrolled QR
    for _ in range(3):
        r = rng.standard_normal(K.size1())
        x = np.array(solve(K, r)).ravel()
        np.testing.assert_allclose(x, np.linalg.solve(np.array(K), r), rtol=0, atol=1e-13 * np.abs(x).max())


def test_one_block_keeps_the_library_qr(monkeypatch):
    rng = np.random.default_rng(4)
    K = ca.sparsify(ca.DM(rng.standard_normal((12, 12)) + 4 * np.eye(12)))
    monkeypatch.setattr(kernels, "SX_QR_MAX_NNZ", 10)
    solve = kernels.solve_function(K.sparsity())
    assert not any(f.name().startswith("step_solve_block") for f in solve.find_functions())
    r = rng.standard_normal(12)
    np.testing.assert_allclose(np.array(solve(K, r)).ravel(), np.linalg.solve(np.array(K), r), atol=1e-13)


def _free_bodies_kkt(rng, masses, nb=4, nc=2):
    """K = [[M, A0^T], [A1, 0]] of free bodies (nb coordinates and nc constraint rows each, a
    dense positive definite mass block per body), rows ordered coordinates then constraints as
    in the stepper, and M."""
    nq, n = nb * len(masses), (nb + nc) * len(masses)
    K, M = np.zeros((n, n)), np.zeros((nq, nq))
    for k, m in enumerate(masses):
        q, c = slice(k * nb, (k + 1) * nb), slice(nq + k * nc, nq + (k + 1) * nc)
        X = rng.standard_normal((nb, nb))
        M[q, q] = m * (X @ X.T + nb * np.eye(nb))
        A0 = rng.standard_normal((nc, nb))
        K[q, q], K[q, c], K[c, q] = M[q, q], A0.T, A0 + 1e-3 * rng.standard_normal((nc, nb))
    return ca.sparsify(ca.DM(K)), M


def test_free_body_blocks_are_solved_by_their_schur_complement(monkeypatch):
    """A body's KKT block [[M_b, A0^T], [A1, 0]] (M_b regular, undamped) by its Schur complement,
    S = A1 M_b^-1 A0^T, with H = M_b read from K: against numpy's dense solve of the whole K to
    round-off, for mass blocks from 1e-4 to 1e2 (the complement's scale); a damped body and
    one whose mass block is ill conditioned keep the block's QR."""
    rng = np.random.default_rng(5)
    K, M = _free_bodies_kkt(rng, [1e-4, 1.0, 1e2, 1.0, 1.0])
    monkeypatch.setattr(kernels, "SX_QR_MAX_NNZ", 50)
    solve = kernels.solve_function(K.sparsity(), M, {4})              # body 1 (coordinates 4-7) damped
    schur = [f for f in solve.find_functions() if f.name().startswith("step_solve_block")]
    assert len(schur) == 2, [f.name() for f in schur]                   # one Schur, one QR pattern
    assert solve.find_function("step_solve_block0").n_instructions() < \
        solve.find_function("step_solve_block1").n_instructions()       # the complement is cheaper
    for _ in range(3):
        r = rng.standard_normal(K.size1())
        x = np.array(solve(K, r)).ravel()
        exact = np.linalg.solve(np.array(K), r)
        np.testing.assert_allclose(x, exact, rtol=1e-11, atol=1e-13 * np.abs(exact).max())
    M[:4, :4] = np.diag([1.0, 1.0, 1.0, 1e-9])                          # cond 1e9 > SCHUR_MAX_COND
    assert kernels._schur_blocks(K.sparsity(), kernels._components(K.sparsity()), M, set())[:2] == [0, 4]
    assert kernels._schur_blocks(K.sparsity(), kernels._components(K.sparsity()), None, set()) == [0] * 5


def test_constant_mass_blocks_are_solved_with_their_cholesky_factor(monkeypatch):
    """With ``constant_mass`` each Schur block takes its own block M_b of the constant M as
    constants (its Cholesky factor, not H = M_b read from K and factored): one block function
    per distinct M_b (three masses, the three bodies of mass 1 sharing one), each shorter than
    the complement with H read from K, the damped body keeping its QR; against numpy's dense
    solve of K to round-off."""
    rng = np.random.default_rng(8)
    K, M = _free_bodies_kkt(rng, [1e-4, 1.0, 1e2, 1.0, 1.0])
    for k in (3, 4):                                                    # bodies 3, 4: body 1's M_b
        M[4 * k:4 * k + 4, 4 * k:4 * k + 4] = M[4:8, 4:8]
    K = ca.DM(K)
    K[:20, :20] = M
    K = ca.sparsify(K)
    monkeypatch.setattr(kernels, "SX_QR_MAX_NNZ", 50)
    read = kernels.solve_function(K.sparsity(), M, {0})                 # body 0 damped
    solve = kernels.solve_function(K.sparsity(), M, {0}, constant_mass=True)
    blocks = {f.name(): f for f in solve.find_functions() if f.name().startswith("step_solve_block")}
    assert len(blocks) == 3, sorted(blocks)                             # QR (body 0), M_b of 1, of 1e2
    assert "map3_step_solve_block1" in {f.name() for f in solve.find_functions()}
    schur_read = read.find_function("step_solve_block1").n_instructions()
    assert all(blocks[f"step_solve_block{g}"].n_instructions() < schur_read for g in (1, 2))
    for _ in range(3):
        r = rng.standard_normal(K.size1())
        exact = np.linalg.solve(np.array(K), r)
        np.testing.assert_allclose(np.array(solve(K, r)).ravel(), exact, rtol=1e-11, atol=1e-13 * np.abs(exact).max())


def _chain_kkt(rng, n_points=5, nc=5):
    """K = [[M, A0^T], [A1, 0]] of a chain of points in 3-D: M the banded mass matrix of bars
    sharing ends (m/3 on the diagonal, m/6 between neighbours, per axis), each constraint row
    on two neighbouring points (the first on one), A1 = A0 plus a small change (the end of
    the step), and M."""
    nq = 3 * n_points
    T = np.diag(np.full(n_points, 2 * 0.2 / 3)) + np.diag(np.full(n_points - 1, 0.2 / 6), 1) \
        + np.diag(np.full(n_points - 1, 0.2 / 6), -1)
    T[-1, -1] = 0.2 / 3
    M = np.kron(T, np.eye(3))
    A0 = np.zeros((nc, nq))
    for k in range(nc):
        A0[k, 3 * k:3 * k + 3] = rng.standard_normal(3)
        if k:
            A0[k, 3 * k - 3:3 * k] = -A0[k, 3 * k:3 * k + 3]
    A1 = A0 + 1e-3 * rng.standard_normal((nc, nq)) * (A0 != 0)
    return ca.sparsify(ca.DM(np.block([[M, A0.T], [A1, np.zeros((nc, nc))]]))), M


def test_a_constant_mass_is_solved_through_its_cholesky_factor():
    """The 5-bar chain's KKT pattern with its constant banded M: the Schur complement with M's
    Cholesky factor as constants (fewer instructions than K's unrolled QR) against numpy's
    dense solve of K to round-off; without ``constant_mass``, with a damped coordinate, or
    with M ill conditioned the QR stays."""
    rng = np.random.default_rng(6)
    K, M = _chain_kkt(rng)
    qr = kernels.solve_function(K.sparsity())
    solve = kernels.solve_function(K.sparsity(), M, set(), constant_mass=True)
    assert solve.n_instructions() < 0.5 * qr.n_instructions(), (solve.n_instructions(), qr.n_instructions())
    for _ in range(3):
        r = rng.standard_normal(K.size1())
        exact = np.linalg.solve(np.array(K), r)
        np.testing.assert_allclose(np.array(solve(K, r)).ravel(), exact, rtol=0, atol=1e-13 * np.abs(exact).max())
    assert kernels.solve_function(K.sparsity(), M, {3}, constant_mass=True).n_instructions() == qr.n_instructions()
    assert kernels.solve_function(K.sparsity(), M, set()).n_instructions() == qr.n_instructions()
    bad = M.copy()
    bad[0, 0] = bad[1, 1] = bad[2, 2] = 1e-9                  # nearly singular: cond far above SCHUR_MAX_COND
    bad[0, 3] = bad[3, 0] = bad[1, 4] = bad[4, 1] = bad[2, 5] = bad[5, 2] = 0
    assert kernels._mass_schur_solve(K.sparsity(), bad, 10**6, "s") is None
    assert kernels._mass_schur_solve(K.sparsity(), M, 124, "s") is None     # 5 constraints: 125 > 124


def test_reproducible_cholesky_keeps_a_band_and_refuses_an_indefinite_matrix():
    from ncgen.reproducible import cholesky
    rng = np.random.default_rng(7)
    _, M = _chain_kkt(rng)
    L = cholesky(M)
    np.testing.assert_allclose(L @ L.T, M, rtol=0, atol=1e-16)
    np.testing.assert_allclose(L, np.linalg.cholesky(M), rtol=0, atol=1e-16)
    assert np.all(L[np.abs(np.subtract.outer(np.arange(15), np.arange(15))) > 3] == 0)   # exact zeros off the band
    with pytest.raises(ValueError, match="not positive definite"):
        cholesky(np.array([[1.0, 2.0], [2.0, 1.0]]))
