"""Design-parameter optimisation: the spring of a catapult arm.

A 1 m arm (1 kg) hinged at the origin starts at rest, horizontal, pulled by a spring from
the ground point (0, 1) to its middle.  Which stiffness k and rest length l0 (model
parameters, free in the optimisation) swing the arm up, its tip never below the hinge, so
that it is straight above the hinge (tip x = 0) 0.6 s after release?  Only x is imposed: the
tip stays on a circle, so imposing y too would repeat a condition the hinge already makes
(a redundant equality, which IPOPT cannot satisfy robustly).  Among all designs that work,
the softest spring: minimise k² (a terminal cost on the parameters).  There is no control input: the motion is
the free response, and the parameters are the decision variables.  A simulation with the
spring found confirms it.

Run:  python examples/spring_design.py      (writes spring_design.png)
"""
import numpy as np

import ncgen as nc
from ncgen.optim.solution_plot import plot_solution

s = nc.System("catapult", gravity=(0, -9.81))
arm = s.add_bar("arm", mass=1.0, ends=[s.ground.point((0, 0)), (1.0, 0)])
arm.add_marker("tip", (0.5, 0))
k = s.add_parameter("k", 50.0)                      # N/m
rest = s.add_parameter("rest_length", 0.3)          # m
s.add_force(nc.Spring(s.ground, (0.0, 1.0), arm, (0.0, 0.0), k=k, rest_length=rest))
model = s.build()

ocp = nc.OptimalControl(model, N=30, t_final=0.6)
ocp.free_parameter("k", 0.0, 1000.0)
ocp.free_parameter("rest_length", 0.0, 0.5)
ocp.bound_marker("arm.tip", lower=(None, 0.0))     # path constraint: the tip stays up
ocp.final(marker=("arm.tip", (0.0, None)))
ocp.minimize_terminal(lambda q, v, p: 1e-4 * p[0] ** 2)
sol = ocp.solve()
print(sol.summary())
design = sol.parameters()
print(f"spring: k = {design['k']:.2f} N/m, rest length = {design['rest_length']:.4f} m")

check = nc.simulate(model, 0.6, 0.01, p=design)
print(f"simulated with that spring, the tip is at {np.round(check.marker('arm.tip')[-1], 5)} m at t = 0.6 s")

plot_solution(sol, "spring_design.png")
print("wrote spring_design.png")
