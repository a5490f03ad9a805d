"""Nonsmooth contact scenes on the contact library's tables vs the model's own compiled package
(issue 34: "speed kept or better", each at most 1.2× the flat code): the time per step of the
two forms in one run, interleaved.

Scenes (``contacts="nonsmooth"``): ``examples/box_stack.toml``, ``examples/boxes.toml``,
``examples/falling_chain.toml``, and the 20-sphere frictional heap of ``benchmarks/contact.py``
with non-rotating spheres (point members, ``heap20p``) and rotating ones ('ruvw' bodies,
``heap20r``).  Per scene: the tables (``table_stepper``: the contact library, nothing compiled for
the model) and the package (``load_stepper``: compiled outside the timings, found in the cache
after the first run) each run ``--steps`` fixed RATTLE steps of 1 ms from the model's initial
state (both take the same steps: they agree to round-off); ``--rounds`` rounds, the two forms in
turn (the order alternating), CPU seconds per step (``time.process_time``); printed: min and
median per form, and the ratios tables / package of the mins and of the medians.  The machine
is shared: the CPU and the load average are printed at the start and the end.

    python benchmarks/table_contacts.py                        all scenes, 500 steps, 7 rounds
    python benchmarks/table_contacts.py --scenes box_stack heap20r --rounds 5
    python benchmarks/table_contacts.py --smoke                 falling_chain, 50 steps, 2 rounds
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from common import in_turn, machine
from table_stepper import compare_per_step, one_step

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def scene(name: str):
    """The built model (``contacts="nonsmooth"``) of the scene ``name``."""
    import ncgen as nc

    if name.startswith("heap"):
        from contact import heap
        return heap(int(name[4:-1]), rotating=name.endswith("r"))
    return nc.System.from_toml(ROOT / "examples" / f"{name}.toml").build(contacts="nonsmooth")


SCENES = ("box_stack", "boxes", "falling_chain", "heap20p", "heap20r")


def compare(name: str, steps: int, rounds: int) -> tuple[float, float]:
    """The interleaved times of scene ``name`` printed; returns the ratios (min, median)."""
    from ncgen.runtime.stepper_library import load_stepper
    from ncgen.runtime.table_stepper import table_stepper

    model = scene(name)
    tables = table_stepper(model)
    c = time.process_time()
    package = load_stepper(model)
    print(f"=== {name}: nq = {model.nq}, nc = {model.nc}, nk = {model.nk}; package loaded in "
          f"{time.process_time() - c:.1f} CPU-s", flush=True)
    for stepper in (tables, package):       # warm-up: caches, pages
        one_step(stepper, model, min(steps, 20))
    return compare_per_step(tables, package, model, steps, rounds, name, peer_name="package")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", nargs="+", default=list(SCENES), choices=SCENES)
    ap.add_argument("--steps", type=int, default=500, help="steps of 1 ms per timing (default 500)")
    ap.add_argument("--rounds", type=int, default=7, help="interleaved rounds (default 7)")
    ap.add_argument("--smoke", action="store_true", help="falling_chain, 50 steps, 2 rounds")
    args = ap.parse_args()
    scenes, steps, rounds = (["falling_chain"], 50, 2) if args.smoke else (args.scenes, args.steps, args.rounds)
    print(machine())
    summary = {name: compare(name, steps, rounds) for name in scenes}
    print("summary, tables / package (min, median): "
          + "; ".join(f"{k} {a:.2f} / {b:.2f}" for k, (a, b) in summary.items()))
    print(f"load average at the end: {os.getloadavg()}")


if __name__ == "__main__":
    main()
