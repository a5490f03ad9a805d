"""Coordinate sharing on a user-written chain: stepper cost of the explicit-joint 20-bar chain
against the same chain written with shared points (issue 14, part 1).

The chain as a newcomer writes it: N bars of 1 m and 1 kg, each with its own two ends, joined
by ``nc.Spherical`` joints, the first end of the first bar on a ground point, released
horizontally under gravity.  Three builds: the explicit joints compiled with coordinate
sharing (the default ``build()``), the same with ``build(share=False)`` (every joint as 3
equations), and the chain written with shared points (``ends=[prev.end(1), ...]``).  For each:
nq, nc, and the stepper's wall time per step (``traj.info["wall_time"]``, the compiled C
loop) for T seconds at step h, best of ``--repeat`` runs, plus the tip of the last bar at T
to show that the three are one mechanism.

    python benchmarks/sharing_chain.py [--n 20] [--t-end 2] [--h 1e-3] [--repeat 3] [--smoke]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))
import ncgen as nc  # noqa: E402
from common import machine  # noqa: E402


def chain(n: int, explicit: bool) -> nc.System:
    s = nc.System(f"chain{n}_{'explicit' if explicit else 'shared'}")
    prev = s.add_bar("b0", mass=1.0, ends=[s.ground.point((0, 0, 0)), (1.0, 0, 0)])
    for k in range(1, n):
        if explicit:
            bar = s.add_bar(f"b{k}", mass=1.0, ends=[(float(k), 0, 0), (k + 1.0, 0, 0)])
            s.add_joint(nc.Spherical(prev, bar, at=(float(k), 0, 0)))
        else:
            bar = s.add_bar(f"b{k}", mass=1.0, ends=[prev.end(1), (k + 1.0, 0, 0)])
        prev = bar
    prev.add_marker("tip", (0.5, 0, 0))
    return s


def measure(model, t_end: float, h: float, repeat: int):
    nc.simulate(model, h, h, method="stepper")                      # compile (cached) outside the timing
    best, traj = np.inf, None
    for _ in range(repeat):
        traj = nc.simulate(model, t_end, h, method="stepper")
        best = min(best, traj.info["wall_time"])
    steps = round(t_end / h)
    tip = np.asarray(model.markers(traj.q[-1])[0]).reshape(-1)
    return best / steps * 1e6, tip


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=20)
    ap.add_argument("--t-end", type=float, default=2.0)
    ap.add_argument("--h", type=float, default=1e-3)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--smoke", action="store_true", help="3 bars, 10 steps, one run (CI)")
    a = ap.parse_args(argv)
    if a.smoke:
        a.n, a.t_end, a.h, a.repeat = 3, 0.01, 1e-3, 1
    print(machine())
    print(f"=== chain of N = {a.n} bars, {a.t_end:g} s at h = {a.h:g} s (stepper)")
    cases = {"explicit joints, build()": chain(a.n, True).build(),
             "explicit joints, build(share=False)": chain(a.n, True).build(share=False),
             "shared points (ends=[prev.end(1), ...])": chain(a.n, False).build()}
    rows = {}
    for name, model in cases.items():
        us, tip = measure(model, a.t_end, a.h, a.repeat)
        rows[name] = us
        print(f"{name:<42} nq {model.nq:4d}  nc {model.nc:4d}  {us:8.2f} us/step  tip at T {np.round(tip, 9)}")
    ref = rows["shared points (ends=[prev.end(1), ...])"]
    print(f"RATIO explicit (shared by build) / shared-point chain: {rows['explicit joints, build()'] / ref:.2f}")
    print(f"RATIO explicit (share=False)     / shared-point chain: {rows['explicit joints, build(share=False)'] / ref:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
