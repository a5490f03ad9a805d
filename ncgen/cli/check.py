"""``ncgen check``: degrees of freedom, constraint rank and the initial state of a model."""
from __future__ import annotations

import argparse
import sys

from ncgen.cli.common import load_system, model_arguments
from ncgen.cli.registry import subcommand


def _check_arguments(p: argparse.ArgumentParser) -> None:
    model_arguments(p)
    p.add_argument("--tolerance", type=float, default=1e-6, metavar="TOL",
                   help="largest correction of the initial state, relative to the model's size, "
                        "that still counts as consistent (default 1e-6, as System.build)")
    p.add_argument("--no-share", action="store_true",
                   help="keep every joint's equations (System.build(share=False)) instead of eliminating "
                        "the joints that shared coordinates express")


@subcommand(
    "check",
    help="DOF, constraint rank and initial-state check of a model",
    description=(
        "Build the model in MODEL (TOML or URDF) and print its members, joints and forces, its coordinates "
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
        "ncgen check mymodel.toml --param k=50 || echo 'fix the initial state'\n"
        "ncgen check robot.urdf                               # a URDF robot, fixed base"),
    arguments=_check_arguments,
)
def check(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    from ncgen.assembly.check import check_system

    if not 0 < args.tolerance < float("inf"):
        parser.error(f"--tolerance: expected a positive finite number, got {args.tolerance}")
    system = load_system(args.model, args.param, args.floating_base, args.mjcf_contacts)
    report = check_system(system, tolerance=args.tolerance, share=not args.no_share)
    sys.stdout.write(report.render(args.model))
    return 0 if report.ok else 1
