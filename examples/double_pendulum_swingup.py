"""Double-pendulum swing-up: two uniform 1 m links, hinged to the ground and to each
other, driven by a shoulder and an elbow motor (±30 N·m), from hanging down to balancing
upright, at rest, in 2 s with the least effort.

Model: two planar 'rr' bars (4 coordinates, 2 constraints; the elbow is a basic point
shared by both bars).  A motor torque acts on the link it drives and, in reaction, on the
one it is mounted on: nc.Torque(upper, shoulder − elbow), nc.Torque(fore, elbow).
Radau collocation, N = 60; the optimal torques are replayed by IDAS.  (Upright is
unstable, so an open-loop replay drifts off once there: the horizon ends on arrival.)

Run:  python examples/double_pendulum_swingup.py   (writes double_pendulum_swingup.png and .gif)
"""
import numpy as np

import ncgen as nc
from ncgen.optim.solution_plot import plot_solution

s = nc.System("double_pendulum_2d", gravity=(0, -9.81))
upper = s.add_bar("upper", mass=1.0, ends=[s.ground.point((0, 0)), (0, -1)])
fore = s.add_bar("fore", mass=1.0, ends=[upper.end(1), (0, -2)])
fore.add_marker("tip", (0.5, 0))
tau = s.add_input("tau", 2)                       # [shoulder, elbow] in N·m
s.add_force(nc.Torque(upper, tau[0] - tau[1]))
s.add_force(nc.Torque(fore, tau[1]))
model = s.build()
print(model, model.coordinate_names)

ocp = nc.OptimalControl(model, N=60, t_final=2.0)
ocp.bound_input("tau", -30, 30)
ocp.final(q=[0, 1, 0, 2], v=0)                    # upper.r_j = (0, 1), fore.r_j = (0, 2): upright
ocp.minimize_effort(0.1)
sol = ocp.solve()                                 # starts from the model's state: hanging at rest
print(sol.summary())

sim = nc.simulate(model, sol.t[-1], sol.t[1] - sol.t[0], u=sol.u, q0=sol.q[0], v0=sol.v[0])
gap = np.max(np.abs(sim.marker("fore.tip") - sol.marker("fore.tip")))
print(f"re-simulated with IDAS: the tip stays within {gap:.2e} m of the optimised motion")

plot_solution(sol, "double_pendulum_swingup.png")
nc.viz.animate(sol, "double_pendulum_swingup.gif")
print("wrote double_pendulum_swingup.png, double_pendulum_swingup.gif")
