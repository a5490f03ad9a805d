"""``ncgen derive``: a coordinate type's derivation, or the rigid-motion algebra's, for teaching."""
from __future__ import annotations

import argparse

from ncgen.cli.common import check_files, write_output
from ncgen.cli.registry import subcommand


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
    check_files(args, parser, ())
    if args.type == "se3":
        if args.dim == 2:
            parser.error("se3 is three-dimensional; drop --dim 2")
        from ncgen.symbolic.se3_report import se3_report
        report = se3_report()
    else:
        from ncgen.symbolic.coordinates import TYPES, coordinate_type
        from ncgen.symbolic.teaching import coordinates_report
        dim = 3 if args.dim is None else args.dim
        if args.type not in TYPES[dim]:
            other = 5 - dim
            hint = f" ({args.type!r} is a {other}D type: add --dim {other})" if args.type in TYPES[other] else ""
            parser.error(f"unknown TYPE {args.type!r} for --dim {dim}{hint}\n"
                         f"valid types for --dim {dim}: {_type_list(dim)}")
        report = coordinates_report(coordinate_type(args.type, dim))
    write_output(report.render(args.format), args.output)
    return 0
