"""The ``ncgen`` command line: one module per subcommand (see :mod:`ncgen.cli.registry` for
how to add one).

Exit codes: 0 success, 1 failure while running, 2 bad usage (argparse's convention).
Bad input raised as :class:`ncgen.errors.NcgenError` is reported without a traceback.
"""
from __future__ import annotations

import argparse
import importlib
import sys

from ncgen.cli.common import load_model, load_system, write_output
from ncgen.cli.registry import SUBCOMMANDS, subcommand
from ncgen.errors import NcgenError
from ncgen.version import __version__

#: The subcommand modules, in the order ``ncgen --help`` lists them.
SUBCOMMAND_MODULES = ("derive", "generate", "check", "simulate", "optimize", "statics", "demo")

__all__ = ["SUBCOMMANDS", "build_parser", "load_model", "load_system", "main", "subcommand", "write_output"]


def build_parser() -> argparse.ArgumentParser:
    for name in SUBCOMMAND_MODULES:
        importlib.import_module(f"ncgen.cli.{name}")
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
