"""The joint-space loop behind the integrator seam (:mod:`ncgen.runtime.integrator`): the
joint coordinates integrated by a compiled RK4 or Dormand–Prince loop
(:func:`ncgen.runtime.joint_simulation.simulate_joint`), its options checked and passed to
C whole (:func:`ncgen.codegen.joint_loop.joint_options`)."""
from __future__ import annotations

from ncgen.codegen.joint_loop import joint_options
from ncgen.runtime.integrator import Run
from ncgen.runtime.joint_simulation import simulate_joint
from ncgen.runtime.options import SimulationOptions
from ncgen.runtime.trajectory import Trajectory


class JointIntegrator:
    """``method="joint"``: trees without contacts, a compiled controller and the joints'
    dynamics in the C loop, a Python feedback once per output interval."""

    METHOD = "joint"
    OPTIONS = ("integrator", "rtol", "atol", "substeps", "max_steps", "hold", "joint_dynamics", "progress", "kernels")

    def __init__(self, model, opts: SimulationOptions):
        self.model, self.opts = model, opts
        self.loop_options = joint_options(opts.integrator, opts.rtol, opts.atol, opts.substeps, opts.max_steps)

    def run(self, run: Run) -> Trajectory:
        o = self.opts
        return simulate_joint(self.model, run.t, run.U, o.hold, run.p, run.q, run.v, options=self.loop_options,
                              feedback=run.feedback, controller=run.controller, joint_dynamics=o.joint_dynamics,
                              progress=o.progress, kernels=o.kernels)
