"""Issue 41's statics targets on a 3-stage tower of 100 members: inverse statics in at most
0.5 s and prestress optimisation in at most 5 s (CPU time).

The tower: three stacked regular 10-prisms (``stacked_prisms(10, 3)``: 40 nodes, 30 struts,
70 cables), as in tests/test_inverse_statics.py and tests/test_prestress.py.
*Inverse statics*: loaded by forces its shape can carry (``A t_ref`` for member forces drawn
in [1, 2] N, none on the ten fixed nodes of the bottom ring), least-norm forces with every cable at 10 N
or more, then the rest lengths for k = 2000 N/m.  *Prestress*: the stiffest prestress of the
free tower's mechanisms with cables between 1 and 100 N (IPOPT).  Each answer is checked
(13 states of self-stress and a balance residual below 1e-9 N; 17 mechanisms, positive
smallest stiffness, the largest cable at its bound) before its time is kept.  The two runs
alternate for ``--rounds`` rounds, each under ncgen's BLAS thread rule (``NCGEN_BLAS_THREADS``
unset: one thread inside ncgen, ncgen/blas_threads.py) and with the BLAS's own threads
(``NCGEN_BLAS_THREADS=0``, what ncgen did before the rule), interleaved; CPU
(``time.process_time``, every thread of the process) and wall time, min and median, the ratios
own threads / rule, the load average and the BLAS variables are printed, with ``TARGET`` lines
for the rule.  ``--smoke``: 2 rounds.
"""
from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np

from common import machine

import ncgen as nc
from ncgen.analysis.self_stress import framework
from ncgen.analysis.tensegrity_shapes import stacked_prisms

TARGETS = {"inverse statics": 0.5, "prestress optimisation": 5.0}       # s of CPU, issue 41
SETTINGS = {"rule": None, "own threads": "0"}                   # NCGEN_BLAS_THREADS


def loaded_tower():
    """The 100-member tower on its fixed bottom ring, loaded by forces its shape can carry."""
    nodes, struts, cables = stacked_prisms(10, stages=3)
    fw = framework(nodes, struts, cables, who="benchmark")
    loads = (fw.full_equilibrium_matrix() @ np.random.default_rng(0).uniform(1, 2, len(fw.members))).reshape(-1, 3)
    loads[:10] = 0
    return nodes, struts, cables, loads, list(range(10))


def inverse(nodes, struts, cables, loads, supports):
    inv = nc.inverse_statics(nodes, struts, cables, loads, supports, cable_min=10.0)
    inv.rest_lengths(2000.0)
    assert inv.analysis.n_self_stress == 13 and inv.residual < 1e-9, (inv.analysis.n_self_stress, inv.residual)
    assert abs(inv.tensions.min() - 10.0) < 1e-9


def prestress(nodes, struts, cables):
    d = nc.optimize_prestress(nodes, struts, cables, cable_min=1.0, cable_max=100.0)
    assert d.analysis.n_mechanisms == 17 and d.min_stiffness > 0 and abs(d.max_cable - 100.0) < 1e-5, d


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--smoke", action="store_true")
    ap.add_argument("--rounds", type=int, default=7)
    args = ap.parse_args()
    rounds = 2 if args.smoke else args.rounds
    print(machine())
    print(f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS', 'unset')}, "
          f"OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', 'unset')}")
    tower = loaded_tower()
    assert len(tower[1]) + len(tower[2]) == 100
    runs = {"inverse statics": lambda: inverse(*tower), "prestress optimisation": lambda: prestress(*tower[:3])}
    for run in runs.values():                                          # warm-up: imports, CasADi plugins
        run()
    times = {(name, setting): ([], []) for name in runs for setting in SETTINGS}
    for _ in range(rounds):
        for name, run in runs.items():
            for setting, value in SETTINGS.items():
                os.environ.pop("NCGEN_BLAS_THREADS", None)
                if value is not None:
                    os.environ["NCGEN_BLAS_THREADS"] = value
                w, c = time.perf_counter(), time.process_time()
                run()
                times[name, setting][0].append(time.perf_counter() - w)
                times[name, setting][1].append(time.process_time() - c)
    os.environ.pop("NCGEN_BLAS_THREADS", None)
    print(f"=== 3-stage tower, 100 members, {rounds} interleaved rounds, "
          f"load average {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    for (name, setting), (wall, cpu) in times.items():
        line = (f"{name}, {setting}: CPU min {min(cpu):.3f} s, median {statistics.median(cpu):.3f} s; "
                f"wall min {min(wall):.3f} s, median {statistics.median(wall):.3f} s")
        if setting == "rule":
            target = TARGETS[name]
            line = f"TARGET {line} (target CPU <= {target} s: " \
                   f"{'met' if statistics.median(cpu) <= target else 'MISSED'})"
        print(line)
    for name in runs:
        for k, what in enumerate(("wall", "CPU")):
            ratio = np.array(times[name, "own threads"][k]) / np.array(times[name, "rule"][k])
            print(f"{name}: {what} own threads / rule, per round: min {ratio.min():.2f}x, "
                  f"median {np.median(ratio):.2f}x")


if __name__ == "__main__":
    main()
