"""``ncgen mpc``: export the model-predictive controller of a problem file as a standalone C
package (docs/control.md)."""
from __future__ import annotations

import argparse
from pathlib import Path

from ncgen.cli.common import check_files, load_model, missing_model, mjcf_contacts_argument
from ncgen.cli.registry import subcommand


def _arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("problem", metavar="PROBLEM.toml",
                   help="an optimal-control problem file naming its model (docs/optimal-control.md)")
    p.add_argument("-o", "--output", metavar="DIR", required=True, help="directory of the C package")
    p.add_argument("--name", default=None, help="package and C prefix (default: the model's name)")
    p.add_argument("--solver", choices=("sqp", "fatrop"), default="sqp",
                   help="the controller's solver: sqp (default; the real-time-iteration SQP, no library needed) "
                        "or fatrop (Fatrop's interior-point method on the joint-space problem of a tree; the "
                        "package links libfatrop and libblasfeo from the CasADi wheel, the Makefile's FATROP_DIR)")
    p.add_argument("--iterations", type=int, default=1,
                   help="SQP iterations (fatrop: solves) per control step (default 1: the real-time iteration)")
    p.add_argument("--terminal-weight", type=float, default=1e3,
                   help="weight of the problem's final conditions, soft in MPC (default 1000)")
    p.add_argument("--x0", default=None, metavar="Q=V,...",
                   help="the demo's initial state as coordinate=value pairs (the others assembled, at rest), "
                        "e.g. pole.r_j.x=0.1 (coordinates as written before coordinate sharing too); "
                        "default: the problem file's [initial] state, else the model's")
    p.add_argument("--t-end", type=float, default=5.0, help="the demo's duration, s (default 5)")
    p.add_argument("--substeps", type=int, default=5, help="plant steps per control step in the demo (default 5)")
    p.add_argument("--disturbance", action="append", default=[], metavar="T_ON:T_OFF:U1,U2,...",
                   help="an input pulse added by the demo's plant (repeatable), e.g. 1.0:1.1:8")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="replace a model parameter's default value (repeatable)")
    mjcf_contacts_argument(p)


@subcommand(
    "mpc",
    help="export a model-predictive controller as a standalone C package",
    description=(
        "Read the optimal-control problem file, turn it into a receding-horizon controller "
        "(the model's RATTLE step with exact Jacobians, a real-time-iteration SQP with CasADi's "
        "qrqp; the problem's final conditions become a terminal penalty) and write it as a C "
        "package: the solver, the plant step, the API <name>_mpc_step(m, x, t, u_out) in "
        "<name>_mpc.h, a closed-loop demo program and a Makefile. `make && ./demo` needs no Python."),
    examples=(
        "ncgen mpc examples/cartpole_mpc.toml -o cartpole_mpc\n"
        "ncgen mpc examples/cartpole_mpc.toml -o cp --x0 pole.r_j.x=0.1,pole.r_j.y=0.49 --disturbance 1.0:1.1:8\n"
        "ncgen mpc examples/cartpole_mpc.toml -o cp_fatrop --solver fatrop\n"
        "cd cartpole_mpc && make && ./demo 5 > run.txt"),
    arguments=_arguments,
)
def mpc(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    from ncgen.control.export import MAX_T_END, export_mpc
    from ncgen.optim.problem_file import model_path, problem_from_data, read_problem_file

    check_files(args, parser, None, directories=("output",))
    if not 0 < args.t_end <= MAX_T_END:
        parser.error(f"--t-end: expected the demo's duration in seconds, 0 < T <= {MAX_T_END:g}, got {args.t_end:g}")
    for flag, value in (("--iterations", args.iterations), ("--substeps", args.substeps)):
        if value < 1:
            parser.error(f"{flag}: expected a positive integer, got {value}")
    if not 0 <= args.terminal_weight < float("inf"):
        parser.error(f"--terminal-weight: expected a finite number >= 0, got {args.terminal_weight:g}")
    data, origin = read_problem_file(Path(args.problem))
    model_file = model_path(data, origin)
    if model_file is None:
        raise missing_model(origin, data, "mpc")
    model = load_model(str(model_file), args.param, mjcf_contacts=args.mjcf_contacts)
    ocp, _ = problem_from_data(data, model, origin)
    x0 = _start_state(model, args.x0, parser) if args.x0 else None
    pulses = [_pulse(item, parser) for item in args.disturbance]
    pkg = export_mpc(ocp, args.output, name=args.name, solver=args.solver, iterations=args.iterations,
                     terminal_weight=args.terminal_weight, x0=x0, t_end=args.t_end, substeps=args.substeps,
                     disturbance=pulses)
    print(f"wrote the MPC package {pkg.name!r} to {pkg.path}: build it with `make -C {pkg.path}`, "
          f"run `{pkg.path}/demo`")
    return 0


def _start_state(model, text: str, parser: argparse.ArgumentParser):
    """``--x0 coordinate=value,...``: the consistent state at rest with those coordinates
    (the others assembled from the model's), or the parser's error naming the bad item."""
    import numpy as np

    from ncgen.assembly.kinematics import assemble
    from ncgen.errors import NcgenError
    values = {}
    for item in text.split(","):
        key, _, value = item.partition("=")
        try:
            model.coordinate(key)
        except NcgenError as exc:
            parser.error(f"--x0: {exc}")
        try:
            values[key] = float(value)
        except ValueError:
            values[key] = np.nan
        if not np.isfinite(values[key]):
            parser.error(f"--x0: {item!r}: expected coordinate=number (a finite number)")
    try:
        return np.concatenate([assemble(model, model.q0, values=values), np.zeros(model.nq)])
    except NcgenError as exc:
        parser.error(f"--x0 {text}: no consistent state has these coordinates: {exc}")


def _pulse(item: str, parser: argparse.ArgumentParser) -> tuple:
    """``--disturbance T_ON:T_OFF:U1,U2,...``: ``(t_on, t_off, values)``, or the parser's error."""
    import numpy as np

    parts = item.split(":")
    try:
        t_on, t_off, values = float(parts[0]), float(parts[1]), [float(v) for v in parts[2].split(",")]
    except (ValueError, IndexError):
        parser.error(f"--disturbance {item!r}: expected T_ON:T_OFF:U1,U2,... (numbers)")
    if not (np.isfinite(t_on) and np.isfinite(t_off) and t_on < t_off and np.all(np.isfinite(values))):
        parser.error(f"--disturbance {item!r}: expected finite numbers with T_ON < T_OFF")
    return t_on, t_off, values
