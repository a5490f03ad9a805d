"""The controller of ``nc.export_mpc(ocp, path, solver="fatrop")``: Fatrop on the horizon
problem in the tree's joint space (:mod:`ncgen.control.mpc_fatrop_joint`), the solver CasADi's
generated C (the same file ``nc.MPC(ocp, "fatrop")`` compiles, :func:`ncgen.control.compiled_nlp.fatrop_c`),
around the model-independent driver ``ncgen_mpc.h`` (``templates/c/mpc/fatrop.{h,c}.j2``).

The driver's guess is the joint states ``X`` (``2 n_j`` values a node) and the inputs ``U``,
shifted as ``nc.MPC`` shifts its ``Z`` and ``U``; each control step maps the measured natural
state into joint space near the guess's first node (``joint_state``, as
:meth:`ncgen.control.mpc_fatrop.FatropSolver.solve` does), solves from the guess, clips the
inputs into their bounds, and keeps the guess when Fatrop fails or answers anything not
finite — the arithmetic of ``nc.MPC(ocp, "fatrop")``, so the package answers its inputs.
"""
from __future__ import annotations

import numpy as np

from ncgen.control.mpc_context import c_bound, c_double
from ncgen.errors import OptimizationError


def fatrop_controller(model, problem, name: str, iterations: int, options: dict | None):
    """``(functions, sources, context)`` of the Fatrop controller of ``problem`` in the
    package ``name``: the package's CasADi functions (``joint_state``), the generated
    solver as an extra source, and the context of the controller's templates;
    ``options``: Fatrop's own (as ``nc.MPC``'s ``fatrop_options``), checked by one solve."""
    from ncgen.codegen.package import ExtraSource
    from ncgen.control.compiled_nlp import SLOTS, fatrop_c
    from ncgen.control.mpc_fatrop import FatropSolver
    from ncgen.control.mpc_fatrop_joint import joint_form_refusal, joint_maps
    why = joint_form_refusal(model)
    if why is not None:
        raise OptimizationError(f"export_mpc: solver='fatrop' exports the joint form (a tree of hinges and slides); "
                                f"model {model.name!r}: {why}; use solver='sqp'")
    fatrop = FatropSolver(model, problem, options, "joint", compiled=False)
    fp, N, nu = fatrop.nlp, problem.N, model.nu
    nxj = 2 * model.joint_space.nv
    stage = nxj + nu
    for k in range(N + 1):                    # the driver packs the variables stage by stage: x_0, u_0, x_1, ...
        if not (np.array_equal(fp.state[k], np.arange(k * stage, k * stage + nxj))
                and (k == N or np.array_equal(fp.input[k], np.arange(k * stage + nxj, (k + 1) * stage)))):
            raise OptimizationError(f"export_mpc: the joint form's variables of stage {k} are not in stage order")
    solver_name = f"{name}_fatrop_solver"
    solver, code = fatrop_c(solver_name, fp.nlp, fp.options)
    joint_state = joint_maps(model, N)[0]
    fns = (solver, joint_state)
    nw, ng = fp.lbx.size, fp.lbg.size
    u_rest = np.clip(np.zeros(nu), *problem.u_bounds)
    context = {
        "model_name": model.name, "N": N, "h": f"{problem.h:g}", "h_c": c_double(problem.h), "iterations": iterations,
        "in_process": False, "nx": 2 * model.nq, "nxj": nxj, "nu": nu, "np": model.np, "nw": nw, "ng": ng,
        "solver": solver_name, "max_controllers": SLOTS, "fatrop_options": ", ".join(f"{k} = {v!r}" for k, v in sorted(fp.options["fatrop"].items())),
        "sz_arg": max(f.sz_arg() for f in fns), "sz_res": max(f.sz_res() for f in fns),
        "sz_iw": max(f.sz_iw() for f in fns), "sz_w": max(f.sz_w() for f in fns),
        "u_rest": ", ".join(c_double(v) for v in u_rest) or "0",
        "u_lo": ", ".join(c_bound(v) for v in problem.u_bounds[0]) or "0",
        "u_hi": ", ".join(c_bound(v) for v in problem.u_bounds[1]) or "0",
        **{key: ", ".join(c_bound(v) for v in getattr(fp, key)) for key in ("lbx", "ubx", "lbg", "ubg")},
    }
    source = ExtraSource("mpc/fatrop_solver.c.j2", f"{solver_name}.c", {"code": code, "solver": solver_name, "max_controllers": SLOTS},
                         fatrop=True)
    return [joint_state], [source], context
