"""Instructions per call of the tree algorithms' doors on the UR10 (issue 59: the model's data
kept on the model, the doors found through ``model._data.doors``, must cost no more than the
module dictionary keyed by the model did): ``nc.aba``, ``nc.rnea``, ``nc.inverse_dynamics``
and ``nc.joint_forward_dynamics`` at one state, counted by valgrind's callgrind (deterministic,
unaffected by the load): 200 uncounted calls, then the instrumentation switched on
(``callgrind_control -i on``) for ``--calls`` calls.  Printed per door: instructions per call
for this tree and ``--before DIR``, with ``RATIO`` lines (target ≤ 1.02).  ``--all``: issue
37's other doors too (fresh outputs): ``nc.crba``, ``nc.rnea_derivatives``,
``nc.aba_derivatives``, ``nc.JointStep`` called and ``.jacobians`` on the UR10,
``nc.forward_dynamics(..., backend="compiled")`` and ``nc.step_function`` called and
``.jacobians`` on examples/chain.toml (the load-free complement of door_overhead.py).

    python benchmarks/door_callgrind.py [--before DIR] [--calls 2000] [--all] [--smoke]
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import callgrind_rows, callgrind_trees, machine  # noqa: E402

CHILD = r"""
import os, subprocess, sys, importlib.metadata as md
import numpy as np
import ncgen as nc

rel = "ur_description/urdf/ur10_robot.urdf"
model = nc.System.from_urdf(next(f.locate() for f in md.files("example-robot-data") if str(f).endswith(rel))).build()
n = model.joint_space.nv
q, v, w = np.linspace(-0.8, 0.9, n), np.linspace(0.3, -0.2, n), np.linspace(-1.0, 1.0, n)
door, calls = sys.argv[1], int(sys.argv[2])
calls_of = {"aba": lambda: nc.aba(model, q, v, w), "rnea": lambda: nc.rnea(model, q, v, w),
            "inverse_dynamics": lambda: nc.inverse_dynamics(model, q, v, w),
            "joint_forward_dynamics": lambda: nc.joint_forward_dynamics(model, q, v, w),
            "crba": lambda: nc.crba(model, q), "rnea_derivatives": lambda: nc.rnea_derivatives(model, q, v, w),
            "aba_derivatives": lambda: nc.aba_derivatives(model, q, v, w)}
if door.startswith("JointStep"):
    st, x = nc.JointStep(model, 0.01), np.concatenate([q, v])
    calls_of |= {"JointStep call": lambda: st(x, w), "JointStep.jacobians": lambda: st.jacobians(x, w)}
elif door not in calls_of:
    chain = nc.System.from_toml(os.path.join("examples", "chain.toml")).build()
    sf, qc, vc = nc.step_function(chain, 0.01), chain.q0, chain.v0
    xc, none = np.concatenate([qc, vc]), np.zeros(0)
    calls_of |= {"forward_dynamics compiled": lambda: nc.forward_dynamics(chain, qc, vc, backend="compiled"),
                 "StepFunction call": lambda: sf(xc, none), "StepFunction.jacobians": lambda: sf.jacobians(xc, none)}
call = calls_of[door]
for _ in range(200):
    call()
switch = lambda on: subprocess.run(["callgrind_control", "-i", on, str(os.getpid())], check=True, capture_output=True)
switch("on")
for _ in range(calls):
    call()
switch("off")
"""
DOORS = ("aba", "rnea", "inverse_dynamics", "joint_forward_dynamics")
#: ``--all``: issue 37's other doors.
MORE = ("crba", "rnea_derivatives", "aba_derivatives", "JointStep call", "JointStep.jacobians",
        "forward_dynamics compiled", "StepFunction call", "StepFunction.jacobians")


def counted(tree: Path, door: str, calls: int) -> float:
    """Instructions per call of ``door`` on ``tree`` (the child's counted loop)."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    subprocess.run([sys.executable, "-c", CHILD, door, "2"], env=env, cwd=tree, check=True, capture_output=True)
    rows = callgrind_rows(CHILD, [door, str(calls)], tree)
    return next(n for n, name in rows if "PROGRAM TOTALS" in name) / calls


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--before", type=Path, help="another ncgen tree to compare with (its root directory)")
    ap.add_argument("--calls", type=int, default=2000)
    ap.add_argument("--all", action="store_true", help="issue 37's other doors too (module docstring)")
    ap.add_argument("--smoke", action="store_true", help="2 calls (CI)")
    a = ap.parse_args(argv)
    print(machine())
    counting = callgrind_trees(ROOT, a.before, a.calls, a.smoke)
    if counting is None:
        return
    calls, trees = counting
    print(f"\n=== ur10: one call of each door at one state, {calls} calls counted"
          + (" (forward_dynamics and StepFunction: examples/chain.toml)" if a.all else ""))
    for door in DOORS + (MORE if a.all else ()):
        got = {name: counted(tree, door, calls) for name, tree in trees.items()}
        print(f"  {door}: " + ", ".join(f"{name} {c:,.0f}" for name, c in got.items()) + " instructions per call")
        if a.before:
            print(f"  RATIO this tree / before, {door}: {got['this tree'] / got['before']:.4f}")


if __name__ == "__main__":
    main()
