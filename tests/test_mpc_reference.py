"""The MPC's time-varying reference (``nc.MPC(ocp, reference=plan, state_weight=…,
input_weight=…)``): the generated interpolation equals NumPy's (states linear between the
plan's times, inputs held, both held beyond the ends); the receding-horizon cost with a
reference is the closed form ``Σ h [(u − u_ref)ᵀ R (u − u_ref) + Σ Q (x − x_ref)²] +
W |x_N − x_ref(t_N)|²`` at the nodes' times; bad references and weights are refused by name
before anything is generated."""
from __future__ import annotations

from pathlib import Path

import casadi as ca
import numpy as np
import pytest

import ncgen as nc
from ncgen.control.mpc import merit_function
from ncgen.control.mpc_problem import mpc_problem
from ncgen.control.mpc_reference import reference_arrays, reference_function
from ncgen.errors import NcgenError

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def plan(M=6, nx=3, nu=2, seed=0):
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.05, 0.3, M)) - 0.1          # uneven, not starting at 0
    return t, rng.normal(size=(M, nx)), rng.normal(size=(M, nu))


def held(t_grid, U, t):
    """The input held on ``[t_j, t_{j+1})``, the ends held (an independent lookup)."""
    return U[int(np.clip(np.searchsorted(t_grid, t, side="right") - 1, 0, len(t_grid) - 1))]


def test_reference_interpolates_states_linearly_and_holds_inputs():
    t, X, U = plan()
    f = reference_function(t, X, U)
    times = np.concatenate([np.linspace(t[0] - 0.5, t[-1] + 0.5, 97), t, t[1:] - 1e-9])
    for s in times:
        x, u = (np.asarray(o).reshape(-1) for o in f(s))
        x_np = [np.interp(s, t, X[:, i]) for i in range(X.shape[1])]   # np.interp holds the ends
        np.testing.assert_allclose(x, x_np, atol=1e-12, rtol=0)
        np.testing.assert_array_equal(u, held(t, U, s))


def test_reference_from_a_solution_repeats_its_last_input():
    t, X, U = plan(nx=4)

    class Solution:                                   # what an OCP's solution offers
        pass
    sol = Solution()
    sol.t, sol.q, sol.v, sol.u = t, X[:, :2], X[:, 2:], U[:-1]
    t2, X2, U2 = reference_arrays(sol, 4, 2)
    np.testing.assert_array_equal(X2, X)
    np.testing.assert_array_equal(U2, np.vstack([U[:-1], U[-2:-1]]))


@pytest.mark.parametrize("bad, message", [
    (lambda t, X, U: (t[::-1], X, U), "t: expected at least 2 increasing times"),
    (lambda t, X, U: (t, X[:, :2], U), r"X: expected shape \(6, 3\)"),
    (lambda t, X, U: (t, X, U[:3]), r"U: expected shape \(6, 2\)"),
    (lambda t, X, U: (t, np.where(X > 1, np.nan, X), U), "X: expected finite numbers"),
    (lambda t, X, U: 3.0, "expected \\(t, X, U\\) or a solution"),
])
def test_bad_reference_is_named(bad, message):
    with pytest.raises(NcgenError, match=message):
        reference_arrays(bad(*plan()), 3, 2)


@pytest.fixture(scope="module")
def cartpole_ocp():
    """The cart-pole over 5 steps of 0.02 s, with an effort cost and final conditions (which a
    reference replaces)."""
    model = nc.System.from_toml(EXAMPLES / "cartpole.toml").build()
    ocp = nc.OptimalControl(model, N=5, t_final=0.1).bound_input("push", -20.0, 20.0).minimize_effort(0.3)
    return ocp.final(q={"cart.r_i.x": 0.0}, v=0.0)


def test_cost_with_a_reference_is_the_closed_form(cartpole_ocp):
    """The MPC's merit (evaluated by CasADi, not compiled) at a random iterate: the cost is
    the closed form at the nodes' times ``t + k h``, shifted with ``t``."""
    ocp = cartpole_ocp
    model = ocp.model
    nx, nu = 2 * model.nq, model.nu
    t_ref, X_ref, U_ref = plan(M=8, nx=nx, nu=nu, seed=1)
    rng = np.random.default_rng(2)
    Q, r, W = rng.uniform(0.5, 2.0, nx), 0.7, 3.0
    problem = mpc_problem(ocp, W, (t_ref, X_ref, U_ref), Q, r)
    R = (np.zeros((nu, nu)) if ocp.effort_R is None else ocp.effort_R) + r * np.eye(nu)
    merit = merit_function(model, problem)
    h, N = problem.h, problem.N
    x0 = np.concatenate([model.q0, model.v0])
    X = x0 + 1e-3 * rng.normal(size=(N + 1, nx))
    U = rng.normal(size=(N, nu))
    for t in (t_ref[0] + 0.01, t_ref[3] - 0.013, t_ref[-1] + 0.2):
        expected = 0.0
        for k in range(N):
            x_r = [np.interp(t + k * h, t_ref, X_ref[:, i]) for i in range(nx)]
            du = U[k] - held(t_ref, U_ref, t + k * h)
            expected += h * (du @ R @ du + np.sum(Q * (X[k] - x_r) ** 2))
        x_r = np.array([np.interp(t + N * h, t_ref, X_ref[:, i]) for i in range(nx)])
        expected += W * np.sum((X[N] - x_r) ** 2)
        J = float(merit(x0, t, ca.DM(X.T), ca.DM(U.T))[0])
        assert J == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("kw, message", [
    ({"state_weight": -1.0}, "state_weight: expected a number or 16 numbers"),
    ({"state_weight": np.ones(3)}, "state_weight: expected a number or 16 numbers"),
    ({"input_weight": [np.inf]}, "input_weight: expected a number or 1 numbers"),
])
def test_bad_weights_are_named(cartpole_ocp, kw, message):
    nx, nu = 2 * cartpole_ocp.model.nq, cartpole_ocp.model.nu
    with pytest.raises(NcgenError, match=message):
        nc.MPC(cartpole_ocp, reference=plan(nx=nx, nu=nu), **kw)


def test_weights_without_a_reference_are_refused(cartpole_ocp):
    with pytest.raises(NcgenError, match="state_weight: a weight of the tracking cost, given without a reference"):
        nc.MPC(cartpole_ocp, state_weight=1.0)
