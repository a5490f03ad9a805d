"""``step_solve`` of a block-diagonal KKT pattern (free bodies coupled only by contacts) solves
each diagonal block alone: its result against a dense LU solve (numpy) of the whole matrix,
with the blocks' rows interleaved (each block's in order, as a body's coordinates), blocks of several patterns (1×1, equal
5×5 ones sharing one mapped solve, 7×7, 8×8), and the block functions present."""
import casadi as ca
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
