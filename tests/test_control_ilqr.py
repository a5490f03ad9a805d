"""iLQR on the compiled cart-pole step against IPOPT on the same discrete problem (the step
equations as SX constraints, exact Hessians): the cart-pole swing-up."""
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


def test_ilqr_swings_the_pole_up_with_the_cost_of_ipopt(swingup):
    st, x0, U0, costs = swingup
    res = nc.ilqr(st, x0, U0, costs, tol=1e-8)
    assert res.converged, res.message
    assert np.all(np.diff(res.history) < 0)
    assert np.allclose(res.X[1:], st.rollout(x0, res.U), atol=1e-12)       # the states are a rollout
    tip = res.X[-1, 6:8]
    assert np.linalg.norm(tip - [0.0, 0.5]) < 0.01 and np.max(np.abs(res.X[-1, 8:])) < 0.05
    _, U_ip, J_ip = solve_discrete(st, x0, U0, costs)
    assert abs(res.cost - J_ip) <= 0.01 * J_ip
    assert abs(res.cost - J_ip) <= 1e-5 * J_ip          # in fact the same local minimum


def test_costs_must_be_casadi_scalars(swingup):
    st, x0, U0, _ = swingup
    with pytest.raises(NcgenError, match="stage cost: expected a scalar cost"):
        nc.ilqr(st, x0, U0, (lambda x, u: x, lambda x: ca.sumsqr(x)))
    with pytest.raises(NcgenError, match="terminal cost: calling it with CasADi symbols failed"):
        nc.ilqr(st, x0, U0, (lambda x, u: ca.sumsqr(u), lambda x: 1.0 if x[0] > 0 else 0.0))
    with pytest.raises(NcgenError, match=r"costs: expected \(stage, terminal\)"):
        nc.ilqr(st, x0, U0, lambda x, u: 0)
