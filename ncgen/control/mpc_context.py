"""The exported SQP controller's template context (``templates/c/mpc/mpc.{h,c}.j2``: sizes,
bounds, the line search's constants) and doubles written as C literals, shared by
``nc.export_mpc`` (:mod:`ncgen.control.export`) and ``nc.MPC(..., loop="c")``
(:mod:`ncgen.control.mpc`); the line search's rules come from
:func:`ncgen.control.mpc.line_search_rules`."""
from __future__ import annotations

import numpy as np

from ncgen.errors import NcgenError


def controller_context(model, problem, fns, iterations: int | None, rules: dict) -> dict:
    """The templates' context of the controller for the SQP functions ``fns``
    (:func:`~ncgen.control.mpc.mpc_functions`'s; without ``mpc_qp`` where the QP is solved in
    Python: the controller's C then only condenses ``mpc_qp_blocks``, the QP's rows being the
    bounded state components and the cables' pulls); ``iterations``: per control step, or ``None``
    for the controller inside ``nc.MPC(..., loop="c")`` (``in_process``: iterations set at run
    time, no plant); ``rules``: :func:`~ncgen.control.mpc.line_search_rules` (step lengths,
    Armijo fraction, filter margin, feasibility and stationarity thresholds, the step's
    residual tolerance).  The work sizes are those of the C functions generated for ``fns``
    (:func:`~ncgen.codegen.kernels.c_function`: an MX wrapper asks for more than what it calls;
    ``init`` refuses work arrays its functions do not fit in)."""
    from ncgen.codegen.kernels import c_function
    from ncgen.control.mpc_problem import bounded_states, qp_rows
    nx, nu = 2 * model.nq, model.nu
    u_rest = np.clip(np.zeros(nu), *problem.u_bounds)
    lo_x, hi_x = problem.x_bounds
    bounded = bounded_states(problem)
    taut = problem.min_tension is not None
    generated = [c_function(f, f.name()) for f in fns]     # the work the C functions ask for (a wrapper's, say)
    return {
        "model_name": model.name, "N": problem.N, "h": f"{problem.h:g}", "h_c": c_double(problem.h),
        "iterations": iterations or 0, "in_process": iterations is None, "nx": nx, "nu": nu, "np": model.np,
        "qp_in_c": any(f.name() == "mpc_qp" for f in fns), "n_rows": qp_rows(problem, nx),
        "n_pulls": problem.cable_pull.numel_out(0) if taut else 0,
        "t_min": c_double(problem.min_tension) if taut else "0.0",
        "sz_arg": max(f.sz_arg() for f in generated), "sz_res": max(f.sz_res() for f in generated),
        "sz_iw": max(f.sz_iw() for f in generated), "sz_w": max(f.sz_w() for f in generated),
        "nnz": {f"{f.name()}_{io}{i}": (f.nnz_in(i) if io == "in" else f.nnz_out(i))
                for f in fns for io in ("in", "out") for i in range(f.n_in() if io == "in" else f.n_out())},
        "u_rest": ", ".join(c_double(v) for v in u_rest) or "0",
        "u_lo": ", ".join(c_bound(v) for v in problem.u_bounds[0]) or "0",
        "u_hi": ", ".join(c_bound(v) for v in problem.u_bounds[1]) or "0",
        "nb": len(bounded), "x_bounded": ", ".join(str(int(i)) for i in bounded) or "0",
        "x_lo": ", ".join(c_bound(lo_x[i]) for i in bounded) or "0",
        "x_hi": ", ".join(c_bound(hi_x[i]) for i in bounded) or "0",
        "alphas": rules["alphas"], **{k: c_double(rules[k]) for k in ("armijo", "gamma", "c_min", "stationary",
                                                                     "step_tol")},
    }


def c_bound(v: float) -> str:
    """A bound as a C expression: ``INFINITY``/``-INFINITY`` (math.h) for an absent one."""
    return ("INFINITY" if v > 0 else "-INFINITY") if np.isinf(v) else c_double(v)


def c_double(v: float) -> str:
    """A double as a C literal that reads back exactly."""
    v = float(v)
    if not np.isfinite(v):
        raise NcgenError(f"export_mpc: cannot write the non-finite number {v} into C")
    return repr(v) if ("." in repr(v) or "e" in repr(v)) else repr(v) + ".0"
