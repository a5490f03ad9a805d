"""The joint-space loop behind the integrator seam (:mod:`ncgen.runtime.integrator`): the
joint coordinates integrated by a compiled RK4 or Dormand–Prince loop
(:func:`ncgen.runtime.joint_simulation.simulate_joint`), its options checked and passed to
C whole (:func:`ncgen.codegen.joint_loop.joint_options`)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from ncgen.codegen.joint_loop import JointOptions, joint_options
from ncgen.runtime.integrator import Run
from ncgen.runtime.joint_simulation import simulate_joint
from ncgen.runtime.options import OptionGroup, SimulationOptions
from ncgen.runtime.trajectory import Trajectory


@dataclass(frozen=True)
class JointLoopOptions(OptionGroup):
    """The joint loop's option group, made by ``JointLoopOptions.of(simulation_options)`` (each
    field as :class:`~ncgen.runtime.options.SimulationOptions` documents it; every one of them
    is checked there, as other methods read it too)."""

    METHOD: ClassVar[str] = "joint"
    integrator: str | None
    rtol: float | None
    atol: float | None
    substeps: int
    max_steps: int
    hold: str
    joint_dynamics: bool
    progress: bool | None
    kernels: str

    def loop_options(self) -> JointOptions:
        """The C loop's ``ncgen_joint_options`` (:func:`ncgen.codegen.joint_loop.joint_options`)."""
        return joint_options(self.integrator, self.rtol, self.atol, self.substeps, self.max_steps)


class JointIntegrator:
    """``method="joint"``: trees without contacts, a compiled controller and the joints'
    dynamics in the C loop, a Python feedback once per output interval."""

    METHOD = "joint"
    Options = JointLoopOptions

    def __init__(self, model, opts: SimulationOptions):
        self.model, self.opts = model, JointLoopOptions.of(opts)
        self.loop_options = self.opts.loop_options()

    def run(self, run: Run) -> Trajectory:
        o = self.opts
        return simulate_joint(self.model, run.t, run.U, o.hold, run.p, run.q, run.v, options=self.loop_options,
                              feedback=run.feedback, controller=run.controller, joint_dynamics=o.joint_dynamics,
                              progress=o.progress, kernels=o.kernels)
