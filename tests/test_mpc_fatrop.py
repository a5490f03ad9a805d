"""``nc.MPC(ocp, solver="fatrop")`` on the cart-pole (examples/cartpole_mpc.toml): Fatrop on the
stage-wise problem (ncgen.control.mpc_fatrop) reaches the optimum the converged SQP reaches
(first input and cost, the cost and infeasibility evaluated by the SQP's own compiled merit
function), its closed loop is the converged SQP's, a warm start takes fewer interior-point
iterations than a cold one, a failed solve keeps the guess, and bad solver names and Fatrop
options are refused by name."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.control.export import closed_loop
from ncgen.errors import OptimizationError
from ncgen.optim.problem_file import load_problem

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
PUSH = [(1.0, 1.1, [8.0])]                # an 8 N push on the cart for 0.1 s
QUICK_COMPILE = True             # the cart-pole MPC's packages at -O0 in both tiers, as in the other MPC modules and
#                                 benchmarks/control.py's smoke, which share them through the compile cache (tests/conftest.py)
# the tests that compare with the SQP are slow: its MPC compiles the horizon's step derivatives
# (minutes on a cold cache)


def tilted(angle, cart=0.0):
    """The cart-pole at rest with the pole ``angle`` rad off the upright."""
    q = np.array([cart, 0, 1, 0, 0, 1, cart + 0.5 * np.sin(angle), 0.5 * np.cos(angle)])
    return np.concatenate([q, np.zeros(8)])


@pytest.fixture(scope="module")
def ocp():
    model = nc.System.from_toml(EXAMPLES / "cartpole.toml").build()
    return load_problem(EXAMPLES / "cartpole_mpc.toml", model)[0]


@pytest.fixture(scope="module")
def fatrop(ocp):
    return nc.MPC(ocp, "fatrop", terminal_weight=100.0)


@pytest.fixture(scope="module")
def sqp(ocp):
    return nc.MPC(ocp, terminal_weight=100.0, iterations=10)


@pytest.mark.parametrize("bad", ["ipopt", "SQP", "", None, 3])
def test_bad_solver_names_are_refused_with_the_valid_ones(ocp, bad):
    with pytest.raises(OptimizationError, match=r"MPC: solver: expected one of sqp, fatrop, got "):
        nc.MPC(ocp, bad)


@pytest.mark.parametrize("options, match", [({"no_such_option": 1}, "not supported: no_such_option"),
                                            ({"tolerance": "tight"}, "type mismatch"),
                                            (["tolerance", 1e-8], "expected a dict")])
def test_bad_fatrop_options_are_refused_at_construction(ocp, options, match):
    with pytest.raises(OptimizationError, match=f"fatrop_options.*{match}"):
        nc.MPC(ocp, "fatrop", fatrop_options=options)


@pytest.mark.parametrize("angle, cart", [(0.2, 0.0), (-0.3, 0.5)])
@pytest.mark.slow
@pytest.mark.timeout(1800)
def test_fatrop_reaches_the_converged_sqp_optimum(fatrop, sqp, angle, cart):
    x = tilted(angle, cart)
    sqp.reset(x, 0.0, iterations=3)                     # 30 SQP iterations
    assert sqp.qp_status[-1] == 0
    fatrop.reset(x, 0.0, iterations=1)
    assert fatrop.fatrop.status and all(s == "0" for s in fatrop.fatrop.status), fatrop.fatrop.status
    u_f, u_s = fatrop.U[0], sqp.U[0]
    assert abs(u_f[0]) > 1.0 and abs(u_f[0] - u_s[0]) <= 1e-6 * max(1.0, abs(u_s[0])), (u_f, u_s)
    J_s, c_s = sqp._merit(x, 0.0, sqp.X, sqp.U)
    J_f, c_f = sqp._merit(x, 0.0, fatrop.X, fatrop.U)    # Fatrop's solution through the SQP's C
    assert c_s < 1e-8 and c_f < 1e-7, (c_s, c_f)
    assert abs(J_f - J_s) <= 1e-6 * J_s, (J_f, J_s)
    assert np.max(np.abs(fatrop.U - sqp.U)) <= 1e-5 * max(1.0, np.max(np.abs(sqp.U)))


@pytest.mark.slow
@pytest.mark.timeout(1800)
def test_closed_loop_is_the_converged_sqp_loop(ocp, fatrop, sqp):
    plant = nc.step_function(ocp.model, fatrop.h / 5, kernels="flat")
    x0 = tilted(0.2)
    T, U_f, X_f = closed_loop(fatrop, x0, 4.0, disturbance=PUSH, plant=plant)
    assert all(s == "0" for s in fatrop.fatrop.status)
    _, U_s, X_s = closed_loop(sqp, x0, 4.0, disturbance=PUSH, plant=plant)
    assert np.max(np.abs(U_f)) > 5.0 and np.all(np.abs(U_f) <= 20.0)
    assert np.max(np.abs(U_f - U_s)) <= 1e-5 * np.max(np.abs(U_s)), np.max(np.abs(U_f - U_s))
    assert np.max(np.abs(X_f - X_s)) <= 2e-6, np.max(np.abs(X_f - X_s))
    assert abs(X_f[-1, 0]) < 2e-3 and np.linalg.norm(X_f[-1, 6:8] - [0.0, 0.5]) < 2e-3


@pytest.mark.slow
@pytest.mark.timeout(1800)
def test_swings_up_from_the_documented_start_with_inputs_within_the_bounds(ocp, fatrop):
    """From the model's start (the pole hanging 0.3 rad off the downward vertical) the push
    saturates at the ±20 N bound (Fatrop's relaxed bound clipped) and the pole ends upright."""
    model = ocp.model
    plant = nc.step_function(model, fatrop.h / 5, kernels="flat")
    _, U, X = closed_loop(fatrop, np.concatenate([model.q0, model.v0]), 4.0, plant=plant)
    assert np.all(np.abs(U) <= 20.0) and np.any(np.abs(U) == 20.0)
    assert abs(X[-1, 0]) < 2e-3 and np.linalg.norm(X[-1, 6:8] - [0.0, 0.5]) < 2e-3, X[-1]


def test_warm_start_takes_fewer_iterations_than_a_cold_start(fatrop):
    x = tilted(0.25)
    fatrop.reset(x, 0.0, iterations=1)
    cold = fatrop.fatrop.iteration_counts[-1]
    X = fatrop.X
    fatrop(x, 0.0)                                       # from the reset's solution
    again = fatrop.fatrop.iteration_counts[-1]
    fatrop(X[1], fatrop.h)                               # the predicted next state, the shifted guess
    shifted = fatrop.fatrop.iteration_counts[-1]
    assert again < cold and shifted < cold, (cold, again, shifted)


def test_a_failed_solve_keeps_the_guess(ocp):
    mpc = nc.MPC(ocp, "fatrop", terminal_weight=100.0, fatrop_options={"max_iter": 1})
    x = tilted(0.2)
    mpc.reset(x, 0.0)
    X, U = mpc.X.copy(), mpc.U.copy()
    u = mpc(x, 0.0)
    assert len(mpc.fatrop.status) == 1 and mpc.fatrop.status[0] != "0"         # not converged
    assert np.array_equal(u, U[0]) and np.array_equal(mpc.solution[0], X) and np.array_equal(mpc.solution[1], U)
