"""Step Jacobians with nonsmooth contacts (issue 39, deliverable 2): ``nc.step_function`` on
the heap of benchmarks/contact.py (N point spheres with friction, μ = 0.5, on the floor and
on each other; ``contacts="nonsmooth"``) against ``mujoco.mjd_transitionFD`` (centred and
forward, eps 1e-6) on its MuJoCo twin (``contact.heap_mjcf``: three slide joints per sphere,
elliptic cones).  Each settles for ``--settle`` s from the same release (its own simulator),
then the Jacobians of one step (h = 1 ms) at its settled state are timed, interleaved batches
(ncgen, MuJoCo, ncgen, ...), min and median per call.  Not the same contact model nor the
same scheme (MuJoCo's soft contacts, ncgen's impulses): the same job, one step's
linearisation with its contacts.  ncgen's figure is the whole call: one step of the compiled
contact stepper, the modes, the Newton polish of the active set's equations and the
implicit-function-theorem solve (ncgen/control/contact_step.py, the equations over the active
contacts of ncgen/control/contact_active.py).  The step runs its algebra on one BLAS thread
(ncgen's rule, ncgen/blas_threads.py: ``$NCGEN_BLAS_THREADS``), so that CPU times compare
single-threaded work; the step no longer calls BLAS for its many-column solve (SuperLU's did, and on the shared, loaded
machine its threads waited for the other processes: 0.9 s instead of 40 ms under a load of 12).

    python benchmarks/contact_step_jacobians.py [--heap 20] [--settle 0.5] [--calls 10] [--repeat 5] [--smoke]
"""
from __future__ import annotations

import argparse
import os
import sys
import time

from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import batches, machine, report_ratios  # noqa: E402
from contact import heap, heap_mjcf  # noqa: E402

import ncgen as nc  # noqa: E402

H = 1e-3


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--heap", type=int, default=20)
    ap.add_argument("--settle", type=float, default=0.5, help="seconds the heap settles before the Jacobians")
    ap.add_argument("--calls", type=int, default=10)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--smoke", action="store_true", help="tiny sizes: check that the script runs")
    args = ap.parse_args(argv)
    if args.smoke:
        args.heap, args.settle, args.calls, args.repeat = 4, 0.05, 2, 2
    print(machine())
    import mujoco

    model = heap(args.heap, rotating=False)
    traj = nc.simulate(model, args.settle, args.settle, method="stepper", substeps=round(args.settle / H))
    x = np.concatenate([traj.q[-1], traj.v[-1]])
    st = nc.step_function(model, H)
    s = st.step(x, np.zeros(0))
    print(f"\nncgen heap of {args.heap}: nq {model.nq}, {model.nk} contacts; after {args.settle:g} s: modes "
          f"{dict(Counter(s.modes))}, impact {s.impact}, at a switch {s.at_switch} {s.switches[:3]}, "
          f"|x+ - stepper's| {s.stepper_difference:.2e}")
    mj = mujoco.MjModel.from_xml_string(heap_mjcf(args.heap, H, False))
    d = mujoco.MjData(mj)
    mujoco.mj_step(mj, d, nstep=round(args.settle / H))
    print(f"ncgen evaluates the step's equations with {st.evaluation}")
    print(f"MuJoCo twin: nv {mj.nv}, {d.ncon} contacts active after {args.settle:g} s")
    nxm = 2 * mj.nv + mj.na
    A, B = np.zeros((nxm, nxm)), np.zeros((nxm, mj.nu))
    fns = {"ncgen st.jacobians": lambda: st.jacobians(x, np.zeros(0)),
           "mujoco mjd_transitionFD centred": lambda: mujoco.mjd_transitionFD(mj, d, 1e-6, True, A, B, None, None),
           "mujoco mjd_transitionFD forward": lambda: mujoco.mjd_transitionFD(mj, d, 1e-6, False, A, B, None, None)}
    title = f"heap of {args.heap}, h = {H} s: ncgen A {2 * model.nq}×{2 * model.nq}; MuJoCo A {nxm}×{nxm}"
    t = batches(fns, args.calls, args.repeat)
    report_ratios(f"{title} (wall clock)", t, "ncgen st.jacobians", "target ≤ 0.5 against the centred")
    t = batches(fns, args.calls, args.repeat, clock=time.process_time)
    report_ratios(f"{title} (CPU time of the process: both single-threaded, steadier on a loaded machine)", t,
                  "ncgen st.jacobians", "target ≤ 0.5 against the centred")
    print(f"\nload average at end: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
