"""``ncgen demo``: the main job on the built-in heavy top (:mod:`ncgen.cli.demo_job`)."""
from __future__ import annotations

import argparse
from pathlib import Path

from ncgen.cli.common import check_files
from ncgen.cli.registry import subcommand


def _demo_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("-o", "--output", metavar="DIR", default="ncgen-demo",
                   help="directory for the C package, trajectory, plot and animation "
                        "(default ./ncgen-demo, created if needed)")
    p.add_argument("--animate", action="store_true", help="also write an animation (GIF)")
    p.add_argument("--t-end", type=float, default=1.4, metavar="T",
                   help="simulated time (s, default 1.4: one turn of precession)")
    p.add_argument("--backend", default="auto", choices=("auto", "compiled", "vm"),
                   help="auto (default: compiled, or the VM with a one-line note when there is no C "
                        "compiler), compiled (generated C) or vm (CasADi's virtual machine)")


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
        "ncgen demo --backend vm             # skip the C compiler"),
    arguments=_demo_arguments,
)
def demo(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    from ncgen.cli.demo_job import run_demo

    check_files(args, parser, None, directories=("output",))
    out = Path(args.output)
    if not 0 < args.t_end < float("inf"):
        parser.error(f"--t-end: expected a positive finite time (s), got {args.t_end}")
    print(run_demo(out, animate=args.animate, t_end=args.t_end, backend=args.backend).summary())
    return 0
