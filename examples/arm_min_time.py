"""Minimum-time point-to-point motion of a planar two-link arm.

A shoulder and an elbow motor (±10 N·m each) move the arm, in a vertical plane, from
stretched out horizontally to the upper link pointing up and the forearm pointing left,
from rest to rest, as fast as they can.  The final time is a decision variable
(t_final=(lower, upper)); the cost is T plus a tiny effort term that makes the torques unique
where they are not saturated.  The shoulder torque comes out bang-bang (on a bound, one
switch); the elbow torque leaves its bounds in the middle of the motion (a singular arc).

The torques enter the model as input expressions: nc.Torque(upper, shoulder − elbow) and
nc.Torque(fore, elbow) (the elbow motor, mounted on the upper link, reacts on it).

Run:  python examples/arm_min_time.py       (writes arm_min_time.png and .gif)
"""
import numpy as np

import ncgen as nc
from ncgen.optim.solution_plot import plot_solution

s = nc.System("arm", gravity=(0, -9.81))
upper = s.add_bar("upper", mass=1.0, ends=[s.ground.point((0, 0)), (0.5, 0)])
fore = s.add_bar("fore", mass=0.8, ends=[upper.end(1), (1.0, 0)])
fore.add_marker("hand", (0.25, 0))
tau = s.add_input("tau", 2)                         # [shoulder, elbow], N·m
s.add_force(nc.Torque(upper, tau[0] - tau[1]))
s.add_force(nc.Torque(fore, tau[1]))
model = s.build()

ocp = nc.OptimalControl(model, N=40, t_final=(0.2, 3.0))
ocp.bound_input("tau", -10, 10)
ocp.final(q=[0.0, 0.5, -0.5, 0.5], v=0)             # elbow at (0, 0.5), hand at (-0.5, 0.5)
ocp.minimize_time()
ocp.minimize_effort(1e-3)
sol = ocp.solve()
print(sol.summary())
saturated = np.mean(np.abs(sol.u[:-1]) > 9.9, axis=0)
print(f"minimum time T = {sol.t_final:.4f} s; torques on a bound in {100 * saturated[0]:.0f} % (shoulder) "
      f"and {100 * saturated[1]:.0f} % (elbow) of the intervals")

plot_solution(sol, "arm_min_time.png")
nc.viz.animate(sol, "arm_min_time.gif")
print("wrote arm_min_time.png, arm_min_time.gif")
