"""``nc.MPC(ocp, loop="c")`` on the cart-pole (examples/cartpole_mpc.toml): the control step
in one C call (the exported package's controller compiled into the MPC's package).  Its
converged solution is IPOPT's on the same discrete horizon problem (an independent solver on
the step equations as constraints); its real-time-iteration closed loop costs within 0.1 % of
the converged MPC's closed loop (10 SQP iterations a step) from the same start and push; it
answers the Python loop's inputs; a guess along which the steps fail raises and is kept;
bad ``loop`` values and the controllers the C loop does not cover are refused by name."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

import ncgen as nc
from ncgen.control.export import closed_loop
from ncgen.control.reference import solve_discrete
from ncgen.errors import OptimizationError

from cartpole_mpc import PUSH, cartpole_problem, tilted

QUICK_COMPILE = True             # the cart-pole MPC's packages at -O0 in both tiers, as in the other MPC modules and
#                                 benchmarks/control.py's smoke, which share them through the compile cache (tests/conftest.py)


@pytest.fixture(scope="module")
def ocp():
    return cartpole_problem()


@pytest.fixture(scope="module")
def rti(ocp):
    return nc.MPC(ocp, terminal_weight=100.0, loop="c")


def loop_cost(problem, X, U):
    """``Σ_k ℓ(x_k, u_k)`` along a closed loop (the horizon problem's stage cost)."""
    x, u = ca.SX.sym("x", X.shape[1]), ca.SX.sym("u", U.shape[1])
    return float(np.sum(np.array(ca.Function("l", [x, u], [problem.stage(x, u)]).map(len(U))(X.T, U.T))))


@pytest.mark.parametrize("bad", ["C", "fortran", 1, None])
def test_bad_loop_is_refused_by_name(ocp, bad):
    with pytest.raises(OptimizationError, match="loop: expected 'python' or 'c'"):
        nc.MPC(ocp, loop=bad)


@pytest.mark.parametrize("kwargs, reason", [
    ({"solver": "fatrop"}, "solver='fatrop'"),
    ({"qp_solver": "qpoases"}, "qp_solver='qpoases'"),
    ({"reference": (np.array([0.0, 1.0]), np.zeros((2, 16)), np.zeros((2, 1)))}, "a reference"),
])
def test_controllers_the_c_loop_does_not_cover_are_refused(ocp, kwargs, reason):
    with pytest.raises(OptimizationError, match=f"loop='c'.*got {reason}"):
        nc.MPC(ocp, loop="c", **kwargs)


@pytest.mark.slow
def test_converged_c_loop_is_the_ipopt_solution_of_the_horizon_problem(ocp, rti):
    x = tilted(0.1)
    rti.reset(x, iterations=30)
    X, U = rti.X.copy(), rti.U.copy()
    st = nc.step_function(ocp.model, rti.h)
    assert np.allclose(X[1:], st.rollout(x, U), atol=1e-9)              # converged: the states are a rollout
    assert np.max(np.abs(U)) < 19.0                                     # bounds inactive: IPOPT needs none
    _, U_ip, _ = solve_discrete(st, x, U, (rti.problem.stage, rti.problem.terminal))
    assert np.max(np.abs(U - U_ip)) < 1e-6 * np.max(np.abs(U_ip))


@pytest.mark.slow
def test_real_time_iteration_costs_within_a_tenth_of_a_percent_of_the_converged_mpc(ocp, rti):
    """One SQP iteration a step (C loop) against ten (converged: twenty give the same inputs),
    and the Python loop's inputs equal to round-off (the same arithmetic)."""
    x0 = tilted(0.2)
    _, U, X = closed_loop(rti, x0, 3.0, disturbance=PUSH)
    converged = nc.MPC(ocp, terminal_weight=100.0, iterations=10, loop="c")
    _, U10, X10 = closed_loop(converged, x0, 3.0, disturbance=PUSH)
    _, U20, _ = closed_loop(nc.MPC(ocp, terminal_weight=100.0, iterations=20, loop="c"), x0, 3.0, disturbance=PUSH)
    assert np.max(np.abs(U20 - U10)) < 1e-6
    J, J10 = loop_cost(rti.problem, X, U), loop_cost(rti.problem, X10, U10)
    assert abs(J / J10 - 1) < 1e-3, (J, J10)          # measured 2e-5 (benchmarks/control.py)
    assert np.all(np.abs(U) <= 20.0) and np.max(np.abs(U)) > 1.0
    assert np.linalg.norm(X[-1, 6:8] - [0.0, 0.5]) < 1e-2              # upright again after the push
    _, U_py, _ = closed_loop(nc.MPC(ocp, terminal_weight=100.0), x0, 3.0, disturbance=PUSH)
    assert np.max(np.abs(U - U_py)) < 1e-9


@pytest.mark.slow
def test_a_failing_guess_raises_and_is_kept(ocp, rti):
    x = tilted(0.1)
    rti.reset(x)
    bad = rti.X.copy()
    bad[1:, 8:] = 1e12                                                  # rates no step converges from
    rti.X = bad
    with pytest.raises(OptimizationError, match="compiled control step failed"):
        rti(x, 0.0)
    assert np.array_equal(rti.X, bad)
    with pytest.raises(nc.NcgenError, match="x"):
        rti(np.full(16, np.nan), 0.0)


def test_stationary_needs_a_converged_qp_a_feasible_guess_and_a_round_off_decrease():
    from ncgen.control.mpc import C_MIN, STATIONARY, stationary
    J0 = 0.625
    assert stationary(J0, 0.0, -0.5 * STATIONARY * J0, 0)
    assert stationary(0.0, 0.0, 0.0, 0)
    assert not stationary(J0, 0.0, -2 * STATIONARY * J0, 0)            # a decrease a trial can confirm
    assert not stationary(J0, 10 * C_MIN, 0.0, 0)                      # infeasible: the filter decides
    assert not stationary(J0, 0.0, 0.0, 1)                             # the QP failed: its prediction says nothing


@pytest.mark.slow
def test_at_the_upright_equilibrium_the_guess_is_kept_without_trials(ocp, rti):
    """Upright at rest is the optimum (u = 0 holds it): after converging there, a control step
    keeps the guess without evaluating a single trial, in Python and in C, and answers 0 N."""
    x = tilted(0.0)
    py = nc.MPC(ocp, terminal_weight=100.0)
    merit, calls = py._merit_fn, []
    py._merit_fn = lambda *a: calls.append(1) or merit(*a)
    for mpc in (py, rti):
        mpc.reset(x, iterations=10)
        u = mpc(x, 0.0)
        assert mpc.step_lengths == [0.0] and mpc.qp_status == [0]
        assert abs(u[0]) < 1e-9
    assert calls == []
