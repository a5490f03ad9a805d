"""``ncgen tensegrity``: self-stress, mechanisms and member forces of a tensegrity design file
(:mod:`ncgen.analysis.tensegrity_file`)."""
from __future__ import annotations

import argparse

from ncgen.cli.common import check_files, write_output
from ncgen.cli.registry import subcommand

#: What -o/--output accepts.
OUTPUTS = (".csv",)


def _arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("design", help="tensegrity design file (TOML: nodes, struts, cables, supports, loads, "
                                  "[prestress]; see docs/tensegrity.md)")
    p.add_argument("-o", "--output", metavar="FILE", default=None,
                   help="write the member forces (.csv: member,i,j,length_m,force_N,density_N_per_m)")


@subcommand("tensegrity", help="self-stress, mechanisms, forces of a tensegrity",
            description="Read a tensegrity design (a shape, supports, loads, bounds on the prestress), print its "
                        "states of self-stress and infinitesimal mechanisms (Calladine's rule), the member "
                        "forces (least norm within the bounds, or the stiffest / most even prestress by IPOPT), "
                        "their prestress stability and, with a stiffness, the rest lengths that realise them.",
            examples="ncgen tensegrity examples/snelson_prism.tensegrity.toml\n"
                     "ncgen tensegrity examples/snelson_prism.tensegrity.toml -o forces.csv",
            arguments=_arguments)
def tensegrity(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    from ncgen.analysis.tensegrity_file import read_design, run_design

    check_files(args, parser, OUTPUTS)
    text, res = run_design(read_design(args.design))
    write_output(text, None)
    if args.output is not None:
        fw = res.framework
        rows = ["member,i,j,length_m,force_N,density_N_per_m"]
        for e, ((i, j), l, t) in enumerate(zip(fw.members, res.lengths, res.forces)):
            name = f"cable{e}" if e < len(fw.cables) else f"strut{e - len(fw.cables)}"
            rows.append(f"{name},{i},{j},{l:.17g},{t:.17g},{t / l:.17g}")
        write_output("\n".join(rows) + "\n", args.output)
    return 0
