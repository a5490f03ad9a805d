"""``ncgen equilibrium`` and ``ncgen modes``: statics of a model (TOML or URDF) from the command line
(:func:`ncgen.equilibrium`, :func:`ncgen.modes`)."""
from __future__ import annotations

import argparse
import sys

from ncgen.cli.common import check_files, file_arguments, load_model, model_arguments
from ncgen.cli.registry import subcommand

#: What -o/--output accepts.
EQUILIBRIUM_OUTPUTS = MODES_OUTPUTS = (".csv", ".npz")


def _common_arguments(p: argparse.ArgumentParser) -> None:
    model_arguments(p)
    p.add_argument("--input", action="append", default=[], metavar="NAME=VALUE",
                   help="hold an input at a constant value (repeatable; default zero)")
    p.add_argument("--method", default="descent", choices=("descent", "newton"),
                   help="descent (default): Newton steps made to go down the potential, ends in a stable "
                        "equilibrium; newton: plain Newton, the nearest equilibrium of any stability")
    p.add_argument("--tol", type=float, default=1e-10, help="relative force tolerance (default 1e-10)")
    p.add_argument("--no-share", action="store_true",
                   help="keep every joint's equations (System.build(share=False)), so that every joint "
                        "has multipliers of its own; by default joints that shared coordinates express are "
                        "replaced by them, and their reactions come from the unshared form of the model")


def _equilibrium_arguments(p: argparse.ArgumentParser) -> None:
    _common_arguments(p)
    file_arguments(p, EQUILIBRIUM_OUTPUTS, "the equilibrium: .csv (name,value rows of q and lambda) or .npz",
                   plot="the equilibrium configuration",
                   html="an interactive 3D page of the equilibrium configuration (opens offline)")


def _modes_arguments(p: argparse.ArgumentParser) -> None:
    _common_arguments(p)
    file_arguments(p, MODES_OUTPUTS, "the modes: .csv (mode, frequency_hz, omega2, kind) or .npz (with the "
                   "shapes)", plot="the first vibration mode shapes", animate="one mode shape (see --mode)",
                   html="an interactive 3D page of one mode shape in motion (opens offline; see --mode)")
    p.add_argument("--mode", type=int, default=None, metavar="K",
                   help="mode to animate (--animate, --html), 1-based as in the table (default: the first "
                        "vibration mode)")


def _inputs(model, items: list[str]):
    import numpy as np

    from ncgen.errors import NcgenError
    u = np.zeros(model.nu)
    offsets = np.cumsum([0] + model.input_sizes)
    for item in items:
        name, sep, text = item.partition("=")
        if not sep or name.strip() not in model.input_names:
            raise NcgenError(f"--input {item!r}: expected NAME=VALUE with NAME one of "
                             f"{', '.join(model.input_names) or '(the model has no inputs)'}")
        i = model.input_names.index(name.strip())
        try:
            value = np.array([float(x) for x in text.split(",")])
        except ValueError:
            value = np.zeros(0)
        if value.size != model.input_sizes[i]:
            raise NcgenError(f"--input {item!r}: expected {model.input_sizes[i]} number(s), got {text!r}")
        u[offsets[i]:offsets[i + 1]] = value
    return u


def _solve(args):
    from ncgen.analysis.statics import equilibrium
    model = load_model(args.model, args.param, share=not args.no_share, floating_base=args.floating_base,
                       mjcf_contacts=args.mjcf_contacts)
    return equilibrium(model, u=_inputs(model, args.input), method=args.method, tol=args.tol)


@subcommand(
    "equilibrium",
    help="static equilibrium: configuration, reactions, stability",
    description=(
        "Build the model in MODEL (TOML or URDF) and solve F(q) - A(q)^T lambda = 0, Phi(q) = 0 by Newton's method "
        "on the constraints, from the model's initial configuration, with inputs held constant "
        "(--input) and without velocities. Prints the configuration, the multipliers (reactions, N per "
        "unit of each constraint), the spring and cable tensions (slack cables marked) and the "
        "stability: the reduced tangent stiffness on the motions the constraints allow is positive "
        "definite (stable), singular (neutral) or not (unstable)."),
    examples=(
        "ncgen equilibrium examples/double_pendulum.toml\n"
        "ncgen equilibrium examples/tensegrity.toml --param tension=5 -o eq.csv --plot eq.png\n"
        "ncgen equilibrium examples/cartpole.toml --input push=0 --method newton\n"
        "ncgen equilibrium examples/tensegrity.toml --html eq.html"),
    arguments=_equilibrium_arguments,
)
def equilibrium_command(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    check_files(args, parser, EQUILIBRIUM_OUTPUTS)
    eq = _solve(args)
    print(eq.table(), end="")
    model = eq.model
    if args.output:
        eq.save(args.output)
        print(f"wrote {args.output}", file=sys.stderr)
    if args.plot:
        from ncgen.viz.statics_pictures import plot_configuration
        plot_configuration(model, eq.q, args.plot, title=f"{model.name}: equilibrium ({eq.stability})")
        print(f"wrote {args.plot}", file=sys.stderr)
    if args.html:
        import numpy as np

        from ncgen.runtime.trajectory import Trajectory
        from ncgen.viz.html import to_html
        still = Trajectory.from_states(model, np.zeros(1), eq.q[None, :], np.zeros((1, model.nq)), eq.lam[None, :],
                                       eq.u[None, :], eq.p, {"method": "equilibrium", "complete": True})
        to_html(still, args.html, title=f"{model.name}: equilibrium ({eq.stability})", plots=False)
        print(f"wrote {args.html}", file=sys.stderr)
    return 0


@subcommand(
    "modes",
    help="natural frequencies (Hz) and mode shapes about an equilibrium",
    description=(
        "Find the model's static equilibrium (as 'ncgen equilibrium') and solve K_r x = omega^2 M_r x "
        "with the reduced tangent stiffness (geometric stiffness of prestressed springs and cables "
        "included) and reduced mass on the motions the constraints allow. Prints one row per mode: "
        "frequency (Hz), omega (rad/s), kind (vibration, zero: a mechanism or rigid motion, unstable) "
        "and the coordinate that moves most."),
    examples=(
        "ncgen modes examples/double_pendulum.toml\n"
        "ncgen modes examples/tensegrity.toml -o modes.csv --plot modes.png\n"
        "ncgen modes examples/chain.toml --animate mode1.gif --mode 1\n"
        "ncgen modes examples/tensegrity.toml --html mode2.html --mode 2"),
    arguments=_modes_arguments,
)
def modes_command(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    from ncgen.analysis.modes import modes
    check_files(args, parser, MODES_OUTPUTS)
    eq = _solve(args)
    result = modes(eq.model, eq)
    print(result.table(), end="")
    if args.output:
        result.save(args.output)
        print(f"wrote {args.output}", file=sys.stderr)
    if args.plot:
        from ncgen.viz.statics_pictures import plot_modes
        plot_modes(result, args.plot)
        print(f"wrote {args.plot}", file=sys.stderr)
    if args.animate or args.html:
        vib = [i for i, k in enumerate(result.kind) if k == "vibration"]
        k = (vib[0] if vib else 0) if args.mode is None else args.mode - 1
        if not 0 <= k < len(result.kind):
            parser.error(f"--mode {args.mode}: expected a mode number in 1..{len(result.kind)}")
    if args.html:
        from ncgen.viz.html import to_html
        what = f"{result.frequencies[k]:.4g} Hz" if result.kind[k] == "vibration" else result.kind[k]
        to_html(result.trajectory(k, cycles=4), args.html, title=f"{eq.model.name}: mode {k + 1} ({what})")
        print(f"wrote {args.html}", file=sys.stderr)
    if args.animate:
        from ncgen.viz.statics_pictures import animate_mode
        animate_mode(result, k, args.animate)
        print(f"wrote {args.animate}", file=sys.stderr)
    return 0
