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

from ncgen.cli.common import load_model
from ncgen.cli.registry import subcommand
from ncgen.errors import ProblemFileError


def _arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", metavar="FILE.toml",
                   help="a problem file naming its model (model = \"cartpole.toml\"), or, with --problem, "
                        "the model file")
    p.add_argument("--problem", metavar="PROBLEM.toml", default=None,
                   help="the problem file, when FILE is the model (its 'model' key is then ignored)")
    p.add_argument("-o", "--output", metavar="FILE.npz", default=None,
                   help="where to write the optimal trajectory (default: the problem file's name with "
                        ".npz, in the current directory)")
    p.add_argument("--plot", metavar="FILE", default=None,
                   help="where to write the plot, .png/.pdf/.svg (default: the problem file's name with "
                        ".png, in the current directory)")
    p.add_argument("--no-plot", action="store_true", help="do not plot")
    p.add_argument("--animate", metavar="FILE", default=None, help="also animate the motion (.gif)")
    p.add_argument("--html", metavar="FILE.html", default=None,
                   help="also write an interactive 3D page of the optimal motion (opens offline in any browser)")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="replace a model parameter's default value (repeatable)")
    p.add_argument("-v", "--verbose", action="store_true", help="show IPOPT's iterations")


@subcommand(
    "optimize",
    help="solve an optimal-control problem (TOML) with IPOPT",
    description=(
        "Build the model, transcribe the optimal-control problem described in the problem file "
        "(horizon, N, method, bounds, initial/final/periodic conditions, costs, free parameters; "
        "see docs/optimal-control.md) and solve it with IPOPT. Prints the solver's summary, then "
        "writes the optimal trajectory (.npz) and a plot of the motion, inputs, markers and "
        "constraint drift. If IPOPT fails, nothing is written and the message names IPOPT's "
        "status and the condition or bound most likely at fault."),
    examples=(
        "ncgen optimize examples/cartpole_swingup.toml                 # writes cartpole_swingup.npz/.png\n"
        "ncgen optimize examples/cartpole.toml --problem examples/cartpole_swingup.toml -o cp.npz\n"
        "ncgen optimize examples/cartpole_swingup.toml --plot cp.pdf --animate cp.gif -v\n"
        "ncgen optimize examples/cartpole_swingup.toml --html cp.html"),
    arguments=_arguments,
)
def optimize(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    from ncgen.files import atomic_path
    from ncgen.optim.plots import FORMATS, plot_solution
    from ncgen.optim.problem_file import model_path, problem_from_data, read_problem_file

    problem = Path(args.problem or args.file)
    output = Path(args.output or f"{problem.stem}.npz")
    plot = None if args.no_plot else Path(args.plot or f"{problem.stem}.png")
    if output.suffix.lower() != ".npz":
        parser.error(f"-o/--output {str(output)!r}: expected a file name ending in .npz")
    if plot is not None and plot.suffix.lower() not in FORMATS:
        parser.error(f"--plot {str(plot)!r}: expected a file name ending in {' or '.join(FORMATS)}")
    if args.animate and Path(args.animate).suffix.lower() not in (".gif", ".mp4"):
        parser.error(f"--animate {args.animate!r}: expected a file name ending in .gif or .mp4")
    if args.html and Path(args.html).suffix.lower() != ".html":
        parser.error(f"--html {args.html!r}: expected a file name ending in .html")
    for name in (output, plot, args.animate and Path(args.animate), args.html and Path(args.html)):
        if name and not name.resolve().parent.is_dir():
            parser.error(f"{name}: directory {str(name.parent)!r} does not exist")
    data, origin = read_problem_file(problem)
    if args.problem:
        model_file = Path(args.file)
    else:
        model_file = model_path(data, origin)
        if model_file is None:
            raise ProblemFileError(f"{origin}: model: missing; name the model file in the problem file "
                                   f"(model = \"cartpole.toml\") or give it first and the problem with --problem")
    model = load_model(str(model_file), args.param)
    ocp, options = problem_from_data(data, model, origin)
    kwargs = options.kwargs()
    kwargs["verbose"] = kwargs["verbose"] or args.verbose
    print(f"{ocp}: solving with IPOPT ...", file=sys.stderr)
    sol = ocp.solve(**kwargs)
    print(sol.summary())
    with contextlib.ExitStack() as stack:
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
