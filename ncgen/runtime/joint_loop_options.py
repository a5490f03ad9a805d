"""The joint loop's option group (the integrator :mod:`ncgen.runtime.joint_integrator`): the
fields of :class:`~ncgen.runtime.options.SimulationOptions` the loop reads, passed to C whole."""
from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from ncgen.codegen.joint_loop import JointOptions, joint_options
from ncgen.runtime.option_group import OptionGroup


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
