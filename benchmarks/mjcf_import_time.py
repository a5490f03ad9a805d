"""Import time of an MJCF model (issue 40's targets: a Menagerie arm ≤ 3 s the first time,
≤ 1 s after, through the store of built models).

* First and later imports, each in a fresh process with its own store
  (``$NCGEN_CACHE_DIR`` in a temporary folder): ``System.from_mjcf(path)`` and then
  ``.build()``, wall and CPU seconds of this process (the interpreter's start and ``import
  ncgen`` included in "whole process"); the first run parses the file (SymPy derives the
  body coordinates' formulas once per process) and builds, later runs read both from the
  store.  Default file: the UR5e of ``$NCGEN_MENAGERIE`` (a mujoco_menagerie checkout), else
  ``tests/data/sequences.xml``.
* Scaling of the parse: chains of n hinged bodies with springs (2n checked elements), in
  one process (store off, text): seconds per element should not grow with n.

Times are wall-clock and CPU on a shared machine (the CPU model and the load average are
printed); CPU seconds are the steadier figure under load.
``python benchmarks/mjcf_import_time.py [FILE] [--rounds 2] [--smoke]``."""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import machine

ROOT = Path(__file__).resolve().parents[1]
CHILD = """
import json, sys, time, resource, warnings
t0, c0 = time.perf_counter(), time.process_time()
import ncgen as nc
warnings.simplefilter("ignore")
t1, c1 = time.perf_counter(), time.process_time()
s = nc.System.from_mjcf(sys.argv[1])
t2, c2 = time.perf_counter(), time.process_time()
m = s.build()
t3, c3 = time.perf_counter(), time.process_time()
print(json.dumps({"parse": [t2 - t1, c2 - c1], "build": [t3 - t2, c3 - c2], "dof": m.dof}))
"""


def default_file() -> Path:
    menagerie = os.environ.get("NCGEN_MENAGERIE")
    arm = Path(menagerie) / "universal_robots_ur5e" / "ur5e.xml" if menagerie else None
    return arm if arm is not None and arm.is_file() else ROOT / "tests" / "data" / "sequences.xml"


def process_run(path: Path, cache: str) -> dict:
    """One fresh process: its own figures, and the whole process's wall and CPU seconds."""
    env = {**os.environ, "NCGEN_CACHE_DIR": cache, "PYTHONPATH": str(ROOT)}
    env.pop("NCGEN_MODEL_CACHE", None)
    before = os.times()
    start = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", CHILD, str(path)], env=env, capture_output=True, text=True,
                         check=True)
    wall = time.perf_counter() - start
    after = os.times()
    figures = json.loads(out.stdout.strip().splitlines()[-1])
    figures["process"] = [wall, (after.children_user - before.children_user)
                          + (after.children_system - before.children_system)]
    return figures


def chain(n: int) -> str:
    body = ""
    for k in reversed(range(n)):
        body = (f'<body name="b{k}" pos="{0.0 if k == 0 else 0.2} 0 {1.0 if k == 0 else 0.0}">'
                f'<joint name="j{k}" axis="0 1 0" stiffness="1"/>'
                f'<geom type="capsule" fromto="0 0 0 0.2 0 0" size="0.02"/>{body}</body>')
    return f'<mujoco model="chain"><worldbody>{body}</worldbody></mujoco>'


def scaling(sizes) -> None:
    import ncgen as nc
    nc.System.from_mjcf(chain(2))                          # the derivation, once per process
    print("parse of a chain of n hinged bodies with springs (2n elements), store off:")
    for n in sizes:
        t, c = time.perf_counter(), time.process_time()
        nc.System.from_mjcf(chain(n))
        wall, cpu = time.perf_counter() - t, time.process_time() - c
        print(f"  n = {n:4d}: wall {wall:7.3f} s, CPU {cpu:7.3f} s, CPU per element {1e3 * cpu / (2 * n):6.2f} ms")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("file", nargs="?", default=None)
    p.add_argument("--rounds", type=int, default=2, help="later imports after the first")
    p.add_argument("--smoke", action="store_true", help="one later round, chains of 5 and 10")
    args = p.parse_args()
    path = Path(args.file) if args.file else default_file()
    print(machine())
    print(f"load average: {', '.join(f'{x:.2f}' for x in os.getloadavg())}; {os.cpu_count()} CPUs")
    print(f"file: {path}")
    with tempfile.TemporaryDirectory() as cache:
        for k in range(1 + (1 if args.smoke else args.rounds)):
            f = process_run(path, cache)
            label = "first" if k == 0 else f"later {k}"
            print(f"{label:8s} parse wall {f['parse'][0]:6.2f} s CPU {f['parse'][1]:6.2f} s | build wall "
                  f"{f['build'][0]:6.2f} s CPU {f['build'][1]:6.2f} s | whole process wall {f['process'][0]:6.2f} s "
                  f"CPU {f['process'][1]:6.2f} s | dof {f['dof']}")
    scaling((5, 10) if args.smoke else (10, 20, 40, 80))
    print(f"load average at the end: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
