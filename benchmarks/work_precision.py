"""Work–precision: tip error after 2 s versus wall time, ncgen against MuJoCo.

Model: the chain of N bars (benchmarks/common.py), released from rest, 2 s.  Error: the
Euclidean distance (m) between the simulated tip and a reference tip from IDAS (compiled) at
rtol = atol = 1e-12, cross-checked against the stepper at a tiny step and MuJoCo RK4 at a
tiny step (the differences are printed: they bound the reference's own error and the
models' equivalence).

Methods, each at several accuracies:

* ncgen IDAS, compiled DAE and Jacobian: rtol = atol = 1e-4 ... 1e-11;
* ncgen stepper (compiled RATTLE): fixed steps h;
* MuJoCo ``mj_step`` with RK4, and with its default integrator (Euler: semi-implicit), at
  fixed steps (``nstep`` steps in one call).

Times: integration only (compilation and model loading excluded), best of ``--repeat``
runs.  ncgen times are ``traj.info["wall_time"]`` (the C stepper called once for all steps;
IDAS through CasADi, chunked over a 0.1 s output grid).  Ratios: ncgen time / MuJoCo RK4
time at equal tip error, interpolated log-log on each curve (targets: 1e-3 for the
stepper, 1e-6 for IDAS).

    python benchmarks/work_precision.py            N = 1, 5, 20, 50 (several minutes)
    python benchmarks/work_precision.py --smoke    N = 2, coarse (seconds; CI)
    python benchmarks/work_precision.py --sizes 20 --repeat 5
"""
from __future__ import annotations

import argparse
import sys
import warnings

import numpy as np

from common import AXIAL_INERTIA, chain_system, machine, mujoco_run, ncgen_tip, time_at

T_END = 2.0
OUTPUT_DT = 0.1
TARGETS = {"stepper": 1e-3, "idas": 1e-6}

FULL = {
    "sizes": [1, 5, 20, 50],
    "rtols": [1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11],
    "steps": [1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4, 1e-4],
    "mujoco_steps": [1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4, 1e-4, 5e-5],
    "reference_step": 2e-5,
}
SMOKE = {
    "sizes": [2],
    "rtols": [1e-5, 1e-7],
    "steps": [1e-2, 5e-3],
    "mujoco_steps": [1e-2, 5e-3],
    "reference_step": 1e-3,
}


def ncgen_runs(model, reference, config, repeat):
    """Curves ``{method: [(label, error, seconds)]}`` of the ncgen integrators."""
    import ncgen as nc
    from ncgen.errors import SimulationError

    curves = {"idas": [], "stepper": []}
    nc.simulate(model, OUTPUT_DT, OUTPUT_DT, backend="compiled")            # compile outside timings
    nc.simulate(model, OUTPUT_DT, OUTPUT_DT, method="stepper")
    for rtol in config["rtols"]:
        runs = [nc.simulate(model, T_END, OUTPUT_DT, rtol=rtol, atol=rtol, backend="compiled", max_steps=10**6)
                for _ in range(repeat)]
        wall = min(r.info["wall_time"] for r in runs)
        curves["idas"].append((f"rtol {rtol:.0e}", _err(runs[-1].q[-1], reference), wall))
    for h in config["steps"]:
        sub = int(round(OUTPUT_DT / h))
        try:
            runs = [nc.simulate(model, T_END, OUTPUT_DT, method="stepper", substeps=sub) for _ in range(repeat)]
        except SimulationError as e:
            curves["stepper"].append((f"h {h:.0e}", float("nan"), float("nan")))
            print(f"  (stepper, h = {h:.0e}: {str(e).split(':')[0]} at t = {e.time:g} s; left out)")
            continue
        wall = min(r.info["wall_time"] for r in runs)
        curves["stepper"].append((f"h {h:.0e}", _err(runs[-1].q[-1], reference), wall))
    return curves


def mujoco_runs(n, reference, config, repeat):
    curves = {"mujoco RK4": [], "mujoco Euler (default)": []}
    for name, integrator in (("mujoco RK4", "RK4"), ("mujoco Euler (default)", "Euler")):
        for dt in config["mujoco_steps"]:
            runs = [mujoco_run(n, integrator, dt, T_END) for _ in range(repeat)]
            curves[name].append((f"dt {dt:.0e}", _err(runs[-1][1], reference), min(r[0] for r in runs)))
    return curves


def _err(tip, reference) -> float:
    return float(np.linalg.norm(np.asarray(tip).reshape(-1)[-3:] - reference))


def reference_tips(n, model, config) -> tuple[np.ndarray, dict[str, float]]:
    """The reference tip (IDAS, rtol 1e-12) and its distances to the cross-checks."""
    import ncgen as nc

    ref = ncgen_tip(nc.simulate(model, T_END, OUTPUT_DT, rtol=1e-12, atol=1e-12, backend="compiled",
                                max_steps=10**7).q[-1])
    h = config["reference_step"]
    stepper = ncgen_tip(nc.simulate(model, T_END, OUTPUT_DT, method="stepper",
                                    substeps=int(round(OUTPUT_DT / h))).q[-1])
    checks = {f"ncgen stepper, h = {h:.0e}": _err(stepper, ref)}
    for axial in (AXIAL_INERTIA, 1e-4):
        _, tip = mujoco_run(n, "RK4", h, T_END, axial=axial)
        checks[f"MuJoCo RK4, dt = {h:.0e}, axial inertia {axial:.0e}"] = _err(tip, ref)
    return ref, checks


def report(n, curves, checks) -> None:
    print(f"\n=== chain of N = {n} bars: tip error after {T_END:g} s vs wall time ===")
    for what, dist in checks.items():
        print(f"  reference check: |tip({what}) - tip(IDAS rtol 1e-12)| = {dist:.2e} m")
    for method, runs in curves.items():
        print(f"  {method}")
        for label, err, secs in runs:
            print(f"    {label:<12} error {err:9.2e} m   time {secs * 1e3:10.3f} ms")
    rk4 = curves["mujoco RK4"]
    for method, target in TARGETS.items():
        mine = time_at([e for _, e, _ in curves[method]], [t for _, _, t in curves[method]], target)
        theirs = time_at([e for _, e, _ in rk4], [t for _, _, t in rk4], target)
        print(f"  RATIO ncgen {method} / MuJoCo RK4 at tip error {target:.0e}: {mine / theirs:.2f} "
              f"({mine * 1e3:.2f} ms vs {theirs * 1e3:.2f} ms)")
    euler = curves["mujoco Euler (default)"]
    best = min((e for _, e, _ in euler if np.isfinite(e)), default=float("nan"))
    if not best <= TARGETS["stepper"]:
        print(f"  MuJoCo Euler (default) does not reach {TARGETS['stepper']:.0e} at these steps "
              f"(best tip error {best:.2e} m)")
    else:
        theirs = time_at([e for _, e, _ in euler], [t for _, _, t in euler], TARGETS["stepper"])
        mine = time_at([e for _, e, _ in curves["stepper"]], [t for _, _, t in curves["stepper"]],
                       TARGETS["stepper"])
        print(f"  RATIO ncgen stepper / MuJoCo Euler at tip error {TARGETS['stepper']:.0e}: {mine / theirs:.2f} "
              f"({mine * 1e3:.2f} ms vs {theirs * 1e3:.2f} ms)")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--smoke", action="store_true", help="tiny and coarse: runs in seconds (CI)")
    parser.add_argument("--sizes", type=int, nargs="+", help="numbers of bars (default 1 5 20 50)")
    parser.add_argument("--repeat", type=int, default=3, help="runs per point; the fastest counts")
    args = parser.parse_args(argv)
    config = dict(SMOKE if args.smoke else FULL)
    if args.sizes:
        config["sizes"] = args.sizes
    repeat = 1 if args.smoke else args.repeat
    print(machine())
    warnings.simplefilter("ignore")
    for n in config["sizes"]:
        model = chain_system(n).build()
        reference, checks = reference_tips(n, model, config)
        curves = {**ncgen_runs(model, reference, config, repeat), **mujoco_runs(n, reference, config, repeat)}
        report(n, curves, checks)
    return 0


if __name__ == "__main__":
    sys.exit(main())
