"""``examples/box_stack.toml``'s first stepper run from an empty cache, this tree against a peer
checkout, interleaved (issue 34: first run ≤ 3 s).

Each run is a fresh process in the tree's own directory (``python -m ncgen.cli simulate
examples/box_stack.toml --method stepper --contacts nonsmooth --t-end T``, ``PYTHONPATH`` the
tree: a child started with ``-m`` imports the ncgen of its working directory) with a new, empty
``NCGEN_CACHE_DIR``: the model is built, its package generated and compiled (gcc), the run
made.  Per tree: CPU (user + system of the process and its compilers) and wall time, min and
median over the rounds, and the ratio of the CPU times per round.  The CPU model and the load
average are printed: on a shared machine wall time is CPU time times the queue.

    python benchmarks/box_stack_first_run.py --peer /work/main --rounds 3
    python benchmarks/box_stack_first_run.py --peer /work/main --rounds 3 --libraries
                          each run's cache starts with the tree's element and contact libraries
                          (compiled once per ncgen version: their compile is timed apart), the
                          model never seen
    python benchmarks/box_stack_first_run.py --smoke          this tree, 1 round, T = 0.001 s
    python benchmarks/box_stack_first_run.py --python /tmp/v/bin/python --rounds 3
                          the ncgen installed in that interpreter's environment (``pip install .``:
                          its libraries compiled at install), run outside the tree, no PYTHONPATH
"""
from __future__ import annotations

import argparse
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import machine

ROOT = Path(__file__).resolve().parent.parent
#: Issue 34's target for the first run (s).
TARGET = 3.0


LIBRARIES = """
from ncgen.runtime import table_library as t
t.load_element_library()
if hasattr(t, "load_contact_library"):
    t.load_contact_library()
"""


def children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def library_cache(tree: Path, into: Path) -> float:
    """``tree``'s element library (and contact library, where it has one) compiled into the
    cache ``into``; the CPU s it took."""
    env = {**os.environ, "PYTHONPATH": str(tree), "NCGEN_CACHE_DIR": str(into)}
    before = children_cpu()
    out = subprocess.run([sys.executable, "-c", LIBRARIES], capture_output=True, text=True, env=env, cwd=tree)
    if out.returncode:
        raise SystemExit(f"{tree}: building the libraries failed:\n{out.stderr}")
    return children_cpu() - before


def first_run(tree: Path, t_end: float, base: Path | None = None, python: str | None = None) -> dict:
    """One first run of box_stack in ``tree`` with an empty cache (or a copy of ``base``): CPU
    and wall s; with ``python``, that interpreter's installed ncgen, run in the cache folder."""
    with tempfile.TemporaryDirectory(prefix="box34-first-") as cache:
        if base is not None:
            shutil.copytree(base, cache, dirs_exist_ok=True)
        env = {**os.environ, "PYTHONPATH": str(tree), "NCGEN_CACHE_DIR": cache}
        if python is not None:
            env.pop("PYTHONPATH")
        cmd = [python or sys.executable, "-m", "ncgen.cli", "simulate", str(tree / "examples/box_stack.toml"),
               "--method", "stepper", "--contacts", "nonsmooth", "--t-end", str(t_end), "-o",
               str(Path(cache) / "out.npz")]
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        out = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=cache if python else tree)
        wall = time.perf_counter() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if out.returncode:
            raise SystemExit(f"{tree}: {' '.join(cmd)} failed:\n{out.stdout}\n{out.stderr}")
        return {"cpu": after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime, "wall": wall}


def summary(xs: list[float]) -> str:
    return f"{min(xs):7.2f} / {statistics.median(xs):7.2f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--peer", type=Path, help="another checkout to compare with (e.g. /work/main)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--t-end", type=float, default=0.01, help="simulated time (s)")
    ap.add_argument("--smoke", action="store_true", help="this tree only, 1 round, T = 0.001 s")
    ap.add_argument("--libraries", action="store_true",
                    help="start each cache with the tree's element (and contact) libraries compiled")
    ap.add_argument("--python", help="time the ncgen installed for this interpreter (no PYTHONPATH; the "
                    "peer and --libraries do not apply)")
    args = ap.parse_args()
    if args.python:
        args.peer, args.libraries = None, False
    if args.smoke:
        args.peer, args.rounds, args.t_end = None, 1, 0.001
    trees = {"this": ROOT} | ({"peer": args.peer.resolve()} if args.peer else {})
    print(machine())
    bases = {}
    if args.libraries:
        for name, tree in trees.items():
            bases[name] = Path(tempfile.mkdtemp(prefix="box34-libs-"))
            print(f"  {name}: libraries compiled in {library_cache(tree, bases[name]):.1f} CPU s (once per "
                  "ncgen version)", flush=True)
    what = "a cache with the libraries only" if args.libraries else "empty cache"
    print(f"box_stack first run ({what}), --t-end {args.t_end}, {args.rounds} rounds, interleaved")
    results = {k: [] for k in trees}
    for r in range(args.rounds):
        order = list(trees.items()) if r % 2 == 0 else list(reversed(trees.items()))
        for name, tree in order:
            res = first_run(tree, args.t_end, bases.get(name), args.python)
            results[name].append(res)
            print(f"  round {r + 1} {name:4s}: CPU {res['cpu']:6.2f} s, wall {res['wall']:6.2f} s, "
                  f"load {os.getloadavg()[0]:.1f}", flush=True)
    print(f"{'tree':6s} {'CPU s min / median':>20s} {'wall s min / median':>20s}  (target {TARGET} s)")
    for name, rs in results.items():
        print(f"{name:6s} {summary([x['cpu'] for x in rs]):>20s} {summary([x['wall'] for x in rs]):>20s}")
    if args.peer:
        ratio = [a["cpu"] / b["cpu"] for a, b in zip(results["this"], results["peer"])]
        print(f"CPU this / peer per round: min {min(ratio):.3f}, median {statistics.median(ratio):.3f}")
    for base in bases.values():
        shutil.rmtree(base, ignore_errors=True)


if __name__ == "__main__":
    main()
