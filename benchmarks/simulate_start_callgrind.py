"""Instructions of ``nc.simulate`` from a new start on the Panda (issue 37): the run of
``simulate_fixed_cost.py`` (one 1 ms output step, DOPRI5 at rtol = atol = 1e-3), ``q0`` moved
by 1e-3 rad per joint and call, counted by valgrind's callgrind (deterministic, unaffected by
the load): 20 uncounted calls, then the instrumentation switched on (``callgrind_control -i
on``) for ``--calls`` calls.  Printed per call: all instructions, and those of the start check
(CasADi's virtual machine, ``casadi::SXFunction::eval``, or the tree library's C,
``ncgen_tree_start_state``), and those of the calls through ctypes (libffi's ``ffi_call``: the
C loop and the other C the run calls that way), for this tree and ``--before DIR``, with ``RATIO`` lines.  ``--kernels flat`` (or ``tables``): the
run's kernels (``nc.simulate(..., kernels=...)``), default ``auto``.

    python benchmarks/simulate_start_callgrind.py [--before DIR] [--calls 40] [--kernels auto|tables|flat] [--smoke]
"""
from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import MODEL_IMPORT, callgrind_rows, callgrind_trees, machine  # noqa: E402

CHILD = MODEL_IMPORT + r"""
import os, subprocess
import ncgen as nc

model, start = start_model()
calls = int(sys.argv[1])
starts = [start(k) for k in range(calls + 20)]
run = lambda q, v: nc.simulate(model, 1e-3, 1e-3, q0=q, v0=v, method="joint", rtol=1e-3, atol=1e-3,
                               kernels=sys.argv[2])
for q, v in starts[calls:]:
    run(q, v)
switch = lambda on: subprocess.run(["callgrind_control", "-i", on, str(os.getpid())], check=True, capture_output=True)
switch("on")
for q, v in starts[:calls]:
    run(q, v)
switch("off")
"""
#: The start check's functions: CasADi's virtual machine, the tree library's C.
START_CHECK = ("casadi::SXFunction::eval", "ncgen_tree_start_state")
#: The calls through ctypes: the C loop (the model's library's ``<name>_joint_run``, or the tree
#: library's, which callgrind names by its caller only) and the other C the run calls so.
CTYPES_CALLS = re.compile(r":ffi_call \[")


def counted(tree: Path, calls: int, kernels: str) -> tuple[float, float, float]:
    """``(instructions per call, of them the start check's, the ctypes calls')`` of the child on ``tree``."""
    rows = callgrind_rows(CHILD, [str(calls), kernels], tree)
    total = next(n for n, name in rows if "PROGRAM TOTALS" in name)
    start = sum(n for n, name in rows if any(f":{f}" in name for f in START_CHECK))
    ffi = sum(n for n, name in rows if CTYPES_CALLS.search(name))
    return total / calls, start / calls, ffi / calls


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--before", type=Path, help="another ncgen tree to compare with (its root directory)")
    ap.add_argument("--calls", type=int, default=40)
    ap.add_argument("--kernels", choices=("auto", "tables", "flat"), default="auto",
                    help="the run's kernels (nc.simulate's kernels=): the tree tables' loop or the model's own")
    ap.add_argument("--smoke", action="store_true", help="2 calls (CI)")
    a = ap.parse_args(argv)
    print(machine())
    counting = callgrind_trees(ROOT, a.before, a.calls, a.smoke)
    if counting is None:
        return
    calls, trees = counting
    print(f"\n=== panda: nc.simulate of one 1 ms output step from a new start, {calls} calls counted, "
          f"kernels {a.kernels}")
    got = {}
    for name, tree in trees.items():
        got[name] = counted(tree, calls, a.kernels)
        print(f"  {name}: {got[name][0]:12,.0f} instructions per call, start check {got[name][1]:10,.0f}, "
              f"ctypes calls (the C loop) {got[name][2]:10,.0f}")
    if a.before:
        for k, label in ((0, "all"), (1, "the start check"), (2, "the ctypes calls (the C loop)")):
            print(f"  RATIO this tree / before, instructions per call, {label}: {got['this tree'][k] / got['before'][k]:.3f}")


if __name__ == "__main__":
    main()
