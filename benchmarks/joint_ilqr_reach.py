"""iLQR on the Panda's joint-space step against IPOPT on the same discrete problem (issue 37:
iLQR cost within 0.1 % of the discrete optimum on a Panda reach).

The 7-DOF Panda of example-robot-data (fingers locked: ``nc.robots.locked_urdf``), the step
``nc.JointStep(model, h)`` (semi-implicit Euler on ABA, h = 0.02 s), N = 50 steps (1 s) from
rest at ``Q0`` to ``Q1`` (those of benchmarks/joint_mpc.py), costs :func:`reach_costs`:
``ℓ = h (10⁻² |τ/τ_max|² + 10⁻² |v|²)``, ``ℓ_N = 100 |q − q₁|² + |v|²`` (τ_max the URDF's
efforts, 87 and 12 N·m; inputs unbounded).  ``nc.ilqr`` (Gauss–Newton through the step's exact
Jacobians) from the torques that hold ``Q0`` against gravity, against
``ncgen.control.reference.solve_joint_discrete`` (IPOPT, exact Hessians, the step written with
RNEA instead of ABA) from the same guess.  Printed: both costs and their relative gap, iLQR's
iterations and exact gradient norm, the largest difference of the inputs, CPU times.

    python benchmarks/joint_ilqr_reach.py [--smoke]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import casadi as ca
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine  # noqa: E402
from joint_mpc import Q0, Q1  # noqa: E402

import ncgen as nc  # noqa: E402
from ncgen.control.reference import solve_joint_discrete  # noqa: E402

FINGERS = ["panda_finger_joint1", "panda_finger_joint2"]
EFFORT = np.array([87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0])


def reach_costs(n: int, h: float, q1, effort):
    """``(stage, terminal)`` of a joint-space reach to ``q1`` at rest (module docstring)."""
    def stage(x, u):
        return h * (1e-2 * ca.sumsqr(u / effort) + 1e-2 * ca.sumsqr(x[n:]))

    def terminal(x):
        return 100 * ca.sumsqr(x[:n] - q1) + ca.sumsqr(x[n:])
    return stage, terminal


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--smoke", action="store_true", help="N = 10: check that the script runs")
    args = ap.parse_args(argv)
    print(machine())
    h, N = 0.02, 10 if args.smoke else 50
    model = nc.System.from_urdf(nc.robots.locked_urdf("panda", FINGERS)).build()
    step = nc.JointStep(model, h)
    x0 = np.concatenate([Q0, np.zeros(7)])
    U0 = np.tile(nc.rnea(model, Q0, np.zeros(7), np.zeros(7)), (N, 1))
    costs = reach_costs(7, h, Q1, EFFORT)
    c = time.process_time()
    res = nc.ilqr(step, x0, U0, costs, max_iter=1000, tol=1e-8)
    t_ilqr = time.process_time() - c
    c = time.process_time()
    _, U_ip, J_ip = solve_joint_discrete(step, x0, U0, costs)
    t_ip = time.process_time() - c
    print(f"\n=== Panda reach over {N * h:g} s (N = {N}, h = {h} s), iLQR through JointStep against IPOPT")
    print(f"  iLQR  cost {res.cost:.12g}  iterations {res.iterations}  |dJ/dU|_inf {res.gradient_norm:.1e}  "
          f"converged {res.converged}  CPU {t_ilqr:.2f} s")
    print(f"  IPOPT cost {J_ip:.12g}  (the step written with RNEA)  CPU {t_ip:.2f} s")
    print(f"  GAP (iLQR − IPOPT) / IPOPT = {(res.cost - J_ip) / J_ip:.2e} (target ≤ 1e-3); "
          f"max |U_iLQR − U_IPOPT| = {np.max(np.abs(res.U - U_ip)):.1e} N·m")
    print(f"  final joint error {np.max(np.abs(res.X[-1, :7] - Q1)):.1e} rad, "
          f"speed {np.max(np.abs(res.X[-1, 7:])):.1e} rad/s")
    print(f"\nload average at end: {', '.join(f'{v:.2f}' for v in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
