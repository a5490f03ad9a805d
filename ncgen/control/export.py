"""``nc.export_mpc(ocp, path)``: the model-predictive controller of an ``OptimalControl``
problem as a standalone C package that builds with ``make`` and runs without Python.

The package (written by :func:`ncgen.codegen.package.write_package`, so it is reproducible,
written in a temporary sibling and renamed into place, with a manifest) holds:

* ``<name>_mpc_qp_blocks``, ``<name>_mpc_qp``, ``<name>_mpc_update``, ``<name>_mpc_merit``:
  one SQP iteration of :mod:`ncgen.control.mpc` (the QP's blocks interval by interval,
  CasADi's ``qrqp``, the full step, cost and infeasibility of a trial of the line search),
  generated C, self-contained; the blocks are condensed by ``ncgen_condense.h`` (plain C);
* ``<name>_plant_step``: one RATTLE step of ``h / substeps`` (:mod:`ncgen.control.discrete`),
  the plant of the demo;
* ``<name>_mpc.h``/``.c``: the API ``<name>_mpc_init``, ``<name>_mpc_step(m, x, t, u_out)``,
  ``<name>_mpc_free``, ``<name>_plant`` (documented in the header; no dynamic memory), around
  the model-independent driver ``ncgen_mpc.h`` (``templates/c/runtime/``: input checks, the
  iterations, the shift of the guess; unit-tested alone by ``tests/c/test_mpc.c``);
* ``demo.c``: the closed loop — controller every ``h`` seconds, plant with ``substeps``
  substeps, input disturbances — printing ``t u x`` per control step;
* ``Makefile`` (``make``; ``CFLAGS``, ``LDFLAGS`` as usual), ``CMakeLists.txt``, ``main.c``.

With ``solver="fatrop"`` the controller is Fatrop's instead (:mod:`ncgen.control.export_fatrop`:
CasADi's generated Fatrop solver of the joint-space horizon problem, ``<name>_fatrop_solver.c``,
``<name>_joint_state``; the same API), linked to ``libfatrop`` and ``libblasfeo`` (the Makefile's
``FATROP_DIR``: by default the CasADi wheel's directory, which ships them and their headers).

:func:`closed_loop` runs the same loop in Python (``nc.MPC`` and ``nc.step_function``: the
same generated code), for checking the package against Python.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np

from ncgen.control.discrete import default_abstol, step_functions
from ncgen.control.mpc import REGULARIZATION, SOLVERS, line_search_rules, mpc_functions, residual_tolerance
from ncgen.control.mpc_context import c_double as _c, controller_context
from ncgen.control.mpc_problem import mpc_problem
from ncgen.control.initial import check_consistent
from ncgen.control.step_support import PACKAGE_OPTIONS
from ncgen.errors import NcgenError
from ncgen.validation import as_scalar, as_vector

#: Longest demo run (s) the demo program accepts (its command-line check).
MAX_T_END = 1e6


@dataclass(frozen=True)
class Pulse:
    """Input disturbance ``values`` (one per input) added to the controller's input for
    ``t_on ≤ t < t_off`` (s)."""

    t_on: float
    t_off: float
    values: tuple


def pulses(disturbance, nu: int) -> list[Pulse]:
    """``disturbance``: a sequence of ``(t_on, t_off, values)``; checked."""
    out = []
    for i, item in enumerate(disturbance or ()):
        try:
            t_on, t_off, values = item
            values = np.atleast_1d(np.asarray(values, dtype=float)).reshape(-1)
            t_on, t_off = float(t_on), float(t_off)
        except (TypeError, ValueError):
            raise NcgenError(f"disturbance[{i}]: expected (t_on, t_off, values), got {item!r}") from None
        if values.size != nu or not np.all(np.isfinite(values)) or not t_on < t_off:
            raise NcgenError(f"disturbance[{i}]: expected t_on < t_off and {nu} finite input value(s), got {item!r}")
        out.append(Pulse(t_on, t_off, tuple(values.tolist())))
    return out


def plant_function(model, h: float) -> ca.Function:
    """``plant_step: (x, u, p, t) -> (x1, res)``: the RATTLE step of ``h`` seconds (the
    Newton tolerance of :func:`~ncgen.control.step.step_function`, so that the Python plant
    of :func:`closed_loop` takes the same iterations)."""
    step = step_functions(model, h, abstol=default_abstol(model))["step"]
    args = [ca.MX.sym(n, step.size1_in(i)) for i, n in enumerate(step.name_in())]
    return ca.Function("plant_step", args, step(*args), step.name_in(), step.name_out())


def _check_options(solver, fatrop_options, iterations, substeps, warmup) -> None:
    """:func:`export_mpc`'s controller and demo options, each named when it is refused."""
    if not isinstance(substeps, int) or substeps < 1:
        raise NcgenError(f"export_mpc: substeps: expected a positive integer, got {substeps!r}")
    if not isinstance(warmup, int) or warmup < 0:
        raise NcgenError(f"export_mpc: warmup: expected an integer ≥ 0, got {warmup!r}")
    if not isinstance(solver, str) or solver not in SOLVERS:
        raise NcgenError(f"export_mpc: solver: expected one of {', '.join(SOLVERS)}, got {solver!r}")
    if fatrop_options is not None and solver != "fatrop":
        raise NcgenError(f"export_mpc: fatrop_options: options of solver='fatrop', got solver={solver!r}")
    if not isinstance(iterations, int) or iterations < 1:
        raise NcgenError(f"export_mpc: iterations: expected a positive integer, got {iterations!r}")


def _demo_context(model, problem, plant, x0, t_end: float, substeps: int, warmup: int, pl) -> dict:
    """The template values of the plant (``plant_step``'s work sizes, its Newton tolerance)
    and of the demo program (parameters, ``x0``, ``t_end`` in s, the disturbance pulses)."""
    return {
        "substeps": substeps,
        "plant_sz_arg": plant.sz_arg(), "plant_sz_res": plant.sz_res(), "plant_sz_iw": plant.sz_iw(),
        "plant_sz_w": plant.sz_w(), "plant_tol": _c(residual_tolerance(model)),
        "params": ", ".join(_c(v) for v in problem.p) or "0",
        "x0": ", ".join(_c(v) for v in x0), "t_end": _c(t_end), "warmup": warmup,
        "disturbance": [{"t_on": _c(p.t_on), "t_off": _c(p.t_off), "amounts": [_c(v) for v in p.values]}
                        for p in pl],
        "disturbance_text": "; ".join(f"{list(p.values)} for {p.t_on:g} <= t < {p.t_off:g} s" for p in pl)
                            or "none",
    }


def export_mpc(ocp, path, *, name: str | None = None, solver: str = "sqp", iterations: int = 1,
               terminal_weight: float = 1e3, fatrop_options: dict | None = None, x0=None, t_end: float = 5.0,
               substeps: int = 5, disturbance=(), warmup: int = 10):
    """Write the controller of ``ocp`` (options as in :class:`ncgen.control.mpc.MPC`: ``solver``
    ``"sqp"`` or ``"fatrop"`` — the joint form, on a tree of hinges and slides —,
    ``iterations`` per control step, ``terminal_weight``, ``fatrop_options``) as the C
    package ``name`` (default: the model's name) in directory ``path``; returns the
    :class:`~ncgen.codegen.package.Package`.  ``x0`` (default: the problem's initial state,
    ``initial(q=…, v=…)``, else the model's),
    ``t_end`` (s), ``substeps``, ``disturbance`` (:func:`pulses`) and ``warmup`` (solves at
    the first state before the loop starts) are the demo program's defaults."""
    from ncgen.codegen.package import ExtraSource, write_package

    model = ocp.model
    name = name or model.name
    _check_options(solver, fatrop_options, iterations, substeps, warmup)
    problem = mpc_problem(ocp, terminal_weight)
    nx, nu = 2 * model.nq, model.nu
    t_end = as_scalar(t_end, "export_mpc: t_end")
    if not 0 < t_end <= MAX_T_END:
        raise NcgenError(f"export_mpc: t_end: expected the demo's duration in seconds, 0 < t_end <= {MAX_T_END:g}, "
                         f"got {t_end:g}")
    for pname, value in zip(model.parameter_names, problem.p):
        if not np.isfinite(value):
            raise NcgenError(f"export_mpc: parameter {pname!r}: expected a finite value, got {value}")
    if x0 is None:
        x0 = problem.x_start
    else:
        x0 = as_vector(x0, nx, "export_mpc: x0 (the state [q; v])")
        check_consistent(model, x0, problem.p, 0.0, "export_mpc: x0")             # the demo starts at t = 0
    plant = plant_function(model, problem.h / substeps)
    pl = pulses(disturbance, nu)
    if solver == "fatrop":                  # the controller's templates: mpc/fatrop.{h,c}.j2, else mpc/mpc.{h,c}.j2
        from ncgen.control.export_fatrop import fatrop_controller
        fns, own, controller = fatrop_controller(model, problem, name, iterations, fatrop_options)
    else:
        fns, own = mpc_functions(model, problem, regularization=REGULARIZATION), []      # C condenses the blocks
        controller = controller_context(model, problem, fns, iterations, line_search_rules(model))
    kind = "fatrop" if solver == "fatrop" else "mpc"
    context = {**controller, **_demo_context(model, problem, plant, x0, t_end, substeps, warmup, pl)}
    extra = [*own, ExtraSource("runtime/ncgen_mpc.h", "ncgen_mpc.h", included=True),
             *([ExtraSource("runtime/ncgen_condense.h", "ncgen_condense.h", included=True)] if kind == "mpc" else []),
             ExtraSource(f"mpc/{kind}.h.j2", f"{name}_mpc.h", context),
             ExtraSource(f"mpc/{kind}.c.j2", f"{name}_mpc.c", context),
             ExtraSource("mpc/demo.c.j2", "demo.c", context, program=True)]
    return write_package(name, [*fns, plant], Path(path), extra_sources=extra, **PACKAGE_OPTIONS)


def closed_loop(mpc, x0, t_end: float, *, substeps: int = 5, disturbance=(), warmup: int = 10, plant=None):
    """The demo program's loop in Python: ``(t, U, X)`` per control step (the state before
    the step).  ``plant``: a :class:`~ncgen.control.step.StepFunction` of ``mpc.h / substeps``
    (built when not given, on the flat kernels: the exported package's plant is that step, so the
    two loops do the same arithmetic)."""
    from ncgen.control.step import step_function
    model, h = mpc.model, mpc.h
    hs = h / substeps
    plant = plant or step_function(model, hs, kernels="flat")
    pl = pulses(disturbance, mpc.nu)
    x = np.asarray(x0, dtype=float).copy()
    mpc.reset(x, 0.0, iterations=warmup)
    steps = int(t_end / h + 0.5)
    T, U, X = [], [], []
    for k in range(steps):
        t = k * h
        u = mpc(x, t)
        T.append(t), U.append(u), X.append(x.copy())
        for s in range(substeps):
            ts = t + s * hs
            up = u.copy()
            for p in pl:
                if p.t_on <= ts < p.t_off:
                    up += np.asarray(p.values)
            x = plant(x, up, mpc.problem.p, ts)
    return np.array(T), np.array(U), np.array(X)
