"""Import time of an MJCF model (issue 40's targets: a Menagerie arm ≤ 3 s the first time,
≤ 1 s after, through the store of built models).

* First and later imports as a user meets them: each a fresh process
  (``python -c``: the interpreter's start, ``import ncgen``, ``System.from_mjcf(path)``,
  ``.build()``), the first with an empty store of its own (``$NCGEN_CACHE_DIR`` a new
  temporary folder), the later ones reading that store.  Wall and CPU seconds of the whole
  process (the child's user + system time) and, inside it, of the parse and of the build.
  Default files: the arms of ``$NCGEN_MENAGERIE`` (a mujoco_menagerie checkout: UR5e,
  Panda, Kinova Gen3, UR10e, those present), else ``tests/data/sequences.xml``.
* Python's bytecode: ``--bytecode cached`` (default) is what an installed package meets
  (pip writes the ``.pyc`` files at install): a warm-up process per tree fills a bytecode
  folder of the benchmark's own (``PYTHONPYCACHEPREFIX``) before the measured runs;
  ``--bytecode none`` compiles every module from source in each process (as
  ``PYTHONDONTWRITEBYTECODE=1`` does).
* ``--peer DIR``: another source tree of ncgen (e.g. ``git archive <commit> | tar -x -C DIR``)
  measured in the same rounds, the two trees taking turns (each round reverses their order);
  min and median of each figure over the rounds and the peer's ratio to this tree's.
* Scaling of the parse: chains of n hinged bodies with springs (2n checked elements), in
  one process (store off, text): seconds per element should not grow with n.

On a shared machine wall time is CPU time times the queue: the CPU model and the load
average are printed, and the targets are judged on CPU seconds.
``python benchmarks/mjcf_import_time.py [FILE ...] [--rounds 3] [--peer DIR] [--bytecode cached|none] [--smoke]``."""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from common import machine

ROOT = Path(__file__).resolve().parents[1]
#: Issue 40's targets, CPU seconds of the whole process.
FIRST, LATER = 3.0, 1.0
ARMS = ("universal_robots_ur5e/ur5e.xml", "franka_emika_panda/panda.xml", "kinova_gen3/gen3.xml",
        "universal_robots_ur10e/ur10e.xml")
CHILD = """
import json, sys, time, warnings
t0, c0 = time.perf_counter(), time.process_time()
import ncgen as nc
warnings.simplefilter("ignore")
t1, c1 = time.perf_counter(), time.process_time()
s = nc.System.from_mjcf(sys.argv[1])
t2, c2 = time.perf_counter(), time.process_time()
m = s.build()
t3, c3 = time.perf_counter(), time.process_time()
print(json.dumps({"parse": [t2 - t1, c2 - c1], "build": [t3 - t2, c3 - c2], "dof": m.dof,
                  "sympy": "sympy" in sys.modules, "ncgen": nc.__file__}))
"""


def default_files() -> list[Path]:
    menagerie = os.environ.get("NCGEN_MENAGERIE")
    arms = [Path(menagerie) / a for a in ARMS] if menagerie else []
    return [a for a in arms if a.is_file()] or [ROOT / "tests" / "data" / "sequences.xml"]


def process_run(tree: Path, path: Path, cache: str, pycache: str | None) -> dict:
    """One fresh process on ``tree``'s ncgen: its own figures, and the whole process's wall
    and CPU seconds."""
    env = {**os.environ, "NCGEN_CACHE_DIR": cache, "PYTHONPATH": str(tree)}
    env.pop("NCGEN_MODEL_CACHE", None)
    if pycache is None:
        env["PYTHONDONTWRITEBYTECODE"] = "1"
        env.pop("PYTHONPYCACHEPREFIX", None)
    else:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        env["PYTHONPYCACHEPREFIX"] = pycache
    before = os.times()
    start = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", CHILD, str(path)], env=env, capture_output=True, text=True,
                         cwd=tempfile.gettempdir())
    wall = time.perf_counter() - start
    after = os.times()
    if out.returncode != 0:
        raise SystemExit(f"{tree}: importing {path} failed:\n{out.stderr[-3000:]}")
    figures = json.loads(out.stdout.strip().splitlines()[-1])
    if Path(figures["ncgen"]).resolve().parents[1] != tree.resolve():
        raise SystemExit(f"the child imported {figures['ncgen']}, not the tree {tree}")
    figures["process"] = [wall, (after.children_user - before.children_user)
                          + (after.children_system - before.children_system)]
    return figures


def one_round(k: int, trees: dict[str, Path], path: Path, later: int, pycache: str | None) -> dict:
    """Each tree's first import (an empty store) and ``later`` imports reading that store,
    the trees in turn (their order reversed in odd rounds)."""
    out = {}
    for name in (list(trees) if k % 2 == 0 else list(reversed(trees))):
        with tempfile.TemporaryDirectory(prefix="ncgen-import-") as cache:
            runs = [process_run(trees[name], path, cache, pycache) for _ in range(1 + later)]
        for j, f in enumerate(runs):
            label = "first" if j == 0 else f"later {j}"
            print(f"  round {k + 1} {name:5s} {label:8s} parse wall {f['parse'][0]:6.2f} s CPU {f['parse'][1]:6.2f} s"
                  f" | build wall {f['build'][0]:6.2f} s CPU {f['build'][1]:6.2f} s | whole process wall "
                  f"{f['process'][0]:6.2f} s CPU {f['process'][1]:6.2f} s | dof {f['dof']}"
                  + (" | SymPy imported" if f["sympy"] else ""))
        out[name] = runs
    return out


def summary(path: Path, rounds: list[dict]) -> None:
    """Min and median CPU seconds of the whole process, first and later, per tree; the
    peer's ratios to this tree's; the targets judged on this tree's median."""
    print(f"=== {path.name}: CPU seconds of the whole process over {len(rounds)} rounds (min, median)")
    cpu = {name: {"first": [r[name][0]["process"][1] for r in rounds],
                  "later": [x["process"][1] for r in rounds for x in r[name][1:]]} for name in rounds[0]}
    for name, figures in cpu.items():
        print(f"  {name:5s} " + "   ".join(f"{kind} min {min(ts):5.2f} median {np.median(ts):5.2f}"
                                         for kind, ts in figures.items() if ts))
    if "peer" in cpu:
        for kind in ("first", "later"):
            if cpu["this"][kind]:
                print(f"  RATIO peer / this, {kind}: min {min(cpu['peer'][kind]) / min(cpu['this'][kind]):.2f}, "
                      f"median {np.median(cpu['peer'][kind]) / np.median(cpu['this'][kind]):.2f}")
    for kind, target in (("first", FIRST), ("later", LATER)):
        if cpu["this"][kind]:
            median = float(np.median(cpu["this"][kind]))
            print(f"  TARGET {kind} ≤ {target:g} s CPU: {'met' if median <= target else 'NOT met'} "
                  f"(median {median:.2f} s)")


def warm_bytecode(trees: dict[str, Path], path: Path, pycache: str) -> None:
    """Fill the bytecode folder: one first import per tree in a store thrown away."""
    for tree in trees.values():
        with tempfile.TemporaryDirectory(prefix="ncgen-warm-") as cache:
            process_run(tree, path, cache, pycache)


def chain(n: int) -> str:
    body = ""
    for k in reversed(range(n)):
        body = (f'<body name="b{k}" pos="{0.0 if k == 0 else 0.2} 0 {1.0 if k == 0 else 0.0}">'
                f'<joint name="j{k}" axis="0 1 0" stiffness="1"/>'
                f'<geom type="capsule" fromto="0 0 0 0.2 0 0" size="0.02"/>{body}</body>')
    return f'<mujoco model="chain"><worldbody>{body}</worldbody></mujoco>'


def scaling(sizes) -> None:
    import ncgen as nc
    nc.System.from_mjcf(chain(2))                          # the first elements' one-off costs
    print("parse of a chain of n hinged bodies with springs (2n elements), store off:")
    for n in sizes:
        t, c = time.perf_counter(), time.process_time()
        nc.System.from_mjcf(chain(n))
        wall, cpu = time.perf_counter() - t, time.process_time() - c
        print(f"  n = {n:4d}: wall {wall:7.3f} s, CPU {cpu:7.3f} s, CPU per element {1e3 * cpu / (2 * n):6.2f} ms")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("files", nargs="*", type=Path)
    p.add_argument("--rounds", type=int, default=3, help="rounds of first and later imports")
    p.add_argument("--later", type=int, default=2, help="later imports per round")
    p.add_argument("--peer", type=Path, default=None, help="another ncgen source tree, measured in turn")
    p.add_argument("--bytecode", choices=("cached", "none"), default="cached")
    p.add_argument("--smoke", action="store_true", help="one round, one later import, chains of 5 and 10")
    args = p.parse_args()
    if args.smoke:
        args.rounds, args.later = 1, 1
    files = args.files or default_files()
    trees = {"this": ROOT, **({"peer": args.peer} if args.peer else {})}
    print(machine())
    print(f"load average: {', '.join(f'{x:.2f}' for x in os.getloadavg())}; {os.cpu_count()} CPUs")
    print(f"trees: {', '.join(f'{k} {v}' for k, v in trees.items())}; bytecode: "
          + ("cached (a warm-up process per tree first, as after pip install)" if args.bytecode == "cached"
             else "none (every module compiled from source in each process)"))
    with tempfile.TemporaryDirectory(prefix="ncgen-pyc-") as pycache:
        for path in files:
            print(f"file: {path}")
            if args.bytecode == "cached":
                warm_bytecode(trees, path, pycache)
            rounds = [one_round(k, trees, path, args.later, pycache if args.bytecode == "cached" else None)
                      for k in range(args.rounds)]
            summary(path, rounds)
    scaling((5, 10) if args.smoke else (10, 20, 40, 80))
    print(f"load average at the end: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
