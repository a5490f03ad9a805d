"""iLQR/DDP on the compiled cart-pole step against IPOPT on the same discrete problem (the step
equations as SX constraints, exact Hessians): the cart-pole swing-up and a transfer (swing-up
ending 1 m along the rail); its gradient against the rollout's adjoint and finite differences,
the step's second derivatives (DDP) against finite differences of its exact Jacobians."""
from __future__ import annotations

from pathlib import Path

import casadi as ca
import numpy as np
import pytest

import ncgen as nc
from ncgen.control.reference import solve_discrete
from ncgen.errors import NcgenError

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
H, N = 0.02, 100
Q_DOWN = np.array([0, 0, 1, 0, 0, 1, 0, -0.5])
Q_UP = np.array([0, 0, 1, 0, 0, 1, 0, 0.5])


@pytest.fixture(scope="module")
def swingup():
    model = nc.System.from_toml(EXAMPLES / "cartpole.toml").build()
    st = nc.step_function(model, H)
    x_up = np.concatenate([Q_UP, np.zeros(8)])

    def stage(x, u):
        return H * (0.01 * ca.sumsqr(u) + 0.1 * x[0] ** 2)

    def terminal(x):
        return 100 * ca.sumsqr(x - x_up)

    x0 = np.concatenate([Q_DOWN, np.zeros(8)])
    U0 = 0.1 * np.sin(np.arange(N) * H * 4)[:, None]
    return st, x0, U0, (stage, terminal)


@pytest.mark.slow      # the whole iLQR swing-up and an IPOPT solve; fast:
#                       test_gradient_is_the_rollout_adjoint_and_finite_differences,
#                       test_step_curvature_is_the_derivative_of_the_exact_jacobians
def test_ilqr_swings_the_pole_up_with_the_cost_of_ipopt(swingup):
    st, x0, U0, costs = swingup
    res = nc.ilqr(st, x0, U0, costs, tol=1e-8)
    assert res.converged and res.gradient_norm <= 1e-8, res.message
    assert res.gradient_history[-1] == res.gradient_norm and len(res.gradient_history) == res.iterations + 1
    assert np.all(np.diff(res.history) < 0)
    assert np.allclose(res.X[1:], st.rollout(x0, res.U), atol=1e-12)       # the states are a rollout
    tip = res.X[-1, 6:8]
    assert np.linalg.norm(tip - [0.0, 0.5]) < 0.01 and np.max(np.abs(res.X[-1, 8:])) < 0.05
    _, U_ip, J_ip = solve_discrete(st, x0, U0, costs)
    assert abs(res.cost - J_ip) <= 1e-3 * J_ip          # the target: within 0.1 %
    assert abs(res.cost - J_ip) <= 1e-9 * J_ip          # in fact the same stationary point
    assert np.max(np.abs(res.U - U_ip)) <= 1e-5 * np.max(np.abs(U_ip))


@pytest.mark.slow
def test_ilqr_transfer_reaches_the_ipopt_optimum_and_gauss_newton_alone_is_slower(swingup):
    """A swing-up that ends 1 m along the rail, from rest and zero inputs: DDP (the default)
    reaches IPOPT's cost within 1e-9 and a gradient of 1e-8 within 200 iterations; Gauss–Newton
    iLQR (``second_order=False``) converges only linearly and stops at ``max_iter`` unconverged,
    and says so."""
    st, x0, _, _ = swingup
    x_b = np.concatenate([Q_UP + np.array([1.0, 0, 0, 0, 0, 0, 1.0, 0]), np.zeros(8)])
    costs = (lambda x, u: H * 0.01 * ca.sumsqr(u), lambda x: 100 * ca.sumsqr(x - x_b))
    U0 = np.zeros((N, 1))
    _, _, J_ip = solve_discrete(st, x0, U0, costs)
    res = nc.ilqr(st, x0, U0, costs)
    assert res.converged and res.gradient_norm <= 1e-8, res.message
    assert abs(res.cost - J_ip) <= 1e-9 * J_ip
    gn = nc.ilqr(st, x0, U0, costs, second_order=False, max_iter=60)
    assert not gn.converged and "stopped after 60 iterations with |dJ/dU|_inf" in gn.message
    assert gn.cost > res.cost and gn.gradient_norm > 1e-8


def test_gradient_is_the_rollout_adjoint_and_finite_differences(swingup):
    """The gradient iLQR stops on (:func:`ncgen.control.ilqr.gradient`) against the rollout's
    own adjoint (``st.rollout_gradient``) and central differences of the total cost."""
    from ncgen.control.costs import cost_functions
    from ncgen.control.ilqr import _linearisation, gradient
    st, x0, U0, costs = swingup
    U = U0[:20] + 0.3
    stage_d, terminal_d = cost_functions(costs, st.nx, st.nu)
    X = np.vstack([x0, st.rollout(x0, U)])
    A, B = _linearisation(st, X, U, None, st.model.t0)
    _, lx, lu, *_ = (np.array(a) for a in stage_d.map(20)(X[:-1].T, U.T))
    g = gradient(A, B, lx, lu, np.array(terminal_d(X[-1])[1]).ravel())
    dX = np.vstack([lx[:, 1:].T, np.array(terminal_d(X[-1])[1]).T])
    assert np.allclose(g, lu.T + st.rollout_gradient(x0, U, dX)[1], rtol=1e-10, atol=1e-12)

    def total(U):
        X = np.vstack([x0, st.rollout(x0, U)])
        return float(np.sum(np.array(stage_d.map(20)(X[:-1].T, U.T)[0])) + terminal_d(X[-1])[0])
    eps = 1e-6
    fd = [(total(U + eps * e[:, None]) - total(U - eps * e[:, None])) / (2 * eps) for e in np.eye(20)]
    assert np.allclose(g[:, 0], fd, rtol=1e-6, atol=1e-8 * np.max(np.abs(g)))


def test_step_curvature_is_the_derivative_of_the_exact_jacobians(swingup):
    """DDP's ``∂²(λᵀ x⁺)/∂[x; u]²`` (second-order implicit function theorem) against central
    differences of ``λᵀ [A B]`` from the step's exact Jacobians, at a moving state."""
    from ncgen.control.step_curvature import StepCurvature
    st, x0, _, _ = swingup
    x = st.rollout(x0, 2.0 * np.ones((10, 1)))[-1]
    u = np.array([1.5])
    rng = np.random.default_rng(3)
    lam = rng.standard_normal(st.nx)
    _, z = st._solve(x, u, st.model.p0, 0.0)
    Hxx, Huu, Hux = StepCurvature(st.model, H)(z, x, u, st.model.p0, 0.0, lam)

    def row(y):
        _, A, B = st.jacobians(y[:st.nx], y[st.nx:], None, 0.0)
        return lam @ np.hstack([A, B])
    y, eps = np.concatenate([x, u]), 1e-6
    T = st.tangent_basis(x)                       # perturbations of x along the state manifold
    dirs = [np.concatenate([T[:, i], [0.0]]) for i in range(T.shape[1])] + [np.concatenate([np.zeros(st.nx), [1.0]])]
    Hfull = np.block([[Hxx, Hux.T], [Hux, Huu]])
    assert np.max(np.abs(Hfull)) > 1e-4                   # a curved step: the check can fail
    for d in dirs:
        fd = (row(y + eps * d) - row(y - eps * d)) / (2 * eps)
        assert np.allclose(Hfull @ d, fd, rtol=1e-5, atol=1e-6 * np.max(np.abs(Hfull))), d


def test_costs_must_be_casadi_scalars(swingup):
    st, x0, U0, _ = swingup
    with pytest.raises(NcgenError, match="stage cost: expected a scalar cost"):
        nc.ilqr(st, x0, U0, (lambda x, u: x, lambda x: ca.sumsqr(x)))
    with pytest.raises(NcgenError, match="terminal cost: calling it with CasADi symbols failed"):
        nc.ilqr(st, x0, U0, (lambda x, u: ca.sumsqr(u), lambda x: 1.0 if x[0] > 0 else 0.0))
    with pytest.raises(NcgenError, match=r"costs: expected \(stage, terminal\)"):
        nc.ilqr(st, x0, U0, lambda x, u: 0)
