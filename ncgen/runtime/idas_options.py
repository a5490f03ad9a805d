"""IDAS's option group (the integrator :mod:`ncgen.runtime.idas_integrator`): the fields of
:class:`~ncgen.runtime.options.SimulationOptions` IDAS reads, those only it reads checked here."""
from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from ncgen.runtime.option_group import OptionGroup

PROJECTS = (True, False, "auto")


@dataclass(frozen=True)
class IdasOptions(OptionGroup):
    """IDAS's option group, made by ``IdasOptions.of(simulation_options)`` (each field as
    :class:`~ncgen.runtime.options.SimulationOptions` documents it); checks the fields only
    IDAS reads."""

    METHOD: ClassVar[str] = "idas"
    rtol: float | None
    atol: float | None
    hold: str
    max_steps: int
    backend: str
    linear_solver: str
    progress: bool | None
    project: bool | str
    joint_dynamics: bool

    def __post_init__(self):
        if not isinstance(self.linear_solver, str):
            self.fail("linear_solver", "the name of a CasADi linear solver")
        if not any(self.project is v or (isinstance(v, str) and self.project == v) for v in PROJECTS):
            self.fail("project", "True, False or 'auto'")
