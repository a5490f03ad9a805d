"""The rolling integrator's option group (:mod:`ncgen.runtime.rolling_integrator`): the fields
of :class:`~ncgen.runtime.options.SimulationOptions` it reads."""
from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from ncgen.runtime.option_group import OptionGroup


@dataclass(frozen=True)
class RollingOptions(OptionGroup):
    """The rolling integrator's option group, made by ``RollingOptions.of(simulation_options)``
    (each field as :class:`~ncgen.runtime.options.SimulationOptions` documents it; every one of
    them is checked there, as other methods read it too)."""

    METHOD: ClassVar[str] = "rolling"
    integrator: str | None
    rtol: float | None
    atol: float | None
    substeps: int
    backend: str
    hold: str
