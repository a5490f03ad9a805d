"""``SimulationOptions``: how :func:`ncgen.simulate` integrates, in one documented object
(as MuJoCo's ``mjOption`` or Drake's ``SimulatorConfig``).

The run's data — the model, the time grid, inputs ``u``, parameters ``p``, the initial state
``q0``, ``v0``, ``t0`` — are arguments of ``simulate``; everything about the integrator is
here.  The object is frozen and validated once, when made: a bad value raises
:class:`~ncgen.errors.NcgenError` naming the option, what was expected and what was given.
``simulate(model, t_end, dt, options=opts, rtol=1e-9)`` takes ``options`` whole, and its
keyword arguments are shortcuts for the same fields (:meth:`SimulationOptions.resolve`).

Each integrator owns its option group (as Drake's integrator configs): a frozen
:class:`OptionGroup` next to the integrator (``IdasOptions``, ``StepperOptions``,
``JointLoopOptions``, ``RollingOptions``), holding the fields it reads and checking those only it
reads, its errors naming the method; the fields several read (the tolerances, ``hold``,
``substeps``, ``backend``, ...) are checked here.  ``SimulationOptions`` is checked whole when
made (every group's checks run, whichever method is chosen), and ``simulate`` passes the
chosen integrator its group, which goes down whole::

    opts = nc.SimulationOptions(method="stepper", substeps=4)
    traj = nc.simulate(model, 2.0, 0.01, options=opts)
    traj = nc.simulate(model, 2.0, 0.01, method="stepper", substeps=4)      # the same run
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ncgen.codegen.stepper_package import MAX_HALVINGS, MAX_ITER, TOL
from ncgen.errors import NcgenError
from ncgen.model.expressions import did_you_mean
from ncgen.runtime.dae import BACKENDS
from ncgen.runtime.idas_options import IdasOptions
from ncgen.runtime.inputs import HOLDS
from ncgen.runtime.joint_loop_options import JointLoopOptions
from ncgen.runtime.option_group import is_count, is_real
from ncgen.runtime.rolling_options import RollingOptions
from ncgen.runtime.stepper_options import StepperOptions

METHODS = ("auto", "joint", "idas", "stepper", "rolling")
INTEGRATORS = ("dopri5", "rk4")
#: The stepper's kernels (``kernels``): chosen, from the element tables, or the model's own.
KERNELS = ("auto", "tables", "flat")
#: The integrators' option groups, checked whenever options are made.
GROUPS = (IdasOptions, StepperOptions, JointLoopOptions, RollingOptions)


@dataclass(frozen=True)
class SimulationOptions:
    """Options of :func:`ncgen.simulate` (see its docstring for how each acts).

    Both methods:

    * ``method``: ``"auto"`` (default: ``"joint"`` for trees, else ``"idas"``), ``"joint"``
      (joint coordinates in a compiled C loop, :mod:`ncgen.runtime.joint_simulation`),
      ``"idas"`` (SUNDIALS IDAS, variable-order BDF) or ``"stepper"`` (the compiled RATTLE
      stepper).
    * ``joint_dynamics``: honour the joints' damping, friction, limits and armature
      (:mod:`ncgen.model.joint_dynamics`; joint method, IDAS without armature).
    * ``rtol``, ``atol``: local error tolerances (relative; absolute in the units of q and v).
      IDAS: default 1e-8 and 1e-10.  Stepper: None = fixed steps; ``rtol`` given = error
      control (``atol`` default ``rtol``).
    * ``hold``: inputs between grid times, ``"zoh"`` (sample k on ``[t_k, t_k+1)``) or
      ``"linear"``.
    * ``max_steps``: integrator steps (IDAS) or step attempts (error-controlled stepper)
      allowed per output interval.
    * ``ic_tolerance``: largest correction of a given initial state, as a fraction of the
      system's size (None: any).

    IDAS only: ``backend`` (``"vm"``, ``"compiled"``, ``"auto"``), ``linear_solver``
    (CasADi's sparse solver of the Newton systems), ``progress`` (a progress bar: True,
    False, None = on a terminal for runs longer than a second), ``project`` (``"auto"``,
    True, False: crossing singular configurations).

    Joint method only: ``integrator`` (``"dopri5"``, default, error-controlled; ``"rk4"``,
    ``substeps`` fixed steps per output interval).

    ``method="rolling"`` (models with rolling elements, ``model.rolling``; the ``"auto"``
    choice for them): ``integrator`` as the joint method's, ``rtol``, ``atol``, ``substeps``,
    ``backend`` (``"compiled"``: each step compiled C; ``"vm"``: Python-driven CasADi calls;
    ``"auto"``: compiled when it pays) (:mod:`ncgen.runtime.rolling_integrator`).

    Stepper only: ``substeps`` (fixed steps per output interval), ``newton_tol`` (Newton
    tolerance on both constraint levels), ``max_newton`` (Newton iterations per step),
    ``max_halvings`` (splits of a step whose Newton fails, 0 to 10), ``order`` (2 or 4, error
    control), ``scheme`` (fixed steps: ``"auto"``, default: ``"rattle4"``, or ``"rattle"``
    for a model with contacts, which keep their own scheme; ``"rattle"``: RATTLE, order 2, one
    implicit step per step; ``"rattle4"``: Suzuki's symmetric five-stage composition of
    RATTLE steps, order 4, symplectic, both constraint levels kept, five RATTLE steps per
    step, not with nonsmooth contacts; with ``rtol``, ``"rattle4"`` selects the composition's
    error control, ``"auto"`` RATTLE's), ``check`` (make an untrustworthy run an error),
    ``estimate`` (fixed steps: ``True`` or ``"shadow"``, default: a shadow run with steps of
    2h, half the work again, a global estimate that follows the growth of errors along the
    motion; ``"local"``: the local errors of one pair of steps in six, summed and grown as a
    RATTLE shadow run's errors grow, about a fifth more work, reliable where errors do not
    grow fast (see :mod:`ncgen.runtime.stepper_checks`); ``False``: none; error control: any
    true value runs its shadow run at 10x looser tolerances), ``kernels`` (``"tables"``: the
    stepper of the element library, compiled once per ncgen version, run on the model's
    tables, with no compile per model, for models whose every element is of a covered kind;
    ``"flat"``: the model's own generated package, compiled per model; ``"auto"``, default:
    the tables when the model is covered, else flat; ``traj.info["kernels"]`` says which ran;
    see :mod:`ncgen.runtime.table_stepper`; for ``method="joint"`` the same choice between the
    tree library's loop on the model's tree tables, for trees without a compiled controller or
    joint dynamics, and the model's compiled joint-space ODE: :func:`ncgen.runtime.joint_simulation.joint_loop`),
    ``backend`` for a model with rolling elements only (``"compiled"``: each RATTLE step one
    call of compiled C; ``"vm"``: Python-driven; ``"auto"``: compiled when it pays,
    :mod:`ncgen.runtime.rolling_stepper`).
    """

    method: str = "auto"
    rtol: float | None = None
    atol: float | None = None
    hold: str = "zoh"
    max_steps: int = 50_000
    ic_tolerance: float | None = 1e-6
    backend: str = "auto"
    linear_solver: str = "csparse"
    progress: bool | None = None
    project: bool | str = "auto"
    substeps: int = 1
    newton_tol: float = TOL
    max_newton: int = MAX_ITER
    max_halvings: int = MAX_HALVINGS
    order: int = 4
    scheme: str = "auto"
    check: bool = True
    estimate: bool | str = True
    integrator: str | None = None
    joint_dynamics: bool = False
    kernels: str = "auto"

    def __post_init__(self):
        for name in ("max_steps", "substeps", "max_newton", "max_halvings", "order"):
            value = getattr(self, name)           # 4.0 or numpy.int64(4) count as 4
            if is_real(value) and math.isfinite(value) and int(value) == value:
                object.__setattr__(self, name, int(value))
        for name in ("rtol", "atol", "ic_tolerance", "newton_tol"):
            value = getattr(self, name)
            if is_real(value):
                object.__setattr__(self, name, float(value))
        for name in ("check", "estimate", "joint_dynamics"):
            value = getattr(self, name)
            if isinstance(value, (bool, np.bool_)) or (is_real(value) and value in (0, 1)):
                object.__setattr__(self, name, bool(value))
        if self.method not in METHODS:
            raise NcgenError(f"method: expected one of {', '.join(METHODS)}, got {self.method!r}")
        for name in ("rtol", "atol", "ic_tolerance"):
            value = getattr(self, name)
            if value is not None and not (is_real(value) and math.isfinite(value) and value > 0):
                raise NcgenError(f"{name}: expected a positive tolerance, got {value!r}")
        if self.hold not in HOLDS:
            raise NcgenError(f"hold: expected one of {', '.join(HOLDS)}, got {self.hold!r}")
        if self.backend not in BACKENDS:
            raise NcgenError(f"backend: expected one of {', '.join(BACKENDS)}, got {self.backend!r}")
        if self.progress not in (True, False, None):
            raise NcgenError(f"progress: expected True, False or None, got {self.progress!r}")
        if not is_count(self.max_steps, 1):
            raise NcgenError(f"max_steps: expected a positive number of steps, got {self.max_steps!r}")
        if not is_count(self.substeps, 1):
            raise NcgenError(f"substeps: expected a positive number of steps per output interval, got {self.substeps!r}")
        if self.integrator is not None and self.integrator not in INTEGRATORS:
            raise NcgenError(f"integrator: expected one of {', '.join(INTEGRATORS)} (method='joint' or 'rolling'), "
                             f"got {self.integrator!r}")
        if not isinstance(self.kernels, str) or self.kernels not in KERNELS:
            raise NcgenError(f"kernels: expected one of {', '.join(map(repr, KERNELS))} (the stepper's kernels: "
                             f"from the element tables or the model's own package), got {self.kernels!r}")
        if not isinstance(self.joint_dynamics, bool):
            raise NcgenError(f"joint_dynamics: expected True or False, got {self.joint_dynamics!r}")
        for group in GROUPS:
            group.of(self)

    @classmethod
    def resolve(cls, options: "SimulationOptions | None" = None, **shortcuts) -> "SimulationOptions":
        """``options`` (default: the defaults) with the fields in ``shortcuts`` replaced, validated;
        an unknown name is an error naming the known ones.  Options of hashable values are
        resolved once (a short run's fixed cost; values keyed with their types, so that ``1``
        and ``True`` stay apart)."""
        try:
            return _resolved(cls, options, tuple((k, type(x), x) for k, x in shortcuts.items()))
        except TypeError:                   # an unhashable value: checked as given, once more
            return _resolve(cls, options, shortcuts)


def _resolve(cls, options, shortcuts: dict) -> SimulationOptions:
    if options is not None and not isinstance(options, cls):
        raise NcgenError(f"options: expected an nc.SimulationOptions, got {type(options).__name__}")
    fields = [f.name for f in dataclasses.fields(cls)]
    for name in shortcuts:
        if name not in fields:
            raise NcgenError(f"simulate: no option named {name!r}{did_you_mean(name, fields)}; options: "
                             f"{', '.join(fields)}")
    if options is None:
        return cls(**shortcuts)
    return dataclasses.replace(options, **shortcuts) if shortcuts else options


@lru_cache(maxsize=64)
def _resolved(cls, options, shortcuts: tuple) -> SimulationOptions:
    """:func:`_resolve` of hashable options (``shortcuts``: ``(name, type, value)`` triples)."""
    return _resolve(cls, options, {k: x for k, _, x in shortcuts})
