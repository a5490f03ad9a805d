"""``ncgen simulate``: a model's trajectory, with plots and animations."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ncgen.cli.common import check_files, file_arguments, load_model, model_arguments
from ncgen.cli.registry import subcommand
from ncgen.runtime.backend_policy import RULE


#: What -o/--output accepts.
OUTPUTS = (".npz", ".csv")


def _simulate_arguments(p: argparse.ArgumentParser) -> None:
    model_arguments(p)
    p.add_argument("--t-end", type=float, default=2.0, metavar="T", help="final time (s, default 2)")
    p.add_argument("--dt", type=float, default=0.01, metavar="DT",
                   help="output step (s, default 0.01); IDAS chooses its own internal steps")
    file_arguments(p, OUTPUTS, "the trajectory: .npz (everything, nc.Trajectory.load reads it) or .csv (t, q, v, "
                   "joint angles and rates, markers, energies, residuals, contact gaps and forces; units in the "
                   "header)", plot="the energy (drift, or the balance of a dissipative run), constraint drift "
                   "and markers", animate="the motion",
                   html="an interactive 3D page of the run (opens offline in any browser: orbit, play, time "
                        "slider, plots; FILE.html?t=1.5 opens paused at t = 1.5 s)")
    p.add_argument("--method", default="auto", metavar="METHOD",
                   help="integrator: auto (default: joint for a tree without contacts, else idas), joint "
                        "(joint coordinates in a compiled C loop: Dormand-Prince 5(4) with error control, or "
                        "--integrator rk4 with --substeps), idas (variable-step BDF with error control) or "
                        "stepper (the compiled constraint-preserving stepper: fixed steps DT/N, see "
                        "--substeps, or error-controlled with --rtol) or rolling (models with [[rolling]] "
                        "elements, the auto choice for them without drives: projected Runge-Kutta, --integrator; "
                        "idas and stepper (RATTLE with velocity constraints, fixed steps) take them too)")
    p.add_argument("--integrator", default=None, choices=("dopri5", "rk4"),
                   help="joint and rolling methods: dopri5 (error-controlled, default) or rk4 (--substeps fixed "
                        "steps per DT)")
    p.add_argument("--controller", default=None, metavar="TABLE",
                   help="a compiled controller, as the keys of a TOML [controller] table, e.g. "
                        "'kind = \"pd\", kp = 100, kd = 20, target = [0.1, -0.3]' (kind pd or computed_torque; "
                        "targets one per actuated joint rate); replaces the model file's [controller]")
    p.add_argument("--joint-dynamics", action="store_true",
                   help="honour the joints' damping, friction and position limits (URDF <dynamics>, <limit>) "
                        "by a stiff law (joint and idas methods)")
    p.add_argument("--contacts", default="smooth", choices=("smooth", "nonsmooth"),
                   help="contacts of the model: smooth (compliant law, any method; default) or nonsmooth "
                        "(rigid impacts and Coulomb friction; --method stepper only, fixed steps)")
    p.add_argument("--substeps", type=int, default=1, metavar="N",
                   help="stepper (and joint with --integrator rk4): fixed steps of DT/N per output interval "
                        "(default 1); a stepper run whose own checks find it untrustworthy stops with an "
                        "error naming the N to use")
    p.add_argument("--backend", default="auto", choices=("auto", "compiled", "vm"),
                   help="where IDAS evaluates the equations: compiled (generated C, built once and "
                        "cached by content), vm (CasADi's virtual machine) or " + RULE)
    p.add_argument("--kernels", default="auto", choices=("auto", "tables", "flat"),
                   help="joint and stepper methods: tables (the kernels of every shipped kind over the model's "
                        "data tables, compiled once per ncgen version: nothing compiled for the model), flat "
                        "(the model's own C, compiled once per model and cached) or auto (default: the tables, "
                        "unless the model's own code is ready or the run is long enough to win back its "
                        "compile; the summary says which ran and why)")
    p.add_argument("--rtol", type=float, default=None,
                   help="relative tolerance: IDAS's and the joint loop's (default 1e-8); with --method stepper, the stepper "
                        "chooses its steps to meet it (default: fixed steps of DT, checked)")
    p.add_argument("--atol", type=float, default=None,
                   help="absolute tolerance (units of q and v): IDAS's (default 1e-10); the stepper's "
                        "(default: rtol)")


def _controller(text: str):
    """The controller of ``--controller`` (the keys of a TOML ``[controller]`` table)."""
    import tomllib

    from ncgen.errors import ModelError
    from ncgen.model.controllers import controller_from_dict

    try:
        data = tomllib.loads(f"controller = {{ {text} }}")["controller"]
    except tomllib.TOMLDecodeError as e:
        raise ModelError(f"--controller {text!r}: not the keys of a TOML table ({e}); expected e.g. "
                         "'kind = \"pd\", kp = 100, kd = 20, target = 0.0'") from None
    return controller_from_dict(data, "--controller")


def _compile_ahead(args: argparse.Namespace) -> None:
    """A URDF robot (a tree without contacts) runs in joint space on the tree tables unless the
    options say otherwise: its first run compiles the tree library's forward unit (once per
    ncgen version), started here in the background so that gcc runs while the robot is read and
    built (:func:`~ncgen.runtime.tree_library.compile_ahead`; the run's choice of kernels is
    that of a run that found the unit missing)."""
    if Path(args.model).suffix.lower() != ".urdf" or args.method not in ("auto", "joint") or \
            args.kernels == "flat" or args.controller or args.joint_dynamics or args.backend == "vm":
        return
    from ncgen.runtime.tree_library import compile_ahead

    compile_ahead(("forward",))


@subcommand(
    "simulate",
    help="simulate a model: trajectory, plot, animation",
    description=(
        "Build the model in MODEL (TOML or URDF), integrate it from its consistent initial state to --t-end "
        "(inputs held at zero, or driven by a compiled controller: --controller or the file's [controller] "
        "table; use the Python API, nc.simulate(..., u=...), for other inputs) on the grid 0, dt, 2 dt, ..., "
        "writing the trajectory to -o FILE if given. A summary (integrator work, energy drift or, for "
        "dissipative runs, the energy balance: work of contacts, dampers, inputs and its residual; "
        "constraint drift) goes to standard output. Files are written only when the whole run "
        "succeeds: a failed integration says where and why it failed, and writes the trajectory up "
        "to that time to OUTPUT (default MODEL.npz) with '.incomplete' before the suffix (e.g. run.incomplete.npz, "
        "whose info says complete = false)."),
    examples=(
        "ncgen simulate examples/chain.toml --t-end 2 --dt 0.01 -o chain.npz --plot chain.png\n"
        "ncgen simulate examples/heavy_top.toml --html top.html      # open top.html in a browser\n"
        "ncgen simulate examples/heavy_top.toml --t-end 3 -o top.csv --animate top.gif\n"
        "ncgen simulate examples/slider_crank.toml --t-end 1 -o sc.npz --param omega=20 --backend vm\n"
        "ncgen simulate examples/tensegrity.toml --t-end 2 -o t.npz --method stepper --substeps 20\n"
        "ncgen simulate examples/tensegrity.toml --t-end 2 -o t.npz --method stepper --rtol 1e-6\n"
        "ncgen simulate balls.toml --t-end 2 --dt 1e-4 -o balls.npz --method stepper --contacts nonsmooth\n"
        "ncgen simulate robot.urdf --t-end 1 -o robot.csv   # URDF: falls under gravity, zero torque\n"
        "ncgen simulate solo12.urdf --floating-base --t-end 0.5   # a free-floating base; summary only\n"
        "ncgen simulate robot.urdf --t-end 2 -o hold.npz --controller 'kind = \"pd\", kp = 200, kd = 20' "
        "--joint-dynamics   # PD to the zero pose, damping and limits from the URDF"),
    arguments=_simulate_arguments,
)
def simulate(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    import contextlib

    from ncgen.errors import SimulationError, SimulationInterrupted
    from ncgen.files import atomic_path, incomplete_path
    from ncgen.runtime import simulate as run

    check_files(args, parser, OUTPUTS)
    _compile_ahead(args)
    model = load_model(args.model, args.param, args.contacts, floating_base=args.floating_base,
                       mjcf_contacts=args.mjcf_contacts)
    try:
        stepper = {"substeps": args.substeps} if args.method in ("stepper", "joint", "rolling", "auto") else {}
        controller = _controller(args.controller) if args.controller else model.controller
        traj = run(model, t_end=args.t_end, dt=args.dt, method=args.method, backend=args.backend,
                   rtol=args.rtol, atol=args.atol, integrator=args.integrator, u=controller,
                   joint_dynamics=args.joint_dynamics, kernels=args.kernels, **stepper)
    except (SimulationError, SimulationInterrupted) as e:
        if e.trajectory is None or not len(e.trajectory):
            raise
        partial = [e.trajectory.save(incomplete_path(args.output))] if args.output else []
        if args.html:
            partial.append(e.trajectory.to_html(incomplete_path(args.html)))
        if not partial:
            raise
        said = (f"{e}\nThe partial trajectory (t = {e.trajectory.t[0]:g} ... {e.trajectory.t[-1]:g} s, marked "
                f"incomplete) was written to {' and '.join(str(x) for x in partial)}")
        if isinstance(e, SimulationInterrupted):
            raise SimulationInterrupted(said, time=e.time, trajectory=e.trajectory) from None
        raise SimulationError(said, time=e.time, trajectory=e.trajectory) from None
    print(traj.summary())
    with contextlib.ExitStack() as stack:
        if args.output:
            traj.save(stack.enter_context(atomic_path(args.output)))
        if args.plot:
            from ncgen.viz import plot
            plot(traj, stack.enter_context(atomic_path(args.plot)))
        if args.animate:
            from ncgen.viz import animate
            animate(traj, stack.enter_context(atomic_path(args.animate)))
        if args.html:
            from ncgen.viz.html import to_html
            to_html(traj, stack.enter_context(atomic_path(args.html)))
    for name in (args.output, args.plot, args.animate, args.html):
        if name:
            print(f"wrote {name}", file=sys.stderr)
    return 0
