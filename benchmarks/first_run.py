"""First run: the end-to-end wall time of the first ``ncgen simulate`` of every shipped
example (and the Panda of example-robot-data, if installed) with an empty compile cache, as
a new user meets it; beside it, with ``--compare``, the same first run forced to compile
(``--backend compiled``, the CLI's old default), interleaved; and model -> loaded library
against chain length (benchmarks/build_scaling.py's measurement, each N in a fresh process
and cache).

Each run is a fresh process (``python -m ncgen.cli simulate MODEL --t-end T``) with
``NCGEN_CACHE_DIR`` a new temporary directory: Python start-up, imports, SymPy derivation,
CasADi assembly, the backend decision (ncgen/runtime/backend_policy.py), integration and the
summary all count.  Wall time and the child's CPU time (user + system) are printed, with the
load average: on a shared machine wall time is CPU time times the queue.

    python benchmarks/first_run.py                    every example, t_end 2 s, chains 10 .. 200
    python benchmarks/first_run.py --compare          also the forced compile, ratio per example
    python benchmarks/first_run.py --smoke            two examples, chains 2 and 4 (CI)
"""
from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

import numpy as np

from common import machine

HERE = Path(__file__).resolve().parent
EXAMPLES = HERE.parent / "examples"
#: Targets of issue 22 (seconds, end to end, cold cache).
TARGET, TARGET_URDF, TARGET_LIBRARY = 5.0, 10.0, 10.0


def examples() -> list[Path]:
    return [p for p in sorted(EXAMPLES.glob("*.toml")) if "members" in tomllib.loads(p.read_text())]


def panda() -> Path | None:
    try:
        sys.path.insert(0, str(HERE.parent))
        import ncgen as nc
        return nc.robots.urdf_path("panda")
    except Exception:  # noqa: BLE001 - not installed: measured without it
        return None


def first_run(model: Path, t_end: float, backend: str) -> tuple[float, float, int, str]:
    """``(wall s, child CPU s, exit status, backend line)`` of one cold ``ncgen simulate``."""
    with tempfile.TemporaryDirectory(prefix="ncgen-first-") as tmp:
        env = {**os.environ, "NCGEN_CACHE_DIR": f"{tmp}/cache", "PYTHONPATH": str(HERE.parent)}
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        out = subprocess.run([sys.executable, "-m", "ncgen.cli", "simulate", str(model), "--t-end", str(t_end),
                              "--backend", backend], capture_output=True, text=True, env=env, cwd=tmp)
        wall = time.perf_counter() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    line = next((x.strip() for x in out.stdout.splitlines() if "integrator:" in x), out.stderr.strip()[-200:])
    return wall, cpu, out.returncode, line


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--smoke", action="store_true", help="two examples, tiny chains (CI)")
    parser.add_argument("--t-end", type=float, default=2.0, help="simulated time per example (s, default 2)")
    parser.add_argument("--compare", action="store_true", help="also the first run with --backend compiled")
    parser.add_argument("--chains", type=int, nargs="*", default=None, help="chain lengths (default 10 20 40 80 160 200)")
    args = parser.parse_args(argv)
    print(machine())
    models = examples()[:2] if args.smoke else examples()
    robot = None if args.smoke else panda()
    if robot is not None:
        models.append(robot)
    t_end = 0.2 if args.smoke else args.t_end
    print(f"\n=== first ncgen simulate, cold cache, --t-end {t_end:g} (target <= {TARGET:g} s; URDF <= {TARGET_URDF:g} s) ===")
    print(f"  {'model':<18} {'wall':>7} {'cpu':>7} {'target':>7}  backend decision")
    ratios = []
    for model in models:
        wall, cpu, status, line = first_run(model, t_end, "auto")
        target = TARGET_URDF if model.suffix == ".urdf" else TARGET
        verdict = "FAILED" if status else ("ok" if wall <= target else "over")
        print(f"  {model.stem:<18} {wall:>6.2f}s {cpu:>6.2f}s {verdict:>7}  {line}")
        if args.compare:
            cwall, ccpu, cstatus, _ = first_run(model, t_end, "compiled")
            print(f"  {'  (compiled)':<18} {cwall:>6.2f}s {ccpu:>6.2f}s {'FAILED' if cstatus else '':>7}")
            ratios.append(wall / cwall)
    if ratios:
        print(f"  RATIO first run auto / compiled: min {min(ratios):.2f}, median {np.median(ratios):.2f}")
    sizes = [2, 4] if args.smoke else (args.chains or [10, 20, 40, 80, 160, 200])
    sys.path.insert(0, str(HERE))
    from build_scaling import spawn
    print(f"\n=== model -> loaded library, chain of N bars, fresh process and cache (target monotonic, "
          f"<= {TARGET_LIBRARY:g} s up to 200) ===")
    print(f"  {'N':>5} {'build':>8} {'generate':>9} {'compile':>8} {'load':>7} {'total':>8}")
    totals = []
    for n in sizes:
        r = spawn("ncgen", n, 1800.0, None)
        if r is None:
            print(f"  {n:>5}  did not finish within 1800 s")
            continue
        t = r["times"]
        total = t["build"] + t["generate"] + t["compile"] + t["load"]
        totals.append((n, total))
        print(f"  {n:>5} {t['build']:>7.2f}s {t['generate']:>8.2f}s {t['compile']:>7.2f}s {t['load']:>6.2f}s {total:>7.2f}s")
    falls = [f"{a[0]}->{b[0]}" for a, b in zip(totals, totals[1:]) if b[1] < a[1]]
    print(f"  monotonic in N: {'yes' if not falls else 'no, falls at ' + ', '.join(falls)}")
    print(f"load average at end: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
