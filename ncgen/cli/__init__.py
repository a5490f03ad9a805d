"""The ``ncgen`` command line: one module per subcommand (see :mod:`ncgen.cli.registry` for
how to add one).

Exit codes: 0 success, 1 failure while running, 2 bad usage (argparse's convention; an
output path that cannot be written is one, found before any work), 70 internal error (a
bug), 130 interrupted.  Bad input raised as
:class:`ncgen.errors.NcgenError` is reported without a traceback; so is anything else (see
:func:`main`).
"""
from __future__ import annotations

import argparse
import importlib
import os
import sys
import warnings

from ncgen.cli.common import load_model, load_system, write_output
from ncgen.cli.registry import SUBCOMMANDS, subcommand
from ncgen.errors import NcgenError, use_cli_names
from ncgen.interrupts import sticky_interrupt
from ncgen.version import __version__

#: The module of :mod:`ncgen.cli` that registers each subcommand, in the order ``ncgen --help`` lists them.
SUBCOMMAND_MODULES = {"derive": "derive", "generate": "generate", "check": "check", "simulate": "simulate",
                      "sweep": "sweep", "optimize": "optimize", "mpc": "mpc", "equilibrium": "statics",
                      "modes": "statics", "demo": "demo", "tensegrity": "tensegrity"}

__all__ = ["SUBCOMMANDS", "build_parser", "load_model", "load_system", "main", "subcommand", "write_output"]


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``ncgen`` parser with every subcommand, or with ``command`` alone (its module is the only
    one imported, so that a run starts fast); the top-level help lists them all."""
    names = [command] if command in SUBCOMMAND_MODULES else list(SUBCOMMAND_MODULES)
    for name in names:
        importlib.import_module(f"ncgen.cli.{SUBCOMMAND_MODULES[name]}")
    commands = [SUBCOMMANDS[name] for name in names]
    parser = argparse.ArgumentParser(
        prog="ncgen",
        description="Rigid multibody dynamics in natural coordinates: SymPy derivations, "
                    "CasADi functions, generated C, simulation and optimisation.",
        epilog="examples:\n" + "".join(f"  {cmd.examples.splitlines()[0]}\n" for cmd in commands)
               + "\nRun 'ncgen SUBCOMMAND --help' for a subcommand's options and more examples.",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"ncgen {__version__}")
    parser.add_argument("--debug", action="store_true",
                        help="print the Python traceback of an internal error (also NCGEN_DEBUG=1)")
    sub = parser.add_subparsers(dest="command", metavar="SUBCOMMAND", title="subcommands")
    for cmd in commands:
        p = sub.add_parser(cmd.name, help=cmd.help, description=cmd.description,
                           epilog="examples:\n" + "\n".join("  " + line for line in cmd.examples.splitlines()),
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        cmd.arguments(p)
        p.set_defaults(_subcommand=cmd, _parser=p)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``ncgen`` with ``argv`` (default ``sys.argv[1:]``); returns the exit code.

    Never shows a Python traceback for bad input: ncgen's errors, files that cannot be
    read or written and running out of memory are one-line messages (exit 1), Ctrl-C exits
    130, and anything else is reported as an internal error with where to report it; its
    traceback is printed with ``--debug`` or ``NCGEN_DEBUG=1``.  Warnings are one line,
    ``ncgen: warning: ...``."""
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv or os.environ.get("NCGEN_DEBUG", "") not in ("", "0")
    argv = [a for a in argv if a != "--debug"]
    parser = build_parser(_command(argv))
    use_cli_names(True)
    with warnings.catch_warnings():
        if not debug:                    # "ncgen: warning: ...", not a source line of ncgen
            warnings.showwarning = _show_warning
        try:
            return _run_main(parser, argv, debug)
        finally:
            use_cli_names(False)


def _unrecognized(parser: argparse.ArgumentParser, unknown: list[str]) -> None:
    """argparse's usage error for arguments ``parser`` does not take, with the option it
    has closest to the first unknown one (``--tend``: did you mean '--t-end'?)."""
    from ncgen.model.expressions import did_you_mean

    flags = [o for action in parser._actions for o in action.option_strings]
    first = next((a.partition("=")[0] for a in unknown if a.startswith("-")), "")
    parser.error(f"unrecognized arguments: {' '.join(unknown)}{did_you_mean(first, flags) if first else ''}")


def _flag_named(message: str, parser: argparse.ArgumentParser) -> str:
    """``message`` with a leading Python argument name (``t_end: ...``) replaced by the
    subcommand's flag for it (``--t-end: ...``), where it has one."""
    name, sep, rest = message.partition(": ")
    flag = "--" + name.replace("_", "-")
    if sep and name.isidentifier() and any(flag in a.option_strings for a in parser._actions):
        return f"{flag}: {rest}"
    return message


def _command(argv: list[str]) -> str | None:
    """The subcommand ``argv`` names (its first argument that is not a top-level option), if any."""
    for arg in argv:
        if not arg.startswith("-"):
            return arg
        if arg not in ("--debug", "--version", "-h", "--help"):
            return None
    return None


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"ncgen: warning: {message}", file=sys.stderr if file is None else file)


def _run_main(parser: argparse.ArgumentParser, argv: list[str], debug: bool) -> int:
    """:func:`main` inside its warning format: every outcome mapped to a message and an exit code."""
    from ncgen.errors import REPORT_TO

    where, command = "ncgen", parser
    try:
        args, unknown = parser.parse_known_args(argv)
        command = getattr(args, "_parser", parser)
        if unknown:
            _unrecognized(getattr(args, "_parser", parser), unknown)
        if args.command is None:
            parser.print_help(sys.stderr)
            return 2
        where = f"ncgen {args.command}"
        with sticky_interrupt():         # a Ctrl-C that CasADi swallows is raised again at the next checkpoint
            return args._subcommand.run(args, args._parser)
    except SystemExit as exc:            # argparse: --help, --version and usage errors
        return 0 if exc.code is None else exc.code if isinstance(exc.code, int) else 1
    except NcgenError as exc:
        print(f"{where}: error: {_flag_named(str(exc), command)}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as exc:
        said = f": {exc}" if str(exc) else ""
        print(f"{where}: interrupted{said}", file=sys.stderr)
        return 130
    except OSError as exc:
        target = f" {exc.filename}" if exc.filename else ""
        print(f"{where}: error:{target}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    except MemoryError:
        print(f"{where}: error: out of memory; reduce the problem (a larger --dt, fewer members)",
              file=sys.stderr)
        return 1
    except Exception as exc:             # a bug: say so, briefly
        if debug:
            import traceback
            traceback.print_exc()
        print(f"{where}: internal error ({type(exc).__name__}: {str(exc)[:300]}). This is a bug in "
              f"ncgen, not in your input; please report it to {REPORT_TO}"
              + ("" if debug else ". Run with --debug (or NCGEN_DEBUG=1) to see the traceback"),
              file=sys.stderr)
        return 70
