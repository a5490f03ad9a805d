"""Tree tables vs flat per-robot kernels vs Pinocchio (issue 34): the joint-space algorithms of
a URDF robot from the tree library (compiled once per ncgen version, the robot as data) and
from the robot's own flat SX functions (compiled per robot), and ``ncgen simulate`` of the
stock Panda URDF.

Per call (interleaved: each round times a batch of ``--calls`` calls of each side in turn, the
order rotating between rounds; best and median CPU time per call over the rounds):

* RNEA: ``TableAlgorithm(qj, vj, aj)`` (``kernels="tables"``) vs ``AlgorithmKernel(qj, vj,
  aj)`` (``kernels="flat"``) vs ``pinocchio.rnea``; ABA the same with ``pinocchio.aba``
  (target: tables ≤ 1.2× flat);
* the public doors ``nc.rnea`` / ``nc.aba`` with each ``kernels=`` (argument checks included);
* the arithmetic alone: RNEA, ABA and CRBA over ``--states`` states in one C call
  (``nc.rnea(model, Q, V, A, kernels=...)``: the tables' loop, the flat kernel's batch loop),
  time per state.

Then ``ncgen simulate <panda.urdf> --t-end 1 -o traj.npz`` in fresh processes: the first run with an empty
compile cache and model store, and later runs (targets: 3 s and 1 s), wall and CPU seconds.
The joint-space simulation still runs its flat per-robot loop (the tables do not drive it yet).

CPU model, load average at start and end are printed: the machine is shared.

    python benchmarks/tree_tables.py [--robots panda ur5] [--calls 2000] [--rounds 7] [--states 1000] [--skip-simulate]
    python benchmarks/tree_tables.py --smoke        one robot, few calls, one simulate run
"""
from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))

from common import machine  # noqa: E402


def per_call(fn, calls: int) -> float:
    """CPU seconds of this process per call (``time.process_time``: on a shared machine the wall
    time of a call counts the other processes' time slices)."""
    start = time.process_time()
    for _ in range(calls):
        fn()
    return (time.process_time() - start) / calls


def compare(label: str, sides: dict, calls: int, rounds: int, per: int = 1) -> None:
    names = list(sides)
    samples = {n: [] for n in names}
    for r in range(rounds):
        for n in names[r % len(names):] + names[:r % len(names)]:
            samples[n].append(per_call(sides[n], calls) / per)
    best = {n: min(s) for n, s in samples.items()}
    line = ", ".join(f"{n} {best[n] * 1e6:.2f} µs (median {statistics.median(samples[n]) * 1e6:.2f})" for n in names)
    print(f"{label}: {line}")
    if "tables" in best and "flat" in best:
        print(f"RATIO {label}: tables / flat = {best['tables'] / best['flat']:.2f} (best/best)")


def algorithms(name: str, calls: int, rounds: int) -> None:
    import ncgen as nc
    from ncgen.assembly.tree_dynamics import MimicMap
    from ncgen.runtime import tree_algorithm_kernels as rta
    from pinocchio_robots import ROBOTS, JointMap, pin, pinocchio_models, random_configuration, urdf_text

    t = time.perf_counter()
    model = nc.System.from_urdf(urdf_text(name), floating_base=ROBOTS[name][1]).build()
    print(f"\n=== {name}: built in {time.perf_counter() - t:.1f} s")
    pm_mimic, pm = pinocchio_models(name)
    jm, mimic = JointMap(model, pm), MimicMap(model)
    rng = np.random.default_rng(0)
    qj = jm.q_to_ncgen(random_configuration(pm, rng))
    for i, (lead, k, off) in mimic.position.items():
        qj[i] = k * qj[lead] + off
    qp = jm.q_to_pin(qj, pm.nq)
    n = mimic.G.shape[1]
    vj, aj, tau = mimic.G @ rng.normal(size=n), mimic.G @ rng.normal(size=n), rng.normal(size=n)
    P = jm.P
    vp, ap, taup = P @ vj, P @ aj, P @ np.linalg.pinv(mimic.G.T) @ tau
    for alg in ("rnea", "aba"):
        t = time.perf_counter()
        rta.algorithm_kernels(model, alg, "tables")
        tables = rta.kernel_of(model, alg, "tables")
        t_tables = time.perf_counter() - t
        t = time.perf_counter()
        flat = rta.kernel_of(model, alg, "flat")
        t_flat = time.perf_counter() - t
        print(f"{alg}: tables ready in {t_tables:.2f} s (library cached: tables packed, library loaded), "
              f"flat kernel in {t_flat:.2f} s")
        args = (qj, vj, aj) if alg == "rnea" else (qj, vj, tau)
        d = pm.createData()
        ref = (lambda: pin.rnea(pm, d, qp, vp, ap)) if alg == "rnea" else (lambda: pin.aba(pm, d, qp, vp, taup))
        compare(f"{name} {alg} kernel", {"tables": lambda: tables(*args), "flat": lambda: flat(*args),
                                         "pinocchio": ref}, calls, rounds)
        door = getattr(nc, alg)
        compare(f"{name} nc.{alg}", {"tables": lambda: door(model, *args, kernels="tables"),
                                     "flat": lambda: door(model, *args, kernels="flat")}, calls, rounds)


def batches(name: str, states: int, rounds: int) -> None:
    """Per state over ``states`` states in one call each (interleaved rounds, best and median)."""
    import ncgen as nc
    from ncgen.assembly.tree_dynamics import MimicMap
    from pinocchio_robots import ROBOTS, pinocchio_models, random_configuration, JointMap, urdf_text

    model = nc.System.from_urdf(urdf_text(name), floating_base=ROBOTS[name][1]).build()
    _, pm = pinocchio_models(name)
    jm, mimic = JointMap(model, pm), MimicMap(model)
    rng = np.random.default_rng(1)
    Q = np.array([jm.q_to_ncgen(random_configuration(pm, rng)) for _ in range(states)])
    for i, (lead, k, off) in mimic.position.items():
        Q[:, i] = k * Q[:, lead] + off
    n = mimic.G.shape[1]
    V, A = rng.normal(size=(states, n)) @ mimic.G.T, rng.normal(size=(states, n)) @ mimic.G.T
    TAU = rng.normal(size=(states, n))
    for alg, args in (("rnea", (Q, V, A)), ("aba", (Q, V, TAU)), ("crba", (Q,))):
        door = getattr(nc, alg)
        compare(f"{name} {alg} per state in batches of {states}",
                {k: (lambda k=k: door(model, *args, kernels=k)) for k in ("tables", "flat")}, 1, rounds,
                per=states)


def simulate_runs(runs: int) -> None:
    from pinocchio_robots import urdf_text

    with tempfile.TemporaryDirectory() as tmp:
        urdf = Path(tmp) / "panda.urdf"
        urdf.write_text(urdf_text("panda"))
        env = {**os.environ, "NCGEN_CACHE_DIR": str(Path(tmp) / "cache"),
               "PYTHONPATH": os.pathsep.join([str(HERE.parent), os.environ.get("PYTHONPATH", "")])}
        print("\n=== ncgen simulate panda.urdf --t-end 1 (fresh processes; run 1 with an empty cache)")
        for r in range(runs):
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            t = time.perf_counter()
            out = subprocess.run([sys.executable, "-m", "ncgen.cli", "simulate", str(urdf), "--t-end", "1",
                                  "-o", str(Path(tmp) / "traj.npz")], env=env, capture_output=True, text=True)
            wall = time.perf_counter() - t
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
            status = "ok" if out.returncode == 0 else f"failed: {out.stderr.strip().splitlines()[-1:]}"
            print(f"run {r + 1}: {wall:.2f} s wall, {cpu:.2f} s CPU ({status})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--robots", nargs="+", default=["panda", "ur5"])
    ap.add_argument("--calls", type=int, default=2000)
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--states", type=int, default=1000)
    ap.add_argument("--simulate-runs", type=int, default=3)
    ap.add_argument("--skip-simulate", action="store_true")
    ap.add_argument("--smoke", action="store_true")
    a = ap.parse_args()
    if a.smoke:
        a.robots, a.calls, a.rounds, a.simulate_runs, a.states = ["ur5"], 20, 2, 1, 20
    print(machine())
    for name in a.robots:
        algorithms(name, a.calls, a.rounds)
        batches(name, a.states, a.rounds)
    if not a.skip_simulate:
        simulate_runs(a.simulate_runs)
    print(f"\nload average at the end: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
