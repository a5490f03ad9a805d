"""The joint-space loop behind the integrator seam (:mod:`ncgen.runtime.integrator`): the
joint coordinates integrated by a compiled RK4 or Dormand–Prince loop
(:func:`ncgen.runtime.joint_simulation.simulate_joint`), its options checked and passed to
C whole (:func:`ncgen.codegen.joint_loop.joint_options`)."""
from __future__ import annotations

from functools import lru_cache

from ncgen.runtime.integrator import Run
from ncgen.runtime.joint_loop_options import JointLoopOptions
from ncgen.runtime.joint_simulation import simulate_joint
from ncgen.runtime.options import SimulationOptions
from ncgen.runtime.trajectory import Trajectory


class JointIntegrator:
    """``method="joint"``: trees without contacts, a compiled controller and the joints'
    dynamics in the C loop, a Python feedback once per output interval."""

    METHOD = "joint"
    Options = JointLoopOptions

    def __init__(self, model, opts: SimulationOptions):
        self.model = model
        self.opts, self.loop_options = _prepared(opts)

    def run(self, run: Run) -> Trajectory:
        return simulate_joint(self.model, run, self.opts, self.loop_options)


@lru_cache(maxsize=64)
def _prepared(opts: SimulationOptions):
    """``(group, C options)`` of ``opts``, made once per options (each run copies the C options,
    :func:`~ncgen.codegen.joint_loop.run_options`)."""
    group = JointLoopOptions.of(opts)
    return group, group.loop_options()
