"""The integrator seam of :func:`ncgen.simulate` (as Drake's ``IntegratorBase``): one class
per integration method, prepared once for a model and its options, then run over a grid.

An integrator class has

* ``METHOD``: its name in ``SimulationOptions.method`` (and ``info["method"]``);
* ``Options``: its option group, a frozen :class:`~ncgen.runtime.options.OptionGroup` of the
  fields of :class:`~ncgen.runtime.options.SimulationOptions` it reads (the others are ignored
  by it), defined beside it and checking the fields only it reads;
* ``__init__(model, opts)``: prepares: takes its group of ``opts`` (``Options.of(opts)``),
  checks it against the model (a bad combination raises :class:`~ncgen.errors.NcgenError`
  naming the option) and loads or compiles what it runs; the group goes down whole;
* ``run(run)``: integrates the :class:`Run` and returns a
  :class:`~ncgen.runtime.trajectory.Trajectory`.

``simulate`` (:mod:`ncgen.runtime.simulation`) resolves ``method="auto"``, prepares the
integrator, makes the :class:`Run` and calls it.  The implementations: the joint-space loop
(:mod:`ncgen.runtime.joint_integrator`), the compiled stepper
(:mod:`ncgen.runtime.stepper_integrator`), IDAS (``IdasIntegrator`` in
:mod:`ncgen.runtime.idas_integrator`) and the rolling integrator of models with nonholonomic
elements (``RollingIntegrator`` in :mod:`ncgen.runtime.rolling_integrator`).
"""
from __future__ import annotations

from typing import Callable, ClassVar, NamedTuple, Protocol

import numpy as np

from ncgen.errors import NcgenError
from ncgen.runtime.option_group import OptionGroup
from ncgen.runtime.options import SimulationOptions
from ncgen.runtime.trajectory import Trajectory


class Run(NamedTuple):
    """One run's data, checked and consistent (a named tuple: made on every ``simulate`` call).

    ``t``: the output grid (s); ``U``: open-loop input samples on it, ``(len(t), nu)``;
    ``columns``: ``U`` held as ``SimulationOptions.hold`` says (IDAS's form); ``p``: parameter
    values; ``q``, ``v``: the consistent initial state at ``t[0]``; ``controller``: a compiled
    :class:`~ncgen.model.controllers.Controller` or None; ``feedback``: ``(kind, u)`` of a
    Python feedback (``kind`` ``"natural"`` or ``"joint"``) or None; ``why_not``: why
    ``method="auto"`` did not choose the joint loop (None otherwise); ``multipliers(t, q, v,
    u)``: ``λ`` solving the KKT system there; ``feedback_input(t, q, v)``: the feedback's
    inputs at a natural state; ``joint_state``: ``(q_j, v_j)`` of ``(q, v)`` when the start
    check gave it (else None)."""

    t: np.ndarray
    U: np.ndarray
    columns: np.ndarray
    p: np.ndarray
    q: np.ndarray
    v: np.ndarray
    controller: object
    feedback: tuple | None
    why_not: str | None
    multipliers: Callable[..., np.ndarray]
    feedback_input: Callable[..., np.ndarray]
    joint_state: tuple | None = None


class Integrator(Protocol):
    """What ``simulate`` needs of an integration method (module docstring)."""

    METHOD: ClassVar[str]
    Options: ClassVar[type[OptionGroup]]

    def __init__(self, model, opts: SimulationOptions) -> None: ...

    def run(self, run: Run) -> Trajectory: ...


def refuse_integrator(opts: SimulationOptions, method: str) -> None:
    """``integrator`` belongs to the joint loop's and the rolling integrator's options: an
    error with any other method."""
    if opts.integrator is not None:
        raise NcgenError(f"integrator: only method='joint' or 'rolling' takes an integrator (got {opts.integrator!r} "
                         f"with method={method!r})")
