"""``ncgen generate``: a model's C package."""
from __future__ import annotations

import argparse
import sys

from ncgen.cli.common import check_files, load_model, model_arguments
from ncgen.cli.registry import subcommand


def _generate_arguments(p: argparse.ArgumentParser) -> None:
    model_arguments(p)
    p.add_argument("-o", "--output", metavar="DIR", required=True,
                   help="package directory to write; over an existing ncgen package only the files "
                        "ncgen wrote (and their build products) are replaced, other files are kept; "
                        "refused if DIR holds anything else or generated files were edited")
    p.add_argument("--compile", action="store_true",
                   help="also build the shared library now (cached by content); the package is "
                        "written only if compiling succeeds")
    p.add_argument("--cflags", metavar="FLAGS", default=None,
                   help="C compiler flags for --compile, for every file (default: $NCGEN_CFLAGS, "
                        "else -O2, and -O1 for files holding functions so long that -O2 takes several times longer)")
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
        "Build the model in MODEL (TOML or URDF) and write its C package to DIR: the system functions "
        "(constraints, Jacobian, forces, M^-1, the DAE with its sparse Jacobian, accelerations, "
        "energies, markers, poses) as CasADi-generated C, a header documenting every function "
        "(argument sizes, units, meaning) and the model (dimensions, names, initial state, mass "
        "matrix), a Makefile and CMakeLists.txt, main.c (evaluates the model without Python) and "
        "manifest.json. The same model always gives the same bytes."),
    examples=(
        "ncgen generate examples/chain.toml -o chain_c       # then: make -C chain_c && chain_c/chain_main\n"
        "ncgen generate examples/heavy_top.toml -o top --compile --cflags='-O3 -march=native'\n"
        "ncgen generate robot.urdf -o robot_c                 # URDF: joint torques are the input tau"),
    arguments=_generate_arguments,
)
def generate(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    from ncgen.codegen.compile_cache import compile_package
    from ncgen.codegen.model_package import generate as generate_package
    from ncgen.codegen.reroll import REROLL_INSTRUCTIONS

    check_files(args, parser, None, directories=("output",))
    model = load_model(args.model, args.param, floating_base=args.floating_base, mjcf_contacts=args.mjcf_contacts)
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
