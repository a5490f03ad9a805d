"""A model never seen before, from ``System`` to its first compiled step with nothing compiled
(issue 34's target: at most 1 s).

Each run is a fresh process with no C compiler on ``PATH`` (and no ``CC``) and its own copy of a
compile cache that holds only what ncgen compiles once per version (the element library) and
the coordinate types' derivations — a user's cache after ncgen has run once, with none of
these models built or stored.  The child times, in CPU seconds (``time.process_time``), the
imports (NumPy, CasADi, ncgen), the ``System`` (constructed, or read from its URDF), ``build()``
and the first ``nc.simulate(model, 2 h, h, method="stepper", kernels="tables")`` (packing the
tables, loading the library, the consistent state, two steps), and says whether SymPy was
imported.  Models: a chain of 10 bars and a planar four-bar whose dimensions change with the
round (new to the cache every time), and the UR5, SO-101 and Panda URDFs of the test extras
(example-robot-data).  With ``--peer ROOT`` the same runs of another ncgen checkout
(e.g. ``/work/main``) alternate with this tree's, and the ratios (this / peer) are printed.

    python benchmarks/second_model.py [--rounds 3] [--peer /work/main] [--models chain fourbar ur5]
    python benchmarks/second_model.py --smoke          the chain, one round
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
H = 1e-3
URDFS = {"ur5": "ur_description/urdf/ur5_robot.urdf", "so101": "so_arm_description/urdf/so101.urdf",
         "panda": "panda_description/urdf/panda.urdf"}
TARGET = 1.0

CHILD = r"""
import json, sys, time
t0 = time.process_time()
import numpy as np, casadi
import ncgen as nc
t1 = time.process_time()
kind, seed, h = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
if kind == "chain":
    s = nc.System(f"chain_{seed}")
    start, pos = s.ground.point((0.0, 0.0, 0.0)), np.zeros(3)
    for k in range(10):
        pos = pos + np.array([0.4 + 0.001 * seed + 0.01 * k, 0.05 * (k % 3), -0.02])
        start = s.add_bar(f"link{k}", coords="rr", mass=0.3 + 0.02 * k, ends=[start, tuple(pos)]).end(1)
elif kind == "fourbar":
    s = nc.System(f"fourbar_{seed}", gravity=(0.0, -9.81))
    crank = s.add_bar("crank", coords="rr", mass=0.4, ends=[(0.0, 0.0), (0.3, 0.7 + 0.001 * seed)])
    coupler = s.add_bar("coupler", coords="rr", mass=1.1, ends=[crank.end(1), (2.2, 1.9)])
    s.add_bar("rocker", coords="rr", mass=0.9, ends=[coupler.end(1), s.ground.point((2.6, 0.0))])
    s.add_joint(nc.Revolute(s.ground, crank, at=(0.0, 0.0)))
else:
    import importlib.metadata as md
    path = [f for f in md.files("example-robot-data") if str(f).endswith(kind)][0].locate()
    s = nc.System.from_urdf(str(path))
t2 = time.process_time()
model = s.build()
t3 = time.process_time()
traj = nc.simulate(model, 2 * h, h, method="stepper", kernels="tables")
t4 = time.process_time()
print(json.dumps({"imports": t1 - t0, "system": t2 - t1, "build": t3 - t2, "first step": t4 - t3,
                  "total": t4 - t1, "sympy": "sympy" in sys.modules, "kernels": traj.info.get("kernels"),
                  "ncgen": nc.__file__}))
"""


def child_env(root: Path, cache: Path, pycache: Path, compiler: bool) -> dict:
    """The child's environment: ``root`` on the path, ``cache`` as compile cache, Python's bytecode
    in the private prefix ``pycache`` (written by the preparing runs, as a user's installation
    has its ``.pyc`` files), and with ``compiler`` False an empty ``PATH`` and no ``CC``."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("CC", "PYTHONPATH", "NCGEN_CACHE_DIR", "PYTHONDONTWRITEBYTECODE")}
    env["PYTHONPATH"], env["NCGEN_CACHE_DIR"] = str(root), str(cache)
    env["PYTHONPYCACHEPREFIX"] = str(pycache)
    if not compiler:
        env["PATH"] = str(cache.parent / "no-compiler-bin")
    return env


def prepare(root: Path, base: Path, models: list[str]) -> None:
    """``base``: the per-version libraries compiled and the derivations stored (each model run
    once with a compiler), then the store of built models emptied."""
    base.mkdir(parents=True)
    for kind in models:
        env = child_env(root, base, base.parent / "pycache", True)
        out = subprocess.run([sys.executable, "-c", CHILD, kind, "999", str(H)], env=env, capture_output=True, text=True,
                             cwd=base.parent)
        if out.returncode:
            sys.exit(f"{root}: preparing {kind} failed:\n{out.stderr[-2000:]}")
    shutil.rmtree(base / "models", ignore_errors=True)


def run(root: Path, base: Path, kind: str, seed: int) -> dict:
    work = Path(tempfile.mkdtemp(dir=base.parent))
    cache = work / "cache"
    shutil.copytree(base, cache)
    (work / "no-compiler-bin").mkdir()
    env = child_env(root, cache, base.parent / "pycache", False)
    out = subprocess.run([sys.executable, "-c", CHILD, kind, str(seed), str(H)], env=env, capture_output=True, text=True,
                         cwd=work)       # not the caller's directory: `python -c` puts it first on sys.path
    shutil.rmtree(work, ignore_errors=True)
    if out.returncode:
        sys.exit(f"{root}: {kind} failed without a compiler:\n{out.stderr[-2000:]}")
    result = json.loads(out.stdout.strip().splitlines()[-1])
    if not Path(result["ncgen"]).resolve().is_relative_to(root):
        sys.exit(f"{root}: the child imported ncgen from {result['ncgen']}")
    return result


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--peer", type=Path, help="another ncgen checkout, run alternately")
    ap.add_argument("--models", nargs="+", default=["chain", "fourbar", *URDFS], choices=["chain", "fourbar", *URDFS])
    ap.add_argument("--smoke", action="store_true", help="the chain, one round")
    args = ap.parse_args()
    if args.smoke:
        args.rounds, args.models = 1, ["chain"]
    roots = {"this": ROOT, **({"peer": args.peer.resolve()} if args.peer else {})}
    kinds = [URDFS.get(m, m) for m in args.models]
    print(machine())
    with tempfile.TemporaryDirectory() as tmp:
        bases = {name: Path(tmp) / name / "base" for name in roots}
        for name, root in roots.items():
            prepare(root, bases[name], kinds)
        results = {(name, m): [] for name in roots for m in args.models}
        for r in range(args.rounds):
            for m, kind in zip(args.models, kinds):
                for name in (roots if r % 2 == 0 else list(roots)[::-1]):
                    results[name, m].append(run(roots[name], bases[name], kind, r))
    print(f"\n=== a model never seen -> first compiled step, no compiler on PATH (CPU s, min / median of "
          f"{args.rounds}; target ≤ {TARGET} s for System + build + first step)")
    for m in args.models:
        for name, root in roots.items():
            rs = results[name, m]
            cols = "  ".join(f"{k} {min(x[k] for x in rs):.3f} / {statistics.median(x[k] for x in rs):.3f}"
                             for k in ("imports", "system", "build", "first step", "total"))
            print(f"  {m:8s} {name:5s} ({root}): {cols}  SymPy imported: {any(x['sympy'] for x in rs)}  "
                  f"kernels {rs[0]['kernels']}")
        if "peer" in roots:
            a, b = ([x["total"] for x in results[n, m]] for n in ("this", "peer"))
            print(f"  RATIO {m} System -> first step, this / peer: min {min(a) / min(b):.2f}, "
                  f"median {statistics.median(a) / statistics.median(b):.2f}")
    print(f"load average at end: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
