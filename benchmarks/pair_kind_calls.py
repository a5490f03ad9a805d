"""The nonsmooth stepper with its contact element kernels calling the shared pair kinds
(``ncgen/assembly/pair_kinds.py``, ``pair_kernels.KIND_CALLS = True``: one C function per kind,
the numbers constant arrays) against the element kernels with the numbers built in
(``KIND_CALLS = False``), in one process, interleaved: per model the package's kernel C and
the stepping CPU time (``Trajectory.info["stepping_cpu_time"]``) of the same run, min and
median over the rounds, and the largest difference of the positions (m).

    python benchmarks/pair_kind_calls.py --rounds 9 --t-end 2
    python benchmarks/pair_kind_calls.py --smoke
"""
from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

import numpy as np

from common import machine

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import ncgen as nc  # noqa: E402
import ncgen.assembly.pair_kernels as pair_kernels  # noqa: E402
from contact import heap  # noqa: E402


def box_stack():
    return nc.System.from_toml(ROOT / "examples" / "box_stack.toml").build(contacts="nonsmooth")


#: name -> (model maker, t_end s, dt s, substeps)
SCENES = {"box_stack": (box_stack, 0.5, 0.01, 10), "heap20": (lambda: heap(20, False), 0.5, 0.01, 10)}


def run(model, t_end, dt, substeps):
    tr = nc.simulate(model, t_end, dt, method="stepper", substeps=substeps)
    return tr.info["stepping_cpu_time"], np.asarray(tr.q)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--t-end", type=float, help="simulated time of each run (s; default per scene)")
    ap.add_argument("--smoke", action="store_true")
    args = ap.parse_args()
    scenes = {"heap20": SCENES["heap20"]} if args.smoke else SCENES
    rounds = 1 if args.smoke else args.rounds
    print(machine())
    for name, (make, t_end, dt, substeps) in scenes.items():
        t_end = args.t_end or t_end
        models = {}
        for calls in (False, True):
            pair_kernels.KIND_CALLS = calls
            models[calls] = make()
            run(models[calls], dt, dt, substeps)                  # compiled outside the timings
        pair_kernels.KIND_CALLS = True
        times = {False: [], True: []}
        q = {}
        for r in range(rounds):
            for calls in ((False, True) if r % 2 == 0 else (True, False)):
                t, q[calls] = run(models[calls], t_end, dt, substeps)
                times[calls].append(t)
        ratio = [a / b for a, b in zip(times[True], times[False])]
        print(f"{name}: stepping CPU s (min / median) built-in numbers {min(times[False]):.4f} / "
              f"{statistics.median(times[False]):.4f}, kind calls {min(times[True]):.4f} / "
              f"{statistics.median(times[True]):.4f}; calls / built-in min {min(ratio):.3f}, median "
              f"{statistics.median(ratio):.3f}; max |Δq| {np.abs(q[True] - q[False]).max():.3g} m")


if __name__ == "__main__":
    main()
