"""The Panda's joint-space tracking MPC (issue 37: ≤ 10 ms a step).

The 7-DOF Panda of example-robot-data (fingers locked: ``nc.robots.locked_urdf``) tracks a
1 s minimum-jerk joint-space reach (0.4–0.8 rad per joint) with ``nc.JointMPC`` (h = 0.01 s,
N = 20: a 0.2 s horizon; one Gauss–Newton SQP iteration a step; torque bounds ±87/±12 N·m
from the URDF) in closed loop against ``nc.simulate(method="joint")`` (Dormand–Prince on ABA,
the input held over each 0.01 s interval) for 1.5 s: 150 control steps.  Each step's CPU time
(``time.process_time``, the call from Python included) is recorded; the loop is run
``--repeat`` times and each step's time is its minimum over the runs; the min and median over
the steps are printed, with the tracking error in joint space (max over the run, and at the
end) and of the hand's position (``panda_hand``'s origin, mm).  ``--qpoases``: the same with
CasADi's qpOASES for the QPs, interleaved run by run (the same inputs to 1e-6: checked).

``OPENBLAS_NUM_THREADS=1`` is set (unless given): the QP's 140 × 140 matrices are small, and
OpenBLAS's threads spinning on a shared 2-core machine cost 20–50× the single-threaded time.

``--smoke``: one run of 0.3 s (30 steps), for the tests.

    python benchmarks/joint_mpc.py [--repeat 3] [--qpoases] [--smoke]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")    # before numpy (module docstring)

import numpy as np  # noqa: E402

import ncgen as nc  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine  # noqa: E402

Q0 = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785])
Q1 = Q0 + np.array([0.8, 0.4, -0.5, 0.6, 0.5, -0.4, 0.6])
T_REACH, H, N = 1.0, 0.01, 20


def reference(t):
    s = min(max(t / T_REACH, 0.0), 1.0)
    return (Q0 + (Q1 - Q0) * (10 * s ** 3 - 15 * s ** 4 + 6 * s ** 5),
            (Q1 - Q0) * (30 * s ** 2 - 60 * s ** 3 + 30 * s ** 4) / T_REACH)


def run(model, qp_solver: str, t_end: float):
    """One closed loop: (per-step CPU times, inputs, trajectory)."""
    mpc = nc.JointMPC(model, H, N, reference, qp_solver=qp_solver)
    times, inputs = [], []

    def u(t, qj, vj):
        c = time.process_time()
        inputs.append(mpc(np.concatenate([qj, vj]), t))
        times.append(time.process_time() - c)
        return inputs[-1]

    q, v = model.from_joint_space(Q0, np.zeros(7))
    tr = nc.simulate(model, t_end, H, u=u, method="joint", q0=q, v0=v)
    return np.array(times), np.array(inputs), tr


def hand_error_mm(model, tr) -> np.ndarray:
    err = []
    for t, qj in zip(tr.t, np.array(tr.qj)):
        p = model.frame_pose("panda_hand", model.from_joint_space(qj)[0])[1]
        p_ref = model.frame_pose("panda_hand", model.from_joint_space(reference(t)[0])[0])[1]
        err.append(1e3 * np.linalg.norm(p - p_ref))
    return np.array(err)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--qpoases", action="store_true", help="also time CasADi's qpOASES for the QPs, interleaved")
    ap.add_argument("--smoke", action="store_true", help="one run of 0.3 s")
    args = ap.parse_args(argv)
    t_end, repeat = (0.3, 1) if args.smoke else (1.5, args.repeat)
    print(machine())
    urdf = nc.robots.locked_urdf("panda", ["panda_finger_joint1", "panda_finger_joint2"])
    model = nc.System.from_urdf(urdf, name="panda_arm").build()
    solvers = ["box"] + (["qpoases"] if args.qpoases else [])
    run(model, "box", 0.05)                                # compiles and loads the kernels
    best = {s: None for s in solvers}
    every = {s: [] for s in solvers}
    inputs = {}
    for _ in range(repeat):
        for s in solvers:
            times, U, tr = run(model, s, t_end)
            best[s] = times if best[s] is None else np.minimum(best[s], times)
            every[s].append(times)
            inputs[s] = U
    print(f"load average at the end: {os.getloadavg()[0]:.2f}; "
          f"OPENBLAS_NUM_THREADS={os.environ['OPENBLAS_NUM_THREADS']}")
    qj = np.array(tr.qj)
    err = np.array([np.max(np.abs(q - reference(t)[0])) for q, t in zip(qj, tr.t)])
    hand = hand_error_mm(model, tr)
    print(f"Panda reach over {t_end} s, h = {H} s, N = {N}, {len(U)} control steps: "
          f"joint error max {err.max():.2e} rad, final {err[-1]:.2e} rad; "
          f"hand position error max {hand.max():.2f} mm, final {hand[-1]:.2e} mm; "
          f"|tau| max {np.round(np.abs(U).max(0), 1).tolist()} N·m")
    for s in solvers:
        t = 1e3 * best[s]
        print(f"  JointMPC qp_solver={s!r}: per step (min over {repeat} runs) min {t.min():.2f} ms, "
              f"median {np.median(t):.2f} ms, max {t.max():.2f} ms; every step of every run: median "
              f"{1e3 * np.median(every[s]):.2f} ms, 95th percentile {1e3 * np.percentile(every[s], 95):.2f} ms "
              f"(target: ≤ 10 ms)")
    if args.qpoases:
        gap = np.max(np.abs(inputs["box"] - inputs["qpoases"]))
        ratio = best["qpoases"] / best["box"]
        print(f"  qpOASES / box: min {ratio.min():.1f}×, median {np.median(ratio):.1f}×; "
              f"inputs differ by {gap:.1e} N·m")
        if not gap < 1e-6:
            raise SystemExit(f"the two QP solvers' inputs differ by {gap:.1e} N·m (expected < 1e-6)")


if __name__ == "__main__":
    main()
