"""The pusher and the box (examples/pusher_box.py) and the hopper (examples/hopper_gait.py) from
a naive guess against the same problem with its contact sequence fixed (issue 39's target:
≤ 10× the IPOPT time).

* naive: ``OptimalControl`` from everything at rest (the hopper standing), the Scholtes
  homotopy from the example's σ₀ (1e-3 for the push, 1 for the hopper), its warm starts and
  the polish (every IPOPT call's CPU time summed);
* fixed sequence: the same NLP built anew from the same rest guess, with the contact sequence
  of the naive optimum imposed — in every complementarity pair the side that is 0 at that
  optimum set to 0 (an equality), as one would write each phase's contacts by hand — and
  solved once by IPOPT (ncgen's options, the adaptive barrier of the homotopy's first solve).

Both NLPs are built before the clock starts; the times are the CPU times of the IPOPT calls,
in interleaved rounds (min and median printed), with the costs and IPOPT's iterations.
The sequence is read off the naive optimum, not written from the gait: what is timed is IPOPT
on the NLP once the combinatorial part is known.  nosnoc is not run on the push: its models are
Filippov systems or a single contact with friction (CLS), not a box on four corners with a
pusher.  (The hopper against nosnoc: benchmarks/contact_implicit.py.)

Run:  python benchmarks/contact_implicit_pusher_box.py [--scene pusher_box|hopper] [--rounds 3]
      [--smoke: one round]
"""
from __future__ import annotations

import argparse
import importlib.util
import os
import time
from pathlib import Path

import numpy as np

from common import impose_contact_sequence, machine
from ncgen.optim.contact_implicit import FIRST_SOLVE, pair_values
from ncgen.optim.nlp import NLP

ROOT = Path(__file__).resolve().parent.parent


#: scene -> the example file (its ``build()`` and ``problem(model)``)
SCENES = {"pusher_box": "pusher_box.py", "hopper": "hopper_gait.py"}


def _example(scene):
    spec = importlib.util.spec_from_file_location(scene, ROOT / "examples" / SCENES[scene])
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def naive(ex, model):
    """``(cost, solver CPU, iterations, sequence)``; ``sequence[i][j]``: pair i's element j has
    its first side (``a``) at 0 (else its second, ``c``)."""
    sol = ex.problem(model).solve("rest")
    value, pairs = sol.nlp.value, sol.nlp.ocp.transcription.pairs
    sequence = [a <= c for a, c in pair_values(pairs, value)]
    return sol.stats.objective, sum(h["cpu_time"] for h in sol.homotopy), sol.stats.iterations, sequence


def fixed_sequence(ex, model, sequence):
    """``(cost, solver CPU, iterations, status)`` of the NLP with ``sequence`` imposed."""
    ocp = ex.problem(model)
    nlp = NLP(ocp)
    nlp.build("rest")
    impose_contact_sequence(nlp, sequence)
    cpu = time.process_time()
    value = nlp.solve(max_iter=3000, tol=1e-8, verbose=False, ipopt=dict(FIRST_SOLVE))
    cpu = time.process_time() - cpu
    stats = nlp.opti.stats()
    return float(value(nlp.opti.f)), cpu, int(stats["iter_count"]), stats["return_status"]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", choices=sorted(SCENES), default="pusher_box")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--smoke", action="store_true", help="one round")
    args = ap.parse_args(argv)
    rounds = 1 if args.smoke else args.rounds
    print(machine())
    ex = _example(args.scene)
    print(f"=== {args.scene} (examples/{SCENES[args.scene]}), N = {ex.N}, T = {ex.T} s, {rounds} interleaved round(s)")
    model = ex.build()
    ratios, rows = [], []
    for r in range(rounds):
        c_n, t_n, it_n, sequence = naive(ex, model)
        c_f, t_f, it_f, status = fixed_sequence(ex, model, sequence)
        ratios.append(t_n / t_f)
        print(f"round {r}: naive cost {c_n:.9f}, IPOPT CPU {t_n:.2f} s, {it_n} iterations | fixed sequence cost "
              f"{c_f:.9f} ({status}), IPOPT CPU {t_f:.2f} s, {it_f} iterations | ratio {t_n / t_f:.1f}", flush=True)
        rows.append((c_n, c_f))
    print(f"RATIO naive / fixed sequence, IPOPT CPU: min {min(ratios):.1f}, median {np.median(ratios):.1f} "
          f"(target ≤ 10); cost difference {max(abs(a - b) for a, b in rows):.2e}; load average at the end "
          f"{os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
