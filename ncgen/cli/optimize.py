"""``ncgen optimize``: solve an optimal-control problem file (docs/optimal-control.md).

Writes the optimal trajectory
(``.npz``, readable by ``nc.Trajectory.load``) and a plot, atomically: a failed solve
leaves no file behind and exits with status 1 and IPOPT's diagnosis.
"""
from __future__ import annotations

import argparse
import contextlib
import sys
from pathlib import Path

from ncgen.cli.common import check_files, file_arguments, load_model, missing_model, mjcf_contacts_argument
from ncgen.cli.registry import subcommand


def _arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", metavar="FILE.toml",
                   help="a problem file naming its model (model = \"cartpole.toml\"), or, with --problem, "
                        "the model file")
    p.add_argument("--problem", metavar="PROBLEM.toml", default=None,
                   help="the problem file, when FILE is the model (its 'model' key is then ignored)")
    file_arguments(p, (".npz",), "the optimal trajectory (.npz; nc.Trajectory.load reads it)",
                   plot="the motion, inputs, markers and constraint drift", animate="the motion",
                   html="an interactive 3D page of the optimal motion (opens offline in any browser)")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="replace a model parameter's default value (repeatable)")
    p.add_argument("--floating-base", action="store_true",
                   help="URDF models only: the robot's base is free instead of fixed to the ground")
    mjcf_contacts_argument(p)
    p.add_argument("--contacts", default="smooth", choices=("smooth", "nonsmooth"),
                   help="contacts of the model: smooth (compliant law in the dynamics; default) or nonsmooth "
                        "(rigid impacts and Coulomb friction: the contact-implicit transcription, settings in "
                        "the problem's [contacts] table)")
    p.add_argument("-v", "--verbose", action="store_true", help="show IPOPT's iterations")


@subcommand(
    "optimize",
    help="solve an optimal-control problem (TOML) with IPOPT",
    description=(
        "Build the model, transcribe the optimal-control problem described in the problem file "
        "(horizon, N, method, bounds, initial/final/periodic conditions, costs, free parameters; "
        "see docs/optimal-control.md) and solve it with IPOPT. Prints the solver's summary, then "
        "writes what -o, --plot and --animate name (as every subcommand). If IPOPT fails, nothing is written and the message names IPOPT's "
        "status and the condition or bound most likely at fault."),
    examples=(
        "ncgen optimize examples/cartpole_swingup.toml -o swingup.npz --plot swingup.png\n"
        "ncgen optimize examples/cartpole.toml --problem examples/cartpole_swingup.toml -o cp.npz\n"
        "ncgen optimize examples/cartpole_swingup.toml --plot cp.pdf --animate cp.gif -v\n"
        "ncgen optimize examples/cartpole_swingup.toml --html cp.html"),
    arguments=_arguments,
)
def optimize(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    from ncgen.files import atomic_path
    from ncgen.optim.solution_plot import plot_solution
    from ncgen.optim.problem_file import model_path, problem_from_data, read_problem_file

    problem = Path(args.problem or args.file)
    check_files(args, parser, (".npz",))
    output, plot = args.output, args.plot
    data, origin = read_problem_file(problem)
    if args.problem:
        model_file = Path(args.file)
    else:
        model_file = model_path(data, origin)
        if model_file is None:
            raise missing_model(origin, data, "optimize", ", or give the model first and the problem with --problem")
    model = load_model(str(model_file), args.param, contacts=args.contacts, floating_base=args.floating_base,
                       mjcf_contacts=args.mjcf_contacts)
    ocp, options = problem_from_data(data, model, origin)
    kwargs = options.kwargs()
    kwargs["verbose"] = kwargs["verbose"] or args.verbose
    print(f"{ocp}: solving with IPOPT ...", file=sys.stderr)
    sol = ocp.solve(**kwargs)
    print(sol.summary())
    with contextlib.ExitStack() as stack:
        if output:
            sol.save(stack.enter_context(atomic_path(output)))
        if plot is not None:
            plot_solution(sol, stack.enter_context(atomic_path(plot)))
        if args.animate:
            from ncgen.viz import animate
            animate(sol, stack.enter_context(atomic_path(args.animate)))
        if args.html:
            from ncgen.viz.html import to_html
            to_html(sol, stack.enter_context(atomic_path(args.html)))
    for name in (output, plot, args.animate, args.html):
        if name:
            print(f"wrote {name}", file=sys.stderr)
    return 0
