"""The compiled stepper's option group (:mod:`ncgen.runtime.stepper`, the integrator
:mod:`ncgen.runtime.stepper_integrator`): the fields of
:class:`~ncgen.runtime.options.SimulationOptions` the stepper reads, those only it reads checked
here."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

from ncgen.codegen.stepper_package import HALVINGS_LIMIT
from ncgen.errors import NcgenError
from ncgen.runtime.option_group import OptionGroup, is_count, is_real

#: Fixed-step schemes of the stepper: ``"auto"`` (``"rattle4"``, or ``"rattle"`` for models with
#: contacts), RATTLE (order 2) and its fourth-order composition.
SCHEMES = ("auto", "rattle", "rattle4")
#: The fixed-step stepper's error estimates (``estimate``; True is ``"shadow"``).
ESTIMATES = (True, False, "local", "shadow")


@dataclass(frozen=True)
class StepperOptions(OptionGroup):
    """The compiled stepper's option group, made by ``StepperOptions.of(simulation_options)``
    (each field as :class:`~ncgen.runtime.options.SimulationOptions` documents it); checks the
    fields only the stepper reads."""

    METHOD: ClassVar[str] = "stepper"
    rtol: float | None
    atol: float | None
    hold: str
    max_steps: int
    substeps: int
    newton_tol: float
    max_newton: int
    max_halvings: int
    order: int
    scheme: str
    check: bool
    estimate: bool | str
    kernels: str
    backend: str

    def __post_init__(self):
        if not (is_real(self.newton_tol) and math.isfinite(self.newton_tol) and self.newton_tol > 0):
            self.fail("newton_tol", "a positive Newton tolerance")
        if not is_count(self.max_newton, 1):
            self.fail("max_newton", "at least one Newton iteration per step (the stepper's max_iter)")
        if not (is_count(self.max_halvings, 0) and self.max_halvings <= HALVINGS_LIMIT):
            self.fail("max_halvings", f"0 to {HALVINGS_LIMIT} step halvings")
        if self.order not in (2, 4) or isinstance(self.order, bool):
            self.fail("order", "2 (RATTLE) or 4 (Richardson-extrapolated RATTLE)")
        if not isinstance(self.scheme, str) or self.scheme not in SCHEMES:
            self.fail("scheme", f"one of {', '.join(SCHEMES)} (the stepper's fixed-step scheme)")
        if not any(self.estimate is e or (isinstance(e, str) and self.estimate == e) for e in ESTIMATES):
            self.fail("estimate", "True, False, 'local' or 'shadow'")
        if not isinstance(self.check, bool):
            self.fail("check", "True or False")

    def check_together(self) -> None:
        """The rule between fields, checked when the stepper runs: ``estimate="shadow"`` is the
        fixed-step run's."""
        if self.estimate == "shadow" and self.rtol is not None:
            raise NcgenError("estimate: 'shadow' is the fixed-step run's shadow run with steps of 2h; with rtol the "
                             "error control runs its own shadow run at 10x looser tolerances (estimate=True)")

    @property
    def error_control(self) -> bool:
        return self.rtol is not None
