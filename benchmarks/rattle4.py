"""RATTLE (order 2) against its fourth-order composition (``scheme="rattle4"``: Suzuki's five
RATTLE steps per step) and MuJoCo RK4:
wall time to reach a tip error of 1e-3 and 1e-6 m after 2 s on the chain of 20 bars written
with explicit ``nc.Spherical`` joints (the ``joints`` case of benchmarks/work_precision.py).

Each method's step is searched finely (a geometric scan by factors of 2^(1/8) from a
prediction of its order; steps that divide the output interval, or T_END for MuJoCo) for
the largest step whose tip error is within the target (every step scanned is printed); the
error is against IDAS at rtol 1e-12 (cross-checked as in work_precision.py).  Then the three
runs at those steps are timed interleaved (``--repeat`` rounds, rattle, rattle4, MuJoCo in
turn), and the min and median times and their ratios printed with the CPU model and the
load average.  ncgen times are end to end (``nc.simulate``: consistent start, stepping,
derived quantities) with ``check=False, estimate=False`` (no shadow run: MuJoCo has none);
the C loop's stepping time alone is printed beside them.

    python benchmarks/rattle4.py                 both targets (a few minutes)
    python benchmarks/rattle4.py --smoke         N = 2, target 1e-3 only (seconds)
"""
from __future__ import annotations

import argparse
import os
import sys
import warnings

import numpy as np

from common import machine, ncgen_tip
from work_precision import OUTPUT_DT, T_END, Case, _err, reference_tip

SCAN = 2 ** (1 / 8)


def ncgen_error(case: Case, reference, scheme: str, substeps: int) -> float:
    traj, _ = case.simulate(T_END, OUTPUT_DT, method="stepper", substeps=substeps, scheme=scheme, check=False,
                            estimate=False)
    return _err(ncgen_tip(traj.q[-1]), reference)


def mujoco_error(case: Case, reference, dt: float) -> float:
    return _err(case.mujoco("RK4", dt)[1], reference)


def search(error, h0: float, order: int, target: float, quantize) -> tuple[float, float, dict]:
    """``(h, error, scanned)``: the largest step of the scan (quantized by ``quantize``) whose
    error is within ``target``: from the error at ``h0``, the step predicted by ``order``,
    then scanned up while within the target and down while not; ``scanned``: every step
    tried and its error."""
    h = quantize(h0)
    e = error(h)
    if np.isfinite(e) and e > 0:
        h = quantize(h * (target / e) ** (1 / order))
    seen = {}

    def at(h):
        if h not in seen:
            seen[h] = error(h)
        return seen[h]

    while not at(h) <= target:                   # down until within (past the quantization)
        down, factor = quantize(h / SCAN), SCAN
        while down >= h:
            factor *= SCAN
            down = quantize(h / factor)
        h = down
    while True:                                  # up while within
        up = quantize(h * SCAN)
        if up == h or not at(up) <= target:
            return h, seen[h], seen
        h = up


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--smoke", action="store_true", help="N = 2, target 1e-3 only")
    parser.add_argument("--repeat", type=int, default=7, help="interleaved timing rounds")
    args = parser.parse_args(argv)
    n, targets = (2, [1e-3]) if args.smoke else (20, [1e-3, 1e-6])
    print(machine())
    warnings.simplefilter("ignore")
    case = Case("joints", n)
    reference, checks = reference_tip(case, {"reference_step": 1e-3 if args.smoke else 2e-5})
    print(f"\n=== {case.title}: nq = {case.model.nq}, nc = {case.model.nc}; tip error after {T_END:g} s ===")
    for what, dist in checks.items():
        print(f"  reference check: |tip({what}) - tip(IDAS rtol 1e-12)| = {dist:.2e} m")
    case.simulate(OUTPUT_DT, OUTPUT_DT, method="stepper", substeps=10, check=False)        # compile outside

    def substeps(h):
        return OUTPUT_DT / max(1, round(OUTPUT_DT / h))

    def mj_step(h):                              # a whole number of steps to T_END
        return T_END / max(1, round(T_END / h))

    for target in targets:
        found = {
            "rattle": search(lambda h: ncgen_error(case, reference, "rattle", round(OUTPUT_DT / h)), 1e-3, 2,
                             target, substeps),
            "rattle4": search(lambda h: ncgen_error(case, reference, "rattle4", round(OUTPUT_DT / h)), 1e-2, 4,
                              target, substeps),
            "mujoco RK4": search(lambda h: mujoco_error(case, reference, h), 1e-3, 4, target, mj_step),
        }
        times = {name: [] for name in found}
        stepping = {name: [] for name in found if name != "mujoco RK4"}
        for _ in range(args.repeat):
            for name, (h, *_) in found.items():
                if name == "mujoco RK4":
                    times[name].append(case.mujoco("RK4", h)[0])
                    continue
                traj, wall = case.simulate(T_END, OUTPUT_DT, method="stepper", substeps=round(OUTPUT_DT / h),
                                           scheme=name, check=False, estimate=False)
                times[name].append(wall)
                stepping[name].append(traj.info["stepping_time"])
        print(f"\n  target tip error {target:.0e} m (load average {os.getloadavg()[0]:.2f}):")
        for name, (h, e, scanned) in found.items():
            t = np.array(times[name])
            line = (f"    {name:<11} step {h:.3e} s  error {e:.2e} m  min {t.min() * 1e3:9.2f} ms  "
                    f"median {np.median(t) * 1e3:9.2f} ms")
            if name in stepping:
                line += f"  (stepping min {min(stepping[name]) * 1e3:8.2f} ms)"
            print(line)
            print("      scanned: " + ", ".join(f"{k:.3e} s: {v:.1e} m" for k, v in sorted(scanned.items())))
        mj = np.array(times["mujoco RK4"])
        for name in ("rattle", "rattle4"):
            t = np.array(times[name])
            print(f"  RATIO {name} / MuJoCo RK4 at {target:.0e}: min {t.min() / mj.min():.2f}, "
                  f"median {np.median(t) / np.median(mj):.2f}")
        r2, r4 = np.array(times["rattle"]), np.array(times["rattle4"])
        print(f"  RATIO rattle4 / rattle at {target:.0e}: min {r4.min() / r2.min():.2f}, "
              f"median {np.median(r4) / np.median(r2):.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
