"""Cart-pole swing-up by iLQR on the compiled RATTLE step, checked against IPOPT.

The step of examples/cartpole.toml (h = 0.02 s, N = 100: 2 s) with exact Jacobians
(nc.step_function); costs written with CasADi operations: a small effort and cart-position
cost along the way, a terminal cost pulling the state to upright at rest.  iLQR
(nc.ilqr) from a small wiggle; then IPOPT on the same discrete problem (the step equations
as constraints) from the same wiggle: the two costs agree.

Run:  python examples/cartpole_ilqr.py
"""
from pathlib import Path

import casadi as ca
import numpy as np

import ncgen as nc
from ncgen.control.reference import solve_discrete

model = nc.System.from_toml(Path(__file__).with_name("cartpole.toml")).build()
h, N = 0.02, 100
st = nc.step_function(model, h)
# x = [q; v], q = [cart.r_i (2), cart.u (2), cart.v (2), pole.r_j (2)] (model.coordinate_names)
x_down = np.concatenate([[0, 0, 1, 0, 0, 1, 0, -0.5], np.zeros(8)])
x_up = np.concatenate([[0, 0, 1, 0, 0, 1, 0, 0.5], np.zeros(8)])


def stage(x, u):
    return h * (0.01 * ca.sumsqr(u) + 0.1 * x[0] ** 2)


def terminal(x):
    return 100 * ca.sumsqr(x - x_up)


U0 = 0.1 * np.sin(np.arange(N) * h * 4)[:, None]
res = nc.ilqr(st, x_down, U0, (stage, terminal))
print(f"iLQR: cost {res.cost:.8g} after {res.iterations} iterations ({res.message})")
print(f"      pole tip at the end: {res.X[-1, 6:8].round(4)} m (target [0, 0.5])")
_, _, J = solve_discrete(st, x_down, U0, (stage, terminal))
print(f"IPOPT on the same discrete problem: cost {J:.8g}; relative difference {abs(res.cost - J) / J:.1e}")
