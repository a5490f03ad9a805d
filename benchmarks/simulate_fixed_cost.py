"""``nc.simulate``'s fixed cost on a tree (issue 37): a Panda run of one output step of
1 ms (``t_end = dt = 1e-3`` s, DOPRI5 at rtol = atol = 1e-3: two steps of the C loop), its
CPU and wall time per call, and the C loop's share (the same grid integrated by the loop
alone); the fixed cost is the difference.  With ``--before DIR`` (a checkout of another ncgen,
e.g. ``git archive`` of an older commit) the same run of both trees is timed in child
processes started in alternation, ``--rounds`` each (interleaved: the load falls on both),
each child timing ``--calls`` calls after a warm-up; min and median of the rounds and of their
ratios (this tree / before) are printed.  The same calls from a new start each (``q0`` moved by
1e-3 rad per joint and call) time the start check that a repeated start skips, and the start check
alone (``JointSpace._checked_state`` at new starts) is timed too.  ``--urdf stock``:
the Panda as shipped (its second finger mimics the first) in place of the fall's.  ``--model talos``,
``--model solo12``: Talos reduced or Solo12 of example-robot-data as shipped, on a free-flyer base
(floating-base trees: free, revolute and fixed joints); ``--model balls``: a chain of 4 bodies on
spherical joints (``common.start_model``).  ``--kernels flat`` (or ``tables``): the run's kernels
(``nc.simulate(..., kernels=...)``), default ``auto``.

    python benchmarks/simulate_fixed_cost.py [--before DIR] [--rounds 7] [--calls 200] [--urdf fall|stock]
                                             [--model panda|talos|solo12|balls] [--kernels auto|tables|flat]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import MODEL_IMPORT, START_MODELS, machine, terminal_sigint  # noqa: E402

terminal_sigint()

CHILD = MODEL_IMPORT + r"""
import json, time
import numpy as np
import ncgen as nc

model, start = start_model(sys.argv[2])
js = model.joint_space
q0, v0 = start(0)
kernels = sys.argv[3]
run = lambda: nc.simulate(model, 1e-3, 1e-3, q0=q0, v0=v0, method="joint", rtol=1e-3, atol=1e-3, kernels=kernels)
for _ in range(20):
    tr = run()
calls = int(sys.argv[1])
c, w = time.process_time(), time.perf_counter()
for _ in range(calls):
    run()
out = {"cpu": (time.process_time() - c) / calls, "wall": (time.perf_counter() - w) / calls,
       "kernels": tr.info["kernels"], "stats": tr.info["stats"], "file": nc.__file__}
starts = [start(k) for k in range(calls)]
c = time.process_time()
for q, v in starts:                     # a new start each call: its start check is not kept from an earlier run
    nc.simulate(model, 1e-3, 1e-3, q0=q, v0=v, method="joint", rtol=1e-3, atol=1e-3, kernels=kernels)
out["cpu_new_start"] = (time.process_time() - c) / calls
try:                                    # the start check alone at new starts (its C where the tree library has it)
    from ncgen.runtime.tree_library import loaded_tree_start
    ts = loaded_tree_start(model)
    fresh = []
    for k in range(calls, 3 * calls):   # (a start from_joint_space cannot make is skipped: Talos' round-off, a few)
        try:
            fresh.append(start(k))
        except nc.ModelError:
            continue
        if len(fresh) == calls:
            break
    c = time.process_time()
    for q, v in fresh:
        js._checked_state(model, q, v, model.t0, model.p0, ts)
    out["check_cpu"] = (time.process_time() - c) / len(fresh)
    out["check_c"] = ts is not None
except Exception as e:                  # noqa: BLE001 - an older tree: no separate start check
    out["check_error"] = repr(e)
try:                                    # the C loop alone on the same grid (this tree's interface)
    from ncgen.codegen.joint_loop import run_options
    from ncgen.runtime.joint_integrator import JointIntegrator
    from ncgen.runtime.joint_simulation import joint_loop
    integ = JointIntegrator(model, nc.SimulationOptions.resolve(None, method="joint", rtol=1e-3, atol=1e-3))
    loop = joint_loop(model, kernels=tr.info["kernels"])
    t = np.array([0.0, 1e-3]); X = np.zeros((2, js.nq + js.nv)); W = np.zeros((1, model.nu))
    X[0] = np.concatenate(model.to_joint_space(q0, v0))
    opts = [run_options(integ.loop_options, False) for _ in range(calls)]
    c = time.process_time()
    for o in opts:
        loop.run(o, t, X, W, None, model.p0, np.zeros(5))
    out["loop_cpu"] = (time.process_time() - c) / calls
except Exception as e:                  # noqa: BLE001 - an older tree: no separate loop time
    out["loop_error"] = repr(e)
print(json.dumps(out))
"""


def child(tree: Path, calls: int, which: str, kernels: str) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    out = subprocess.run([sys.executable, "-c", CHILD, str(calls), which, kernels], env=env, cwd=tree, capture_output=True, text=True,
                         check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def line(label: str, xs: list[float]) -> str:
    return f"  {label:<44} min {min(xs) * 1e3:8.3f} ms, median {statistics.median(xs) * 1e3:8.3f} ms"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--before", type=Path, help="another ncgen tree to compare with (its root directory)")
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--calls", type=int, default=200)
    ap.add_argument("--urdf", choices=("fall", "stock"), default="fall",
                    help="the Panda of joint_simulation.py's fall (its <mimic> and <dynamics> tags dropped, as for "
                         "MuJoCo; the default), or as shipped (its second finger mimics the first)")
    ap.add_argument("--model", choices=("panda", "talos", "solo12", "balls"), default="panda",
                    help="the Panda (--urdf), Talos reduced or Solo12 as shipped on a free-flyer base "
                         "(example-robot-data), or a chain of 4 bodies on spherical joints")
    ap.add_argument("--kernels", choices=("auto", "tables", "flat"), default="auto",
                    help="the run's kernels (nc.simulate's kernels=): the tree tables' loop or the model's own")
    ap.add_argument("--smoke", action="store_true", help="2 rounds of 20 calls (CI)")
    a = ap.parse_args(argv)
    which = a.urdf if a.model == "panda" else a.model
    if a.smoke:
        a.rounds, a.calls = 2, 20
    print(machine())
    print(f"load average at start: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    trees = {"this tree": ROOT} | ({"before": a.before.resolve()} if a.before else {})
    results = {k: [] for k in trees}
    for _ in range(a.rounds):
        for name, tree in trees.items():
            results[name].append(child(tree, a.calls, which, a.kernels))
    print(f"\n=== {START_MODELS[which]}: nc.simulate of one 1 ms output step (DOPRI5, rtol = atol = 1e-3), {a.calls} calls "
          f"per round, {a.rounds} rounds")
    for name, rs in results.items():
        print(f"  {name}: {rs[0]['file']} (kernels {rs[0]['kernels']}, {rs[0]['stats']})")
        print(line(f"{name}: simulate, CPU per call", [r["cpu"] for r in rs]))
        print(line(f"{name}: simulate, wall per call", [r["wall"] for r in rs]))
        print(line(f"{name}: simulate from a new start, CPU per call", [r["cpu_new_start"] for r in rs]))
        if "check_cpu" in rs[0]:
            print(line(f"{name}: start check alone ({'C' if rs[0]['check_c'] else 'CasADi'}), a new start, CPU",
                       [r["check_cpu"] for r in rs]))
        if "loop_cpu" in rs[0]:
            print(line(f"{name}: the C loop alone, CPU per call", [r["loop_cpu"] for r in rs]))
            print(line(f"{name}: FIXED COST (simulate - loop), CPU", [r["cpu"] - r["loop_cpu"] for r in rs]))
            print(line(f"{name}: FIXED COST, a new start each call, CPU", [r["cpu_new_start"] - r["loop_cpu"]
                                                                          for r in rs]))
    if a.before:
        for clock, label in (("cpu", "CPU"), ("wall", "WALL"), ("cpu_new_start", "CPU, a new start each call"),
                             ("check_cpu", "CPU of the start check alone, a new start")):
            if clock not in results["before"][0] or clock not in results["this tree"][0]:
                continue
            ratios = [x[clock] / y[clock] for x, y in zip(results["this tree"], results["before"])]
            print(f"  RATIO this tree / before, simulate {label}: min {min(ratios):.3f}, "
                  f"median {statistics.median(ratios):.3f}")
    print(f"load average at the end: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
