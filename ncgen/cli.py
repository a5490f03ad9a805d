"""The ``ncgen`` command line.

Every subcommand is one function decorated with :func:`subcommand`: the decorator registers
its name, one-line help, description and examples (shown by ``ncgen SUBCOMMAND --help``)
and a function adding its arguments; the decorated function receives the parsed arguments
and the subparser, and returns the exit code.  To add a subcommand, write::

    def _frob_arguments(p: argparse.ArgumentParser) -> None:
        p.add_argument("model", help="model file (TOML)")

    @subcommand("frob", help="...", description="...", examples="ncgen frob m.toml",
                arguments=_frob_arguments)
    def frob(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
        ...
        return 0

Import heavy modules (CasADi, the runtime, compilers) inside the function so that
``ncgen --help`` stays fast.
Exit codes: 0 success, 1 failure while running, 2 bad usage (argparse's convention).
Bad input raised as :class:`ncgen.errors.NcgenError` is reported without a traceback.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from ncgen import __version__
from ncgen.errors import NcgenError


@dataclass(frozen=True)
class Subcommand:
    name: str
    help: str
    description: str
    examples: str
    arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace, argparse.ArgumentParser], int]


SUBCOMMANDS: dict[str, Subcommand] = {}


def subcommand(name: str, *, help: str, description: str, examples: str,
               arguments: Callable[[argparse.ArgumentParser], None]):
    """Register the decorated ``run(args, parser) -> int`` as ``ncgen NAME``."""
    def register(run):
        if name in SUBCOMMANDS:
            raise RuntimeError(f"ncgen subcommand {name!r} registered twice")
        SUBCOMMANDS[name] = Subcommand(name, help, description, examples, arguments, run)
        return run
    return register


def write_output(text: str, path: str | None) -> None:
    """``text`` to stdout, or to ``path`` atomically (temporary file in the same directory,
    then rename), so that a failed run never leaves a truncated file."""
    if path is None or path == "-":
        sys.stdout.write(text)
        return
    target = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent.resolve())
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        os.chmod(tmp, _new_file_mode(target))
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    print(f"wrote {target}", file=sys.stderr)


def _new_file_mode(target: Path) -> int:
    """The existing file's mode, or the default for a new file (0666 minus the umask)."""
    if target.exists():
        return target.stat().st_mode & 0o7777
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


# --------------------------------------------------------------------------- derive
def _type_list(dim: int) -> str:
    from ncgen.symbolic.coordinates import TYPES
    extra = ", se3 (rigid motion)" if dim == 3 else ""
    return ", ".join(f"{n} ({kind})" for n, kind in TYPES[dim].items()) + extra


def _derive_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("type", metavar="TYPE",
                   help="coordinate type (see the list below) or 'se3' for the rigid-motion algebra")
    p.add_argument("--dim", type=int, choices=(2, 3), default=None,
                   help="dimension: 3 (default) or 2 for planar members")
    p.add_argument("--format", choices=("text", "markdown", "latex"), default="text",
                   help="text (terminal, default), markdown (with $$ math) or latex (a complete "
                        "document for pdflatex)")
    p.add_argument("-o", "--output", metavar="FILE", default=None,
                   help="write to FILE instead of standard output")


@subcommand(
    "derive",
    help="show the derivation of a natural-coordinate type, for teaching",
    description=(
        "Show, step by step, how a natural-coordinate type is derived from the seed's "
        "definitions: coordinates and base vectors, the conversion matrix Y = Ybar (x) I, "
        "the transformation C(c), the intrinsic constraints, their Jacobian and constant "
        "Hessians, the mass matrix from mass, centre of mass and inertia, and the pose / "
        "angular-velocity relations. Every formula shown is the one ncgen computes with.\n\n"
        f"3D types: {_type_list(3)}\n"
        f"2D types (--dim 2): {_type_list(2)}"),
    examples=(
        "ncgen derive rrvw                       # 3D body with two basic points, in the terminal\n"
        "ncgen derive rr --dim 2 --format markdown\n"
        "ncgen derive ruvw --format latex -o ruvw.tex && pdflatex ruvw.tex\n"
        "ncgen derive se3                        # rigid-motion algebra (poses, twists, wrenches)"),
    arguments=_derive_arguments,
)
def derive(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    if args.type == "se3":
        if args.dim == 2:
            parser.error("se3 is three-dimensional; drop --dim 2")
        try:
            from ncgen.symbolic.rigid_motion import se3_report
        except ImportError as exc:
            if getattr(exc, "name", None) not in ("ncgen.symbolic.rigid_motion", None):
                raise
            print("ncgen derive: the se3 derivation is not available yet "
                  "(ncgen.symbolic.rigid_motion.se3_report is missing in this version)", file=sys.stderr)
            return 1
        report = se3_report()
    else:
        from ncgen.symbolic.coordinates import TYPES
        from ncgen.symbolic.teaching import coordinates_report
        dim = 3 if args.dim is None else args.dim
        if args.type not in TYPES[dim]:
            other = 5 - dim
            hint = f" ({args.type!r} is a {other}D type: add --dim {other})" if args.type in TYPES[other] else ""
            parser.error(f"unknown TYPE {args.type!r} for --dim {dim}{hint}\n"
                         f"valid types for --dim {dim}: {_type_list(dim)}")
        report = coordinates_report(args.type, dim)
    write_output(report.render(args.format), args.output)
    return 0


# ------------------------------------------------------------------------- models
def load_model(path: str, params: list[str] | None = None):
    """Build the model in TOML file ``path``; ``params`` (``name=value`` strings, a vector as
    ``name=1,2,3``) replace default parameter values.  Raises NcgenError with a message
    naming the file (and the key path, for invalid models)."""
    from ncgen.model.members import ModelError
    from ncgen.model.system import System

    file = Path(path)
    if not file.is_file():
        what = "is a directory, not" if file.is_dir() else "does not exist; expected"
        raise ModelError(f"model file {path!r} {what} a TOML model file (see the examples/ directory)")
    try:
        system = System.from_toml(file)
    except NcgenError as e:
        text = str(e)
        raise type(e)(text if text.startswith(str(file)) else f"{path}: {text}") from None
    for name, value in _parameter_overrides(params or [], system):
        system.parameters[name] = (system.parameters[name][0], value)
    try:
        return system.build()
    except NcgenError as e:
        raise type(e)(f"{path}: model {system.name!r} cannot be built: {e}") from None


def _parameter_overrides(params: list[str], system) -> list[tuple]:
    import numpy as np

    from ncgen.model.members import ModelError

    out = []
    for item in params:
        name, sep, text = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise ModelError(f"--param {item!r}: expected NAME=VALUE, e.g. --param k=50")
        if name not in system.parameters:
            known = ", ".join(system.parameters) or "none"
            raise ModelError(f"--param {item!r}: model {system.name!r} has no parameter {name!r} "
                             f"(parameters: {known})")
        size = system.parameters[name][1].size
        try:
            value = np.array([float(x) for x in text.split(",")])
        except ValueError:
            value = np.zeros(0)
        if value.size != size or not np.all(np.isfinite(value)):
            raise ModelError(f"--param {item!r}: expected {size} finite number(s) for {name!r}, "
                             f"separated by commas, got {text!r}")
        out.append((name, value))
    return out


# ----------------------------------------------------------------------- generate
def _generate_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("model", metavar="MODEL.toml", help="model file (TOML)")
    p.add_argument("-o", "--output", metavar="DIR", required=True,
                   help="package directory to write (replaced if it holds an ncgen package; "
                        "refused if it holds anything else)")
    p.add_argument("--compile", action="store_true",
                   help="also build the shared library now (cached by content); the package is "
                        "written only if compiling succeeds")
    p.add_argument("--cflags", metavar="FLAGS", default=None,
                   help="C compiler flags for --compile, for every file (default: $NCGEN_CFLAGS, "
                        "else -O2, and -O0 for files holding functions too long for gcc's optimiser)")
    p.add_argument("--reroll", metavar="N", default=None, type=_reroll_limit,
                   help="generate functions longer than N SX instructions as loops over short "
                        "kernels found in them (compiles in seconds for any number of members, "
                        "runs about 2-4x slower than straight-line code at -O2); 'none': "
                        "straight-line code only (default: 20000, lowered to 1000 for a model whose "
                        "functions total over 40000 instructions, a chain of about 90 bars)")


def _reroll_limit(text: str) -> int | str:
    """``--reroll``: a number of instructions, or ``"none"``."""
    if text.strip().lower() == "none":
        return "none"
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a number of instructions >= 0 or 'none', got {text!r}")
    return value


@subcommand(
    "generate",
    help="write a model's self-contained C package",
    description=(
        "Build the model in MODEL.toml and write its C package to DIR: the system functions "
        "(constraints, Jacobian, forces, M^-1, the DAE with its sparse Jacobian, accelerations, "
        "energies, markers, poses) as CasADi-generated C, a header documenting every function "
        "(argument sizes, units, meaning) and the model (dimensions, names, initial state, mass "
        "matrix), a Makefile and CMakeLists.txt, main.c (evaluates the model without Python) and "
        "manifest.json. The same model always gives the same bytes."),
    examples=(
        "ncgen generate examples/chain.toml -o chain_c       # then: make -C chain_c && chain_c/chain_main\n"
        "ncgen generate examples/heavy_top.toml -o top --compile --cflags='-O3 -march=native'"),
    arguments=_generate_arguments,
)
def generate(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    from ncgen.codegen.build import compile_package
    from ncgen.codegen.model_package import generate as generate_package
    from ncgen.codegen.reroll import REROLL_INSTRUCTIONS

    model = load_model(args.model)
    limit = {None: REROLL_INSTRUCTIONS, "none": None}.get(args.reroll, args.reroll)
    pkg = generate_package(model, args.output, cflags=args.cflags, compile=args.compile,
                           reroll_instructions=limit)
    print(f"wrote {pkg.path}: C package {pkg.name!r} ({len(pkg.manifest['files']) + 1} files, "
          f"{len(pkg.function_names)} functions; nq = {model.nq}, nc = {model.nc}, dof = {model.dof})",
          file=sys.stderr)
    if args.compile:
        built = compile_package(pkg, cflags=args.cflags)
        print(f"compiled {built.path}", file=sys.stderr)
    return 0


# -------------------------------------------------------------------------- check
def _check_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("model", metavar="MODEL.toml", help="model file (TOML)")
    p.add_argument("--tolerance", type=float, default=1e-6, metavar="TOL",
                   help="largest correction of the initial state, relative to the model's size, "
                        "that still counts as consistent (default 1e-6, as System.build)")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="replace a parameter's default value (repeatable; a vector as NAME=1,2,3)")
    p.add_argument("--no-share", action="store_true",
                   help="keep every joint's equations (System.build(share=False)) instead of eliminating "
                        "the joints that shared coordinates express")


@subcommand(
    "check",
    help="DOF, constraint rank and initial-state check of a model",
    description=(
        "Build the model in MODEL.toml and print its members, joints and forces, its coordinates "
        "and constraints, the rank of the constraint Jacobian A, the degrees of freedom "
        "(nq - rank A), the redundant constraints by name, and the residuals of the initial state "
        "as given (max |Phi| and max |A v + Phi_t|) with the corrections that make it consistent, "
        "and what coordinate sharing did: the joints eliminated (replaced by shared basic points "
        "and axes, or merged bodies) with nq and nc before and after. "
        "Exit code 0 if the model builds and its initial state is consistent within the "
        "tolerance, 1 otherwise."),
    examples=(
        "ncgen check examples/fourbar_planar.toml\n"
        "ncgen check examples/fourbar_3d.toml --tolerance 1e-9\n"
        "ncgen check examples/fourbar_3d.toml --no-share   # every joint as equations\n"
        "ncgen check mymodel.toml --param k=50 || echo 'fix the initial state'"),
    arguments=_check_arguments,
)
def check(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    from ncgen.assembly.check import check_system
    from ncgen.model.members import ModelError
    from ncgen.model.system import System

    file = Path(args.model)
    if not file.is_file():
        what = "is a directory, not" if file.is_dir() else "does not exist; expected"
        raise ModelError(f"model file {args.model!r} {what} a TOML model file (see the examples/ directory)")
    if not args.tolerance > 0:
        parser.error(f"--tolerance: expected a positive number, got {args.tolerance}")
    system = System.from_toml(file)
    for name, value in _parameter_overrides(args.param, system):
        system.parameters[name] = (system.parameters[name][0], value)
    report = check_system(system, tolerance=args.tolerance, share=not args.no_share)
    sys.stdout.write(report.render(args.model))
    return 0 if report.ok else 1


# ----------------------------------------------------------------------- simulate
#: Output kinds of 'ncgen simulate' and the file suffixes each accepts.
SUFFIXES = {"output": (".npz", ".csv"), "plot": (".png", ".pdf", ".svg"), "animate": (".gif", ".mp4")}


def _simulate_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("model", metavar="MODEL.toml", help="model file (TOML)")
    p.add_argument("--t-end", type=float, required=True, metavar="T", help="final time (s)")
    p.add_argument("--dt", type=float, default=0.01, metavar="DT",
                   help="output step (s, default 0.01); IDAS chooses its own internal steps")
    p.add_argument("-o", "--output", metavar="FILE", required=True,
                   help="trajectory file: .npz (everything, nc.Trajectory.load reads it) or .csv "
                        "(t, coordinates, energies, constraint residuals)")
    p.add_argument("--plot", metavar="FILE", default=None,
                   help="also plot energy drift, constraint drift and the markers (.png, .pdf, .svg)")
    p.add_argument("--animate", metavar="FILE", default=None,
                   help="also animate the motion (.gif, or .mp4 with ffmpeg)")
    p.add_argument("--method", default="idas", metavar="METHOD",
                   help="integrator: idas (variable-step BDF with error control, default) or stepper "
                        "(the compiled fixed-step constraint-preserving stepper)")
    p.add_argument("--backend", default="auto", choices=("auto", "compiled", "vm"),
                   help="where the equations run: compiled (generated C, built once and cached), vm "
                        "(CasADi's virtual machine) or auto (compiled if a C compiler is found; default)")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="replace a parameter's default value (repeatable; a vector as NAME=1,2,3)")
    p.add_argument("--rtol", type=float, default=1e-8, help="relative tolerance of IDAS (default 1e-8)")
    p.add_argument("--atol", type=float, default=1e-10, help="absolute tolerance of IDAS (default 1e-10)")


def _check_outputs(args: argparse.Namespace, parser: argparse.ArgumentParser) -> None:
    """Usage errors in the output file names, found before any work is done."""
    for kind, suffixes in SUFFIXES.items():
        name = getattr(args, kind)
        if name is None:
            continue
        option = "-o/--output" if kind == "output" else f"--{kind}"
        if Path(name).suffix.lower() not in suffixes:
            parser.error(f"{option} {name!r}: expected a file name ending in {' or '.join(suffixes)}")
        if not Path(name).resolve().parent.is_dir():
            parser.error(f"{option} {name!r}: directory {str(Path(name).parent)!r} does not exist")


@subcommand(
    "simulate",
    help="simulate a model: trajectory, plot, animation",
    description=(
        "Build the model in MODEL.toml, integrate it from its consistent initial state to --t-end "
        "(inputs held at zero; use the Python API, nc.simulate(..., u=...), to drive them) and write "
        "the trajectory on the grid 0, dt, 2 dt, ... A summary (integrator work, energy and "
        "constraint drift) goes to standard output. Files are written only when the whole run "
        "succeeds: a failed integration leaves nothing behind and says where and why it failed."),
    examples=(
        "ncgen simulate examples/chain.toml --t-end 2 --dt 0.01 -o chain.npz --plot chain.png\n"
        "ncgen simulate examples/heavy_top.toml --t-end 3 -o top.csv --animate top.gif\n"
        "ncgen simulate examples/slider_crank.toml --t-end 1 -o sc.npz --param omega=20 --backend vm\n"
        "ncgen simulate examples/tensegrity.toml --t-end 2 -o t.npz --method stepper"),
    arguments=_simulate_arguments,
)
def simulate(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    import contextlib

    from ncgen.files import atomic_path
    from ncgen.runtime import simulate as run

    _check_outputs(args, parser)
    model = load_model(args.model, args.param)
    traj = run(model, t_end=args.t_end, dt=args.dt, method=args.method, backend=args.backend,
               rtol=args.rtol, atol=args.atol)
    print(traj.summary())
    with contextlib.ExitStack() as stack:
        traj.save(stack.enter_context(atomic_path(args.output)))
        if args.plot:
            from ncgen.viz import plot
            plot(traj, stack.enter_context(atomic_path(args.plot)))
        if args.animate:
            from ncgen.viz import animate
            animate(traj, stack.enter_context(atomic_path(args.animate)))
    for name in (args.output, args.plot, args.animate):
        if name:
            print(f"wrote {name}", file=sys.stderr)
    return 0


# --------------------------------------------------------------------------- demo
def _demo_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("-o", "--output", metavar="DIR", default="ncgen-demo",
                   help="directory for the C package, trajectory, plot and animation "
                        "(default ./ncgen-demo, created if needed)")
    p.add_argument("--animate", action="store_true", help="also write an animation (GIF)")
    p.add_argument("--t-end", type=float, default=1.4, metavar="T",
                   help="simulated time (s, default 1.4: one turn of precession)")
    p.add_argument("--backend", default="compiled", choices=("compiled", "vm"),
                   help="compiled (generated C, default) or vm (CasADi's virtual machine, no compiler)")


@subcommand(
    "demo",
    help="the whole pipeline on a built-in heavy top",
    description=(
        "Run ncgen end to end on a heavy symmetric top spinning on a fixed tip (one 'ruvw' body "
        "whose tip is a ground point shared by its natural coordinates: 9 coordinates, 6 "
        "constraints, 3 degrees of freedom), released without precession so that it nutates. "
        "Stages: build (SymPy derivation to CasADi functions and a consistent initial state), "
        "generate the C package, compile it (cached: a second run is a cache hit), simulate with "
        "IDAS on the compiled DAE, check the motion against the top's exact first integrals "
        "(energy, vertical angular momentum, spin) and the exact turning points of its nutation, "
        "and plot it. Prints the timing of each stage."),
    examples=(
        "ncgen demo                          # writes ./ncgen-demo/heavy_top.png and more\n"
        "ncgen demo -o /tmp/demo --animate   # also heavy_top.gif\n"
        "ncgen demo --backend vm             # without a C compiler"),
    arguments=_demo_arguments,
)
def demo(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    from ncgen.demo import run_demo

    out = Path(args.output)
    if out.exists() and not out.is_dir():
        parser.error(f"-o/--output {args.output!r} exists and is not a directory")
    if not args.t_end > 0:
        parser.error(f"--t-end: expected a positive time, got {args.t_end}")
    print(run_demo(out, animate=args.animate, t_end=args.t_end, backend=args.backend).summary())
    return 0


# ----------------------------------------------------------------------------- main
def build_parser() -> argparse.ArgumentParser:
    import ncgen.optim.command  # noqa: F401  (registers 'optimize'; imports ncgen.cli, so not at the top)

    parser = argparse.ArgumentParser(
        prog="ncgen",
        description="Rigid multibody dynamics in natural coordinates: SymPy derivations, "
                    "CasADi functions, generated C, simulation and optimisation.",
        epilog="examples:\n" + "".join(f"  {cmd.examples.splitlines()[0]}\n" for cmd in SUBCOMMANDS.values())
               + "\nRun 'ncgen SUBCOMMAND --help' for a subcommand's options and more examples.",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"ncgen {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="SUBCOMMAND", title="subcommands")
    for cmd in SUBCOMMANDS.values():
        p = sub.add_parser(cmd.name, help=cmd.help, description=cmd.description,
                           epilog="examples:\n" + "\n".join("  " + line for line in cmd.examples.splitlines()),
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        cmd.arguments(p)
        p.set_defaults(_subcommand=cmd, _parser=p)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``ncgen`` with ``argv`` (default ``sys.argv[1:]``); returns the exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        if args.command is None:
            parser.print_help(sys.stderr)
            return 2
        return args._subcommand.run(args, args._parser)
    except SystemExit as exc:            # argparse: --help, --version and usage errors
        return 0 if exc.code is None else exc.code if isinstance(exc.code, int) else 1
    except NcgenError as exc:
        print(f"ncgen {args.command}: error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    from ncgen.cli import main as _main   # the importable module, where every subcommand registers
    sys.exit(_main())
