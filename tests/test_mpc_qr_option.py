"""The MPC's ``sx_qr_max_nnz``: the step Jacobians' QR either unrolled into SX or left to
CasADi's ``qr`` solver (loops in C, for models whose unrolled factorisation gcc cannot
compile in reasonable time); both give the same Jacobians, which agree with central
differences of the step; a bad value is refused by name before anything is generated."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

import ncgen as nc
from ncgen.control.discrete import qr_solve_columns, step_functions, step_jacobian_function
from ncgen.errors import OptimizationError

from cartpole_mpc import cartpole, cartpole_problem, tilted


def test_both_qr_paths_solve_the_system():
    rng = np.random.default_rng(0)
    K_val = np.eye(4) * 3 + rng.normal(size=(4, 4))
    B_val = rng.normal(size=(4, 3))
    K, B = ca.MX.sym("K", 4, 4), ca.MX.sym("B", 4, 3)
    unrolled = qr_solve_columns(K, B, K.sparsity(), 3)
    looped = qr_solve_columns(K, B, K.sparsity(), 3, 0)
    assert "qr_factor" in str(unrolled) and "qr_factor" not in str(looped)
    exact = np.linalg.solve(K_val, B_val)
    for expr in (unrolled, looped):
        got = np.array(ca.Function("f", [K, B], [expr])(K_val, B_val))
        assert np.abs(got - exact).max() < 1e-12


def test_looped_step_jacobians_match_unrolled_and_finite_differences():
    model = cartpole()
    h = 0.02
    x = tilted(0.3, cart=0.1) + np.concatenate([np.zeros(model.nq), 0.1 * np.ones(model.nq)])
    u = np.array([1.5])
    looped = [np.array(o) for o in step_jacobian_function(model, h, sx_qr_max_nnz=0)(x, u, model.p0, 0.0)]
    unrolled = [np.array(o) for o in step_jacobian_function(model, h)(x, u, model.p0, 0.0)]
    for a, b in zip(looped[:3], unrolled[:3]):
        assert np.abs(a - b).max() < 1e-9 * (1 + np.abs(b).max())
    step = step_functions(model, h)["step"]
    eps = 1e-6
    B_fd = (np.array(step(x, u + eps, model.p0, 0.0)[0]) - np.array(step(x, u - eps, model.p0, 0.0)[0])) / (2 * eps)
    assert np.abs(looped[2] - B_fd).max() < 1e-6 * (1 + np.abs(B_fd).max())
    A_fd = np.column_stack([(np.array(step(x + eps * e, u, model.p0, 0.0)[0])
                             - np.array(step(x - eps * e, u, model.p0, 0.0)[0])).ravel() / (2 * eps)
                            for e in np.eye(2 * model.nq)])
    assert np.abs(looped[1] - A_fd).max() < 1e-6 * (1 + np.abs(A_fd).max())


@pytest.mark.parametrize("bad", [-1, 1.5, True, "0"])
def test_bad_sx_qr_max_nnz_is_named(bad):
    ocp = cartpole_problem()
    with pytest.raises(OptimizationError, match="sx_qr_max_nnz: expected an integer >= 0 or None"):
        nc.MPC(ocp, sx_qr_max_nnz=bad)
