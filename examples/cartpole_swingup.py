"""Cart-pole swing-up by trajectory optimisation (the model of cartpole.toml).

Bring the pole from hanging straight down to upright above the cart, at rest, in 2 s, with
the least effort ∫ push² dt, the push within ±20 N and the cart within ±1.5 m of the
middle of its rail.  Radau collocation (N = 50) solved by IPOPT; the optimal push is then
replayed by IDAS (nc.simulate, held piecewise constant) to check the optimised motion.
The same problem as a file: ncgen optimize examples/cartpole_swingup.toml

Run:  python examples/cartpole_swingup.py      (writes cartpole_swingup.png and .gif)
"""
from pathlib import Path

import numpy as np

import ncgen as nc
from ncgen.optim.solution_plot import plot_solution

model = nc.System.from_toml(Path(__file__).with_name("cartpole.toml")).build()
down = {"cart.r_i.x": 0.0, "pole.r_j.x": 0.0, "pole.r_j.y": -0.5}   # coordinates kept; the rest assembled
up = {"cart.r_i.x": 0.0, "pole.r_j.x": 0.0, "pole.r_j.y": 0.5}

ocp = nc.OptimalControl(model, N=50, t_final=2.0)
ocp.bound_input("push", -20, 20)
ocp.bound_coordinate("cart.r_i.x", -1.5, 1.5)
ocp.initial(q=down, v=0)
ocp.final(q=up, v=0)
ocp.minimize_effort()
sol = ocp.solve()                                  # guess: the pole turned along the shortest arc
print(sol.summary())

sim = nc.simulate(model, sol.t[-1], sol.t[1] - sol.t[0], u=sol.u, q0=sol.q[0], v0=sol.v[0])
gap = np.max(np.abs(sim.marker("pole.tip") - sol.marker("pole.tip")))
print(f"re-simulated with IDAS: the pole tip stays within {gap:.2e} m of the optimised motion")

plot_solution(sol, "cartpole_swingup.png")
nc.viz.animate(sol, "cartpole_swingup.gif")
print("wrote cartpole_swingup.png, cartpole_swingup.gif")
