"""Cost of the reactions of joints eliminated by coordinate sharing (issue 14 part 1 / issue 15
part 2): `nc.joint_reactions` on the default (shared) build against the same call on
`build(share=False)`, where every joint has multipliers of its own.

The explicit-joint chain of N bars (1 m, 1 kg, `nc.Spherical` joints, released horizontally):
IDAS for T seconds on the shared build; at every output state (multipliers from
`nc.forward_dynamics`) the reactions of all joints
on the shared model (through its unshared form, `ncgen/assembly/unshared.py`) and on the
share=False model at the same state (mapped q_u = S q + c, v_u = S v, its own forward
dynamics).  Printed: the one-off cost of the unshared form (built on first use), the time
per state of each call, their ratio, and the largest difference between the two reactions.

    python benchmarks/reactions_shared.py [--n 20] [--t-end 1] [--dt 0.01] [--smoke]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))
import ncgen as nc  # noqa: E402
from common import machine  # noqa: E402


def chain(n: int) -> nc.System:
    s = nc.System(f"chain{n}_explicit")
    prev = s.add_bar("b0", mass=1.0, ends=[s.ground.point((0, 0, 0)), (1.0, 0, 0)])
    for k in range(1, n):
        bar = s.add_bar(f"b{k}", mass=1.0, ends=[(float(k), 0, 0), (k + 1.0, 0, 0)])
        s.add_joint(nc.Spherical(prev, bar, at=(float(k), 0, 0), name=f"ball{k}"))
        prev = bar
    return s


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=20)
    ap.add_argument("--t-end", type=float, default=1.0)
    ap.add_argument("--dt", type=float, default=0.01)
    ap.add_argument("--smoke", action="store_true", help="3 bars, 5 states (CI)")
    args = ap.parse_args(argv)
    n, t_end, dt = (3, 0.05, 0.01) if args.smoke else (args.n, args.t_end, args.dt)
    print(machine())
    shared, explicit = chain(n).build(), chain(n).build(share=False)
    print(f"=== explicit-joint chain of N = {n} bars: shared nq {shared.nq}, nc {shared.nc}; "
          f"share=False nq {explicit.nq}, nc {explicit.nc}")
    traj = nc.simulate(shared, t_end, dt, rtol=1e-10, atol=1e-10)
    states = [(t, q, v, nc.forward_dynamics(shared, q, v, t=t)[1]) for t, q, v in zip(traj.t, traj.q, traj.v)]
    t0 = time.perf_counter()
    S, c = shared.unshared.coordinate_map(shared)
    first = time.perf_counter() - t0
    print(f"unshared form built on first use: {first * 1e3:.0f} ms (one-off per model)")
    mapped = []
    for t, q, v, _ in states:
        qu, vu = S @ q + c, S @ v
        mapped.append((t, qu, vu, nc.forward_dynamics(explicit, qu, vu, t=t)[1]))
    t0 = time.perf_counter()
    rs = [nc.joint_reactions(shared, q, lam, v=v, t=t) for t, q, v, lam in states]
    t_shared = (time.perf_counter() - t0) / len(states)
    t0 = time.perf_counter()
    ru = [nc.joint_reactions(explicit, q, lam, v=v, t=t) for t, q, v, lam in mapped]
    t_explicit = (time.perf_counter() - t0) / len(states)
    diff = max(np.abs(a[k].force - b[k].force).max() for a, b in zip(rs, ru) for k in a)
    scale = max(np.abs(b[k].force).max() for b in ru for k in b)
    print(f"joint_reactions per state, all {len(rs[0])} joints: shared build {t_shared * 1e3:.2f} ms, "
          f"share=False {t_explicit * 1e3:.2f} ms ({len(states)} states)")
    print(f"largest force difference shared vs share=False: {diff:.2e} N (forces up to {scale:.3g} N)")
    print(f"RATIO shared / share=False, joint_reactions per state: {t_shared / t_explicit:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
