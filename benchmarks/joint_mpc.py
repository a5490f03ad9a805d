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

BLAS threads: each run is a fresh process, alternately with the BLAS's default threads
(``OPENBLAS_NUM_THREADS``, ``OMP_NUM_THREADS``, ``MKL_NUM_THREADS`` removed from its
environment: what a user has) and with ``OPENBLAS_NUM_THREADS=1``; both are printed, with the
largest difference of their inputs (the controller makes no large BLAS call: the Gauss–Newton
QP is kept in its stages, ``ncgen.control.stagewise_hessian``).

``--smoke``: one run of 0.3 s (30 steps) in each setting, for the tests.

    python benchmarks/joint_mpc.py [--repeat 3] [--qpoases] [--smoke]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import ncgen as nc

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine  # noqa: E402

THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
SETTINGS = {"default BLAS threads": {}, "OPENBLAS_NUM_THREADS=1": {"OPENBLAS_NUM_THREADS": "1"}}
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


def child(solvers: list[str], t_end: float) -> None:
    """One run of each solver in this process; prints the times, inputs and errors as JSON."""
    urdf = nc.robots.locked_urdf("panda", ["panda_finger_joint1", "panda_finger_joint2"])
    model = nc.System.from_urdf(urdf, name="panda_arm").build()
    run(model, "box", 0.05)                                # compiles and loads the kernels
    out = {}
    for s in solvers:
        times, U, tr = run(model, s, t_end)
        qj = np.array(tr.qj)
        err = np.array([np.max(np.abs(q - reference(t)[0])) for q, t in zip(qj, tr.t)])
        hand = hand_error_mm(model, tr)
        out[s] = {"times": times.tolist(), "inputs": U.tolist(), "err": [err.max(), err[-1]],
                  "hand": [hand.max(), hand[-1]]}
    print(json.dumps(out))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--qpoases", action="store_true", help="also time CasADi's qpOASES for the QPs, interleaved")
    ap.add_argument("--smoke", action="store_true", help="one run of 0.3 s in each BLAS setting")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    t_end, repeat = (0.3, 1) if args.smoke else (1.5, args.repeat)
    solvers = ["box"] + (["qpoases"] if args.qpoases else [])
    if args.child:
        return child(solvers, t_end)
    print(machine())
    base = {k: v for k, v in os.environ.items() if k not in THREAD_VARIABLES}
    command = [sys.executable, __file__, "--child", "--repeat", "1"] + (["--qpoases"] if args.qpoases else []) + \
        (["--smoke"] if args.smoke else [])
    best, every, last = {}, {}, {}
    for _ in range(repeat):
        for setting, extra in SETTINGS.items():
            done = subprocess.run(command, env={**base, **extra}, capture_output=True, text=True)
            if done.returncode != 0:
                raise SystemExit(f"the run with {setting} failed:\n{done.stderr[-3000:]}")
            for s, res in json.loads(done.stdout.splitlines()[-1]).items():
                times = np.array(res["times"])
                best[setting, s] = times if (setting, s) not in best else np.minimum(best[setting, s], times)
                every.setdefault((setting, s), []).append(times)
                last[setting, s] = res
    print(f"load average at the end: {os.getloadavg()[0]:.2f}; each setting in its own processes, "
          f"interleaved run by run")
    res = last["default BLAS threads", "box"]
    U = np.array(res["inputs"])
    print(f"Panda reach over {t_end} s, h = {H} s, N = {N}, {len(U)} control steps: "
          f"joint error max {res['err'][0]:.2e} rad, final {res['err'][1]:.2e} rad; "
          f"hand position error max {res['hand'][0]:.2f} mm, final {res['hand'][1]:.2e} mm; "
          f"|tau| max {np.round(np.abs(U).max(0), 1).tolist()} N·m")
    for (setting, s), b in best.items():
        t, e = 1e3 * b, 1e3 * np.array(every[setting, s])
        print(f"  JointMPC qp_solver={s!r}, {setting}: per step (min over {repeat} runs) min {t.min():.2f} ms, "
              f"median {np.median(t):.2f} ms, max {t.max():.2f} ms; every step of every run: median "
              f"{np.median(e):.2f} ms, 95th percentile {np.percentile(e, 95):.2f} ms (target: ≤ 10 ms)")
    one, default = (np.array(last[k, "box"]["inputs"]) for k in ("OPENBLAS_NUM_THREADS=1", "default BLAS threads"))
    ratio = best["default BLAS threads", "box"] / best["OPENBLAS_NUM_THREADS=1", "box"]
    gap = np.max(np.abs(one - default))
    print(f"  default threads / OPENBLAS_NUM_THREADS=1 (box): min {ratio.min():.2f}×, "
          f"median {np.median(ratio):.2f}×; inputs differ by {gap:.1e} N·m")
    if not gap < 1e-9:
        raise SystemExit(f"the inputs with and without OPENBLAS_NUM_THREADS=1 differ by {gap:.1e} N·m")
    if args.qpoases:
        for setting in SETTINGS:
            box, qpoases = (np.array(last[setting, s]["inputs"]) for s in ("box", "qpoases"))
            gap = np.max(np.abs(box - qpoases))
            ratio = best[setting, "qpoases"] / best[setting, "box"]
            print(f"  qpOASES / box, {setting}: min {ratio.min():.1f}×, median {np.median(ratio):.1f}×; "
                  f"inputs differ by {gap:.1e} N·m")
            if not gap < 1e-6:
                raise SystemExit(f"the two QP solvers' inputs differ by {gap:.1e} N·m (expected < 1e-6)")


if __name__ == "__main__":
    main()
