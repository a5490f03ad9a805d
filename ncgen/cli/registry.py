"""The registry of ``ncgen`` subcommands.

Every subcommand is one module of :mod:`ncgen.cli` holding a function decorated with
:func:`subcommand`: the decorator registers its name, one-line help, description and
examples (shown by ``ncgen SUBCOMMAND --help``) and a function adding its arguments; the
decorated function receives the parsed arguments and the subparser, and returns the exit
code.  To add a subcommand, write ``ncgen/cli/frob.py``::

    def _arguments(p: argparse.ArgumentParser) -> None:
        p.add_argument("model", help="model file (TOML)")

    @subcommand("frob", help="...", description="...", examples="ncgen frob m.toml",
                arguments=_arguments)
    def frob(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
        ...
        return 0

and add ``"frob": "frob"`` (subcommand: module) to :data:`ncgen.cli.SUBCOMMAND_MODULES`; a run
imports only its subcommand's module.  Import heavy modules (CasADi, the runtime, SymPy,
compilers) inside the function so that ``ncgen --help`` and every start stay fast.  A
subcommand that writes files calls :func:`ncgen.cli.common.check_files` first, before any
work, so that an unwritable output path is a usage error naming the path (exit 2).
"""
from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass


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
