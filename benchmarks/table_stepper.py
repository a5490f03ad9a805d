"""The compiled stepper from element tables vs the flat per-model stepper (issue 34): chains
of N bars (benchmarks/common.py, shared points), ``System`` to the first compiled step, and
the time per step.

Per N:

* build: ``chain_system(N).build()`` (the same for both paths);
* tables, empty cache (first N only: the element library does not depend on N): a fresh
  compile cache, the element library compiled, the model's tables packed, one step;
* tables, cached: the tables packed (``table_stepper``), the cached library loaded, one step
  (no compiler call);
* flat, empty cache: the model's stepper package generated and compiled into a fresh cache
  (``load_stepper``), one step;  flat, cached: the same model built again, its package found
  in the cache (C generation and hashing remain), one step;
* time per RATTLE step (h = 1 ms, fixed steps, no estimate), tables and flat alternating over
  the rounds, CPU seconds per step: min and median, and their ratios tables / flat;
* the same for the chain with the force kinds beyond gravity (``forces_chain``: per bar a
  cable to a ground point above it, a spring-damper, a constant point force and torque):
  packing its tables, and the time per step of the two forms.

Wall-clock seconds with CPU seconds (of the process and its children) in brackets.  The
machine is shared: the load average is printed at start and end.

    python benchmarks/table_stepper.py                  N = 10, 40, 160, 1000, 5 rounds
    python benchmarks/table_stepper.py --smoke          N = 3, 6, 2 rounds
    python benchmarks/table_stepper.py --sizes 10 40 --rounds 3
    python benchmarks/table_stepper.py --sizes 10 --no-forces
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from common import GRAVITY, L, MASS, chain_system, ends, in_turn, machine, timed

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))


def one_step(stepper, model, n_steps: int = 1):
    """``n_steps`` RATTLE steps of 1 ms from the model's initial state (status checked)."""
    from ncgen.codegen.stepper_abi import RunOptions
    from ncgen.runtime.stepper_library import step_options

    out = stepper.simulate_stats(model.q0, model.v0, np.zeros(model.nc), 0.0, 1e-3, n_steps, n_steps, None,
                                 model.p0, step_options(1e-10, 12, 4), RunOptions())
    if out[4] != 0:
        raise RuntimeError(f"{model.name}: the stepper failed with status {out[4]}")
    return out


def tables_first_step(model, fresh_cache: str | None):
    from ncgen.runtime import table_library
    from ncgen.runtime.table_stepper import table_stepper

    if fresh_cache is not None:
        os.environ["NCGEN_CACHE_DIR"] = fresh_cache
        table_library._LOADED.clear()
    stepper = table_stepper(model)
    one_step(stepper, model)
    return stepper


def flat_first_step(model, fresh_cache: str | None):
    from ncgen.runtime.stepper_library import load_stepper

    if fresh_cache is not None:
        os.environ["NCGEN_CACHE_DIR"] = fresh_cache
    stepper = load_stepper(model)
    one_step(stepper, model)
    return stepper


def forces_chain(n: int):
    """The benchmark chain of ``n`` bars with, per bar, a cable to a ground point 0.3 m above
    its far end (slack or taut), a spring-damper to a ground point beside it, a constant point
    force at its middle and a constant torque."""
    import ncgen as nc

    pts = ends(n, L)
    s = nc.System(f"chain{n}_forces", gravity=GRAVITY)
    start = s.ground.point((0.0, 0.0, 0.0))
    for k, far in enumerate(pts[1:], start=1):
        bar = s.add_bar(f"bar{k}", coords="rr", mass=MASS, ends=[start, tuple(far)])
        start = bar.end(1)
        s.add_force(nc.Spring(bar, (0.5 * L, 0.0, 0.0), s.ground, tuple(far + (0.0, 0.0, 0.3)), k=50.0,
                              rest_length=0.35, damping=0.4, cable=True))
        s.add_force(nc.Spring(bar, (0.0, 0.0, 0.0), s.ground, tuple(far + (0.0, 0.4, 0.0)), k=20.0,
                              rest_length=0.3, damping=0.2))
        s.add_force(nc.PointForce(bar, (0.0, 0.0, 0.0), force=(0.0, 0.1 * (k % 3), 0.0)))
        s.add_force(nc.Torque(bar, (0.0, 0.0, 0.02)))
    return s


def compare_per_step(tables, peer, model, steps: int, rounds: int, label: str,
                     peer_name: str = "flat") -> tuple[float, float]:
    """Interleaved CPU time per step of the tables and ``peer`` (named ``peer_name``), min and
    median, printed with their ratios; returns the ratios tables / peer (min, median)."""
    times = {"tables": [], peer_name: []}
    for r in range(rounds):
        done = in_turn(r, {"tables": lambda: per_step(tables, model, steps),
                           peer_name: lambda: per_step(peer, model, steps)})
        for name, seconds in done.items():
            times[name].append(seconds)
    t, f = times["tables"], times[peer_name]
    ratios = (min(t) / min(f), statistics.median(t) / statistics.median(f))
    print(f"  time per step, {steps} steps x {rounds} rounds (CPU us): tables min {min(t) * 1e6:.1f} "
          f"median {statistics.median(t) * 1e6:.1f}; {peer_name} min {min(f) * 1e6:.1f} "
          f"median {statistics.median(f) * 1e6:.1f}")
    print(f"  RATIO tables / {peer_name}, time per step, {label}: min {ratios[0]:.2f}, median {ratios[1]:.2f}",
          flush=True)
    return ratios


def per_step(stepper, model, n_steps: int) -> float:
    """CPU seconds per step of ``n_steps`` steps from the initial state."""
    c = time.process_time()
    one_step(stepper, model, n_steps)
    return (time.process_time() - c) / n_steps


def show(label: str, wall: float, cpu: float) -> None:
    print(f"  {label:<44} {wall:8.3f} s  ({cpu:.3f} s CPU)", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[10, 40, 160, 1000])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--smoke", action="store_true", help="N = 3, 6, 2 rounds, few steps")
    ap.add_argument("--no-forces", action="store_true", help="skip the chains with forces")
    args = ap.parse_args()
    sizes, rounds = ([3, 6], 2) if args.smoke else (args.sizes, args.rounds)
    print(machine())
    home = os.environ.get("NCGEN_CACHE_DIR")
    with tempfile.TemporaryDirectory(prefix="ncgen-bench-tables-") as tmp:
        for i, n in enumerate(sizes):
            print(f"=== chain of N = {n} bars", flush=True)
            w, c, model = timed(lambda: chain_system(n).build())
            show("build (System -> Model)", w, c)
            print(f"  nq = {model.nq}, nc = {model.nc}")
            if i == 0:
                w, c, _ = timed(lambda: tables_first_step(model, str(Path(tmp) / "tables")))
                show("tables, empty cache: library + pack + step", w, c)
            w, c, tables = timed(lambda: tables_first_step(model, None))
            show("tables, cached: pack + load + step", w, c)
            w, c, flat = timed(lambda: flat_first_step(model, str(Path(tmp) / f"flat{n}")))
            show("flat, empty cache: generate + compile + step", w, c)
            again = chain_system(n).build()
            w, c, _ = timed(lambda: flat_first_step(again, None))
            show("flat, cached: generate + find + step", w, c)
            if home is None:
                os.environ.pop("NCGEN_CACHE_DIR", None)
            else:
                os.environ["NCGEN_CACHE_DIR"] = home
            steps = 20 if args.smoke else max(50, 200_000 // (model.nq + model.nc))
            compare_per_step(tables, flat, model, steps, rounds, f"N = {n}")
            if args.no_forces:
                continue
            print(f"--- chain of N = {n} bars with cables, spring-dampers, point forces and torques", flush=True)
            loaded = forces_chain(n).build()
            w, c, ftables = timed(lambda: tables_first_step(loaded, None))
            show("tables, cached: pack + load + step", w, c)
            w, c, fflat = timed(lambda: flat_first_step(loaded, str(Path(tmp) / f"forces{n}")))
            show("flat, empty cache: generate + compile + step", w, c)
            if home is None:
                os.environ.pop("NCGEN_CACHE_DIR", None)
            else:
                os.environ["NCGEN_CACHE_DIR"] = home
            compare_per_step(ftables, fflat, loaded, steps, rounds, f"forces, N = {n}")
    print(f"load average at the end: {os.getloadavg()}")


if __name__ == "__main__":
    main()
