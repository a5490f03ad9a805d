"""Build time of an MJCF model with its geoms as contacts (``from_mjcf(path, contacts=True)``):
by default the Menagerie Panda (``$NCGEN_MENAGERIE``; its fingertip pads' box pairs are 400
box-corner contact points), else ``tests/data/contacts.xml``.

Each measurement is a fresh process: the parse, then the build with the store of built
models off (``NCGEN_MODEL_CACHE=0``) and, in another process, through an empty store (the
build plus writing the model: serialising its functions, the read-back check, the pickle).
CPU seconds (``time.process_time``).  ``--peer DIR``: another source tree of ncgen (e.g.
``git archive <commit> | tar -x -C DIR``) measured in the same rounds, the trees taking turns
(each round reverses their order); min and median over the rounds and the peer's ratio.
``python benchmarks/mjcf_contacts_build.py [FILE] [--rounds 2] [--peer DIR]``."""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from common import machine

ROOT = Path(__file__).resolve().parents[1]
PANDA = "franka_emika_panda/panda.xml"
CHILD = """
import json, sys, time, warnings
warnings.simplefilter("ignore")
import ncgen as nc
c0 = time.process_time()
s = nc.System.from_mjcf(sys.argv[1], contacts=True)
c1 = time.process_time()
m = s.build()
c2 = time.process_time()
print(json.dumps({"parse": c1 - c0, "build": c2 - c1, "points": m.nk}))
"""


def run(tree: Path, path: Path, store: bool) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree), "NCGEN_CACHE_DIR": tempfile.mkdtemp(prefix="ncgen_contacts_")}
    env.pop("NCGEN_MODEL_CACHE", None)
    if not store:
        env["NCGEN_MODEL_CACHE"] = "0"
    out = subprocess.run([sys.executable, "-c", CHILD, str(path.resolve())], env=env, capture_output=True,
                         text=True, check=True, cwd=tempfile.gettempdir())
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("file", nargs="?", type=Path)
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--peer", type=Path, default=None, help="another ncgen source tree, measured in turn")
    args = p.parse_args()
    menagerie = os.environ.get("NCGEN_MENAGERIE")
    path = args.file or (Path(menagerie) / PANDA if menagerie and (Path(menagerie) / PANDA).is_file()
                         else ROOT / "tests" / "data" / "contacts.xml")
    print(machine())
    print(f"load average: {', '.join(f'{x:.2f}' for x in os.getloadavg())}; file: {path}")
    trees = {"this": ROOT} | ({"peer": args.peer.resolve()} if args.peer else {})
    figures = {(t, s): [] for t in trees for s in (False, True)}
    for r in range(args.rounds):
        for name in (list(trees) if r % 2 == 0 else list(trees)[::-1]):
            for store in (False, True):
                f = run(trees[name], path, store)
                figures[name, store].append(f["build"])
                print(f"  round {r + 1} {name:4s} {'store' if store else 'no store'}: parse {f['parse']:.2f} s, "
                      f"build {f['build']:.2f} s CPU, {f['points']} contact points", flush=True)
    for store in (False, True):
        what = "through the store" if store else "store off"
        for name in trees:
            xs = figures[name, store]
            print(f"build {what:17s} {name}: min {min(xs):.2f} s, median {np.median(xs):.2f} s CPU")
        if args.peer:
            a, b = figures["peer", store], figures["this", store]
            print(f"  peer / this: min {min(a) / min(b):.2f}, median {np.median(a) / np.median(b):.2f}")
    print(f"load average at the end: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
