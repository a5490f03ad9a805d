"""Load time: the first and later runs of ``ncgen simulate`` on the Panda URDF and on
``examples/box_stack.toml``, beside MuJoCo and Pinocchio loading a comparable model.

Each ncgen run is a fresh process (``python -m ncgen.cli simulate MODEL --t-end T``), so
Python start-up, imports, the model (built, or read from the store of built models,
``ncgen/codegen/model_cache.py``), the compiled code (compiled, or found in the compile cache)
and the integration all count.  Per model:

* **first run**: an ``NCGEN_CACHE_DIR`` empty but for the libraries compiled once per ncgen
  version and compiler (the tree library's units, the element library, the fast caller: a user
  pays them once, not per model; compiled before timing, :data:`PER_VERSION`) — nothing of the
  model stored or compiled; with ``--empty``, a completely empty cache (a user's first-ever
  run: what the run needs of the per-version libraries is compiled in it);
* **later runs**: the same cache directory again (model read back, library found);
* **store off**: later runs with ``NCGEN_MODEL_CACHE=0`` (the model built every time, as
  before the store; the compiled library still found), interleaved with the later runs;
* **first run, derivations stored**: the cache emptied but for the coordinate types'
  derivations (``ncgen/symbolic/derivation_store.py``): a model never seen, after ncgen has
  run once.

Python start-up alone (``python -c pass``) is printed too: what site-packages' ``.pth`` files
import counts in every run.  A later run's heavy imports (SymPy, SciPy, matplotlib, Jinja2,
yourdfpy, asyncio) are listed (none expected).

Python's bytecode is written to a private ``PYTHONPYCACHEPREFIX`` warmed before timing (a
user's installation has its ``.pyc`` files; ``PYTHONDONTWRITEBYTECODE`` would recompile
ncgen's sources in every process).  MuJoCo loads the same URDF with its visual and
collision meshes removed (``mujoco.MjModel.from_xml_string``; kinematics and inertias as
ncgen reads them), Pinocchio with ``pinocchio.buildModelFromUrdf``; each in a fresh process
(start-up and import included) and in process (the load call alone).  Wall and CPU time
(user + system of the child), min and median over the rounds, the CPU model and the load
average are printed: on a shared machine wall time is CPU time times the queue.

The same from Python: ``nc.System.from_urdf(panda).build()`` in a fresh process, first with an
empty cache, then on the warm store (``System.from_urdf`` of a file read before, ``build()`` of a
system built before), then with the store off; the child reports the CPU and wall time of the
imports (``numpy``, ``casadi``, ``ncgen``) and of the call itself, apart.  Each round is
followed by a MuJoCo and a Pinocchio load of the same robot in fresh processes (interleaved).

    python benchmarks/load_time.py                 Panda and box_stack, 5 rounds
    python benchmarks/load_time.py --rounds 3
    python benchmarks/load_time.py --smoke         slider_crank, 1 round (CI)
    python benchmarks/load_time.py --panda-only --rounds 3 --empty     first-ever runs
    python benchmarks/load_time.py --panda-only --rounds 3 --empty --peer /tmp/main
                       the same, each round also run with the ncgen tree at /tmp/main (e.g.
                       ``git archive main | tar -x -C /tmp/main``), ratios this tree / peer printed
    python benchmarks/load_time.py --panda-only --rounds 3 --empty --python /tmp/v/bin/python
                       the same with the ncgen installed for that interpreter (``pip install .``: its
                       libraries compiled at install; no PYTHONPATH)
"""
from __future__ import annotations

import argparse
import json
import os
import re
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from common import machine

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
EXAMPLES = ROOT / "examples"
#: Targets of issue 34 (seconds, wall, end to end).
TARGET_FIRST, TARGET_LATER = 3.0, 1.0
#: The interpreter of the ncgen runs (``--python``).
PYTHON = [sys.executable]


def panda_urdf() -> Path:
    sys.path.insert(0, str(ROOT))
    import ncgen as nc
    return Path(nc.robots.urdf_path("panda"))


def run(cmd: list[str], env: dict, cwd: str) -> tuple[float, float, str]:
    """``(wall s, child CPU s, stdout+stderr)`` of one process; raises if it fails."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    out = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=cwd)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if out.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({out.returncode}):\n{out.stderr[-2000:]}")
    return wall, cpu, out.stdout + out.stderr


def summary(name: str, samples: list[tuple[float, float]]) -> str:
    walls, cpus = [s[0] for s in samples], [s[1] for s in samples]
    return (f"  {name:<38} wall min {min(walls):7.3f} s, median {statistics.median(walls):7.3f} s | "
            f"CPU min {min(cpus):7.3f} s, median {statistics.median(cpus):7.3f} s  ({len(samples)} runs)")


def ncgen_runs(model: Path, t_end: float, rounds: int, base_env: dict, per_version: Path | None,
               kernels: str = "auto", peer: str | None = None) -> dict[str, dict[str, list[tuple[float, float]]]]:
    """First, later and store-off runs of ``ncgen simulate model --kernels kernels`` (see the
    module docstring), ``{tree: {label: samples}}``; each fresh cache starts with the
    per-version libraries of ``per_version`` (None: empty).  With ``peer`` (the root of another
    ncgen tree, run with ``PYTHONPATH`` set to it), each round runs this tree, then the peer."""
    trees = {"this tree": base_env} if peer is None else \
        {"this tree": base_env, "peer": {**base_env, "PYTHONPATH": peer}}
    out = {tree: {"first run (empty cache)": [], "later runs (model stored)": [], "later runs, store off": [],
                  FIRST_DERIVED: []} for tree in trees}
    cmd = [PYTHON[0], "-m", "ncgen.cli", "simulate", str(model), "--t-end", str(t_end), "--kernels", kernels]
    for env in trees.values():          # untimed: the bytecode of every module a run imports written
        with tempfile.TemporaryDirectory(prefix="ncgen-warm-") as tmp:
            run(cmd, {**env, "NCGEN_CACHE_DIR": f"{tmp}/cache"}, tmp)
    for r in range(rounds):
        for tree, env in trees.items():
            for label, samples in _ncgen_round(model, t_end, env, per_version, kernels).items():
                out[tree][label].append(samples)
    return out


def _ncgen_round(model: Path, t_end: float, base_env: dict, per_version: Path | None,
                 kernels: str) -> dict[str, tuple[float, float]]:
    """One round of :func:`ncgen_runs` in a fresh cache: ``{label: (wall, CPU)}``."""
    cmd = [PYTHON[0], "-m", "ncgen.cli", "simulate", str(model), "--t-end", str(t_end), "--kernels", kernels]
    out: dict[str, tuple[float, float]] = {}
    with tempfile.TemporaryDirectory(prefix="ncgen-load-") as tmp:
        cache = f"{tmp}/cache"
        env = {**base_env, "NCGEN_CACHE_DIR": cache}
        seed_per_version(per_version, Path(cache))
        out["first run (empty cache)"] = run(cmd, env, tmp)[:2]
        for label, extra in (("later runs (model stored)", {}), ("later runs, store off", {"NCGEN_MODEL_CACHE": "0"})):
            out[label] = run(cmd, {**env, **extra}, tmp)[:2]
        stored = list(Path(cache, "models").glob("*.model"))
        assert stored, f"{model.name}: nothing stored in {cache}/models"
        for entry in Path(cache).iterdir():          # all but the derivations: a model never seen
            if entry.name != "derivations":
                shutil.rmtree(entry) if entry.is_dir() else entry.unlink()
        seed_per_version(per_version, Path(cache))
        out[FIRST_DERIVED] = run(cmd, env, tmp)[:2]
    return out


#: What a fresh cache starts with: the libraries compiled once per ncgen version and compiler
#: (their index files name the libraries where they were compiled), the fast caller.
PER_VERSION = ("tree-tables-*.json", "element-tables-*.json", "fast_call-*")
#: Compiles the per-version libraries into a cache (the tree and element libraries, the fast caller).
PER_VERSION_BUILD = """
from ncgen.runtime.table_library import load_element_library
from ncgen.runtime.tree_library import build_tree_library
import ncgen.codegen.fast_call as fc
build_tree_library(); load_element_library(); fc._module()
"""


def seed_per_version(per_version: Path | None, cache: Path) -> None:
    """Copy the per-version entries of the cache ``per_version`` (None: none) into ``cache``."""
    cache.mkdir(parents=True, exist_ok=True)
    if per_version is None:
        return
    for pattern in PER_VERSION:
        for entry in per_version.glob(pattern):
            (shutil.copytree if entry.is_dir() else shutil.copy2)(entry, cache / entry.name)


#: A first run of a model (nothing stored, nothing compiled) after ncgen has run once: the
#: coordinate types' derivations are in the store (ncgen/symbolic/derivation_store.py).
FIRST_DERIVED = "first run, derivations stored"

LATER_IMPORTS = """
import json, sys
from ncgen.cli import main
assert main(sys.argv[1:]) == 0
print(json.dumps(sorted(m for m in ("sympy", "scipy", "matplotlib", "jinja2", "yourdfpy", "asyncio") if m in sys.modules)))
"""


def later_imports(model: Path, t_end: float, base_env: dict) -> list[str]:
    """The heavy modules a later run of ``ncgen simulate model`` imports (none expected)."""
    args = ["simulate", str(model), "--t-end", str(t_end)]
    with tempfile.TemporaryDirectory(prefix="ncgen-load-") as tmp:
        env = {**base_env, "NCGEN_CACHE_DIR": f"{tmp}/cache"}
        run([PYTHON[0], "-c", LATER_IMPORTS, *args], env, tmp)
        text = run([PYTHON[0], "-c", LATER_IMPORTS, *args], env, tmp)[2]
    return json.loads(text.strip().splitlines()[-1])


PYTHON_CHILD = """
import json, sys, time
c0, w0 = time.process_time(), time.perf_counter()
import numpy, casadi, ncgen as nc
from ncgen.model import system
c1, w1 = time.process_time(), time.perf_counter()
model = nc.System.from_urdf(sys.argv[1]).build()
c2, w2 = time.process_time(), time.perf_counter()
print(json.dumps({"import": [w1 - w0, c1 - c0], "load": [w2 - w1, c2 - c1], "sympy": "sympy" in sys.modules,
                  "stored": model.data.store_key is not None}))
"""


def python_runs(urdf: Path, rounds: int, base_env: dict, tmp: str) -> dict[str, list[tuple[float, float]]]:
    """``nc.System.from_urdf(urdf).build()`` in fresh processes: first, stored and store-off
    loads (the call alone, and the imports before it), each round followed by a MuJoCo and a
    Pinocchio load in fresh processes."""
    stripped = Path(tmp) / "model.urdf"
    stripped.write_text(mesh_free_urdf(urdf))
    out: dict[str, list[tuple[float, float]]] = {}
    refs = (("MuJoCo from_xml_string (process)", "mujoco_load", stripped),
            ("Pinocchio buildModelFromUrdf (process)", "pinocchio_load", urdf))
    for r in range(rounds):
        env = {**base_env, "NCGEN_CACHE_DIR": f"{tmp}/python-cache{r}"}
        for label, extra in (("first (empty cache)", {}), ("stored", {}), ("store off", {"NCGEN_MODEL_CACHE": "0"})):
            _, _, text = run([sys.executable, "-c", PYTHON_CHILD, str(urdf)], {**env, **extra}, tmp)
            got = json.loads(text.strip().splitlines()[-1])
            out.setdefault(f"from_urdf().build(), {label}", []).append(tuple(got["load"]))
            out.setdefault(f"  imports before it, {label}", []).append(tuple(got["import"]))
            if label == "stored":
                assert got["stored"] and not got["sympy"], f"the stored load built or imported SymPy: {got}"
        for name, fn, arg in refs:
            code = (f"import sys; sys.path.insert(0, {str(HERE)!r}); import load_time; "
                    f"load_time.{fn}({str(arg)!r})")
            try:
                out.setdefault(name, []).append(run([sys.executable, "-c", code], base_env, tmp)[:2])
            except SystemExit as exc:
                print(f"  {name}: {str(exc)[:200]}")
    return out


def mesh_free_urdf(path: Path) -> str:
    """The URDF's text without ``<visual>`` and ``<collision>`` elements (MuJoCo's importer
    would load their meshes; ncgen does not read them either)."""
    text = path.read_text()
    return re.sub(r"<(visual|collision)\b.*?</\1>", "", text, flags=re.S)


def mujoco_load(urdf_text_file: str) -> None:
    import mujoco
    mujoco.MjModel.from_xml_string(Path(urdf_text_file).read_text())


def pinocchio_load(urdf: str) -> None:
    import pinocchio
    pinocchio.buildModelFromUrdf(urdf)


def reference_runs(urdf: Path, rounds: int, base_env: dict, tmp: str) -> dict[str, list[tuple[float, float]]]:
    """MuJoCo's and Pinocchio's loads of ``urdf``: fresh processes and in-process calls."""
    stripped = Path(tmp) / "model.urdf"
    stripped.write_text(mesh_free_urdf(urdf))
    out: dict[str, list[tuple[float, float]]] = {}
    for name, module, fn, arg in (("MuJoCo from_xml_string", "mujoco", "mujoco_load", stripped),
                                  ("Pinocchio buildModelFromUrdf", "pinocchio", "pinocchio_load", urdf)):
        code = (f"import sys; sys.path.insert(0, {str(HERE)!r}); import load_time; "
                f"load_time.{fn}({str(arg)!r})")
        try:
            __import__(module)
        except ImportError:
            print(f"  {name}: {module} not installed, skipped")
            continue
        out[f"{name} (process)"] = [run([sys.executable, "-c", code], base_env, tmp)[:2] for _ in range(rounds)]
        calls = []
        for _ in range(max(rounds, 5)):
            c0, t0 = time.process_time(), time.perf_counter()
            globals()[fn](str(arg))
            calls.append((time.perf_counter() - t0, time.process_time() - c0))
        out[f"{name} (call)"] = calls
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--t-end", type=float, default=0.1, help="simulated time of each run (s)")
    ap.add_argument("--smoke", action="store_true", help="slider_crank only, 1 round")
    ap.add_argument("--kernels", default="auto", choices=("auto", "tables", "flat"),
                    help="ncgen simulate --kernels (default auto)")
    ap.add_argument("--panda-only", action="store_true", help="the Panda's ncgen runs only (no box_stack, "
                    "no Python or reference loads)")
    ap.add_argument("--empty", action="store_true", help="first runs from a completely empty cache (no "
                    "per-version library compiled before)")
    ap.add_argument("--peer", help="with --panda-only: the root of another ncgen tree (e.g. a `git archive` of main), "
                    "its runs interleaved round by round with this tree's, ratios printed")
    ap.add_argument("--python", help="run ncgen with this interpreter's installed ncgen (no PYTHONPATH; with "
                    "--panda-only)")
    args = ap.parse_args()
    if args.python:
        PYTHON[0] = args.python
    print(machine())
    rounds = 1 if args.smoke else args.rounds
    urdf = panda_urdf()
    models = [EXAMPLES / "slider_crank.toml"] if args.smoke else [urdf] if args.panda_only else \
        [urdf, EXAMPLES / "box_stack.toml"]
    with tempfile.TemporaryDirectory(prefix="ncgen-pyc-") as pyc:
        env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
        env.update(PYTHONPATH=str(ROOT), PYTHONPYCACHEPREFIX=pyc)
        if args.python:
            env.pop("PYTHONPATH")
        run([PYTHON[0], "-c", "import ncgen, ncgen.cli, ncgen.codegen.model_cache"
             + ("" if args.python else ", mujoco, pinocchio")], env, pyc)
        if args.peer:
            run([PYTHON[0], "-c", "import ncgen, ncgen.cli, ncgen.codegen.model_cache"],
                {**env, "PYTHONPATH": args.peer}, pyc)
        per_version = Path(pyc, "per-version")
        if args.empty:
            per_version = None
        elif not args.smoke:        # slider_crank needs none of them
            run([sys.executable, "-c", PER_VERSION_BUILD], {**env, "NCGEN_CACHE_DIR": str(per_version)}, pyc)
        startup = [run([PYTHON[0], "-c", "pass"], env, pyc)[:2] for _ in range(rounds)]
        print(summary("python -c pass (start-up alone)", startup))
        for model in models:
            print(f"\n=== {model.stem}: ncgen simulate {model.name} --t-end {args.t_end:g}"
                  + (" (first runs from a completely empty cache)" if args.empty else ""))
            runs = ncgen_runs(model, args.t_end, rounds, env, per_version, args.kernels, args.peer)
            for tree, results in runs.items():
                if args.peer:
                    print(f"  -- {tree}" + (f" ({args.peer})" if tree == "peer" else ""))
                for label, samples in results.items():
                    print(summary(label, samples))
            if args.peer:
                for label, samples in runs["this tree"].items():
                    peer = runs["peer"][label]
                    for i, what in ((1, "CPU"), (0, "wall")):
                        mine, theirs = [x[i] for x in samples], [x[i] for x in peer]
                        print(f"RATIO {label}, {what}, this tree / peer: min {min(mine) / min(theirs):.2f}, "
                              f"median {statistics.median(mine) / statistics.median(theirs):.2f}")
            results = runs["this tree"]
            first = statistics.median(s[0] for s in results["first run (empty cache)"])
            later = statistics.median(s[0] for s in results["later runs (model stored)"])
            off = statistics.median(s[1] for s in results["later runs, store off"])
            on = statistics.median(s[1] for s in results["later runs (model stored)"])
            print(f"  target: first run <= {TARGET_FIRST:g} s wall ({'met' if first <= TARGET_FIRST else 'NOT met'}), "
                  f"later runs <= {TARGET_LATER:g} s wall ({'met' if later <= TARGET_LATER else 'NOT met'})")
            print(f"RATIO later run, store off / stored, CPU: {off / on:.2f}")
            print(f"  heavy modules a later run imports: {later_imports(model, args.t_end, env) or 'none'}")
            print(f"  load average now: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
        if args.panda_only:
            return
        print(f"\n=== {urdf.stem} from Python: nc.System.from_urdf(path).build() in a fresh process "
              f"(the call; imports apart), interleaved with MuJoCo and Pinocchio loads")
        for label, samples in python_runs(urdf, rounds, env, pyc).items():
            print(summary(label, samples))
        print(f"  load average now: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
        print(f"\n=== {urdf.stem}: MuJoCo and Pinocchio load the same robot")
        refs = reference_runs(urdf, rounds, env, pyc)
        for label, samples in refs.items():
            print(summary(label, samples))
        if "MuJoCo from_xml_string (process)" in refs:
            mj = statistics.median(s[0] for s in refs["MuJoCo from_xml_string (process)"])
            print(f"RATIO ncgen later run / MuJoCo load process, wall: {later / mj:.2f}")
        print(f"  load average at the end: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
