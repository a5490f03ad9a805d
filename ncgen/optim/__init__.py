"""ncgen.optim: trajectory optimisation on a Model with ``casadi.Opti`` and IPOPT.

``OptimalControl`` describes the problem (bounds, boundary conditions, costs, free
parameters and final time); ``solve()`` transcribes it (Radau collocation by default, or
multiple shooting with IDAS or a registered integrator) and returns an
``OptimalTrajectory``.  See docs/optimal-control.md.
"""
from ncgen.optim.problem import OptimalControl
from ncgen.optim.problem_file import load_problem
from ncgen.optim.result import OptimalTrajectory, SolverStats
from ncgen.optim.shooting import register_integrator

__all__ = ["OptimalControl", "OptimalTrajectory", "SolverStats", "load_problem", "register_integrator"]
