"""Work–precision: tip error after 2 s versus wall time, ncgen against MuJoCo, on models as
users write them.

Default (the targets of issue 26): the 20-bar explicit-joint chain at tip errors 1e-3 and
1e-6 m and the spinning 5-bar chain at 1e-3 m.  For each, MuJoCo RK4 and ncgen's fixed-step
stepper (``scheme="rattle"`` and ``"rattle4"``, without error estimate; then ``"rattle4"``
with each of its error estimates, the default shadow run and ``estimate="local"``) are each
run at their own largest step reaching the target: bisection on the number of steps (to 2 s
for MuJoCo, per 0.1 s output interval for ncgen) between a failing and a passing count, down
to neighbours (every count tried is printed).  Then all are timed interleaved in one process
(``--repeat`` rounds), min and median, with the ratios to MuJoCo RK4, the CPU model and the
load average.  ncgen times are end to end (``nc.simulate``: consistent start, stepping,
derived quantities, ``Trajectory``); the first-run costs (ncgen: build, generate and compile
its C from a cold compile cache, then a first short run; MuJoCo: the MJCF compile) are
printed beside them.  ``--curves`` gives the whole curves described below instead.

``--sweep`` (issue 38): error against cost over at least 20 step sizes per method, spaced
geometrically (SWEEP), for the 20-bar explicit-joint chain released from rest from each
configuration of CONFIGS (the staircase and a straight horizontal chain: violent; straight
and tilted; a spiral hanging off the vertical: gentle; MuJoCo's twin starts from the same
configuration, ``chain_quaternions``), the spinning 5-bar chain and the stiff-spring
pendulum.  ncgen runs as users run it: ``nc.simulate(..., method="stepper",
substeps=k)`` with its checks and its default error estimate on (and with
``estimate="local"``); a run its checks reject counts as not reaching any target (its
unchecked error is plotted, marked x).  At each target each method's step is taken on its
envelope: the largest swept step from which every smaller swept step reaches the target,
then bisection on the step count between it and the next larger swept step (MuJoCo RK4's
and ncgen's alike).  The methods are then timed there in interleaved rounds (``--repeat``,
default 5), min and median ratios to MuJoCo RK4 printed with the load average, and the
curves plotted (``--plot``, PNG).

Cases (bars of 1 m and 1 kg, released from rest as the horizontal staircase of
benchmarks/common.py unless said otherwise):

* ``shared``: the chain of N = 20 bars written with shared points (``ends=[prev.end(1), ...]``);
* ``joints``: the same chain written with explicit ``nc.Spherical`` joints (each bar its own
  two ends, as a user coming from MuJoCo or pydy writes it; ``build()``'s coordinate
  sharing compiles it to the shared-point chain's coordinates, ``build(share=False)`` would
  keep twice the coordinates and four times the constraints);
* ``spinning``: the shared-point chain of 5 bars spinning about the vertical at 10 rad/s;
* ``stiff``: a bar pendulum (1 m, 1 kg) with a 0.5 kg point mass on a spring of 1e4 N/m at its
  tip (140 rad/s against 5 rad/s), ncgen only (no MuJoCo twin); the error is that of the
  point mass.

Error: the Euclidean distance (m) between the simulated tip and a reference tip from IDAS
(compiled) at rtol = atol = 1e-12, cross-checked against the error-controlled stepper at
rtol 1e-9 and MuJoCo RK4 at a tiny step (the differences are printed: they bound the
reference's own error and the models' equivalence).

Methods, each at several accuracies:

* ncgen IDAS, compiled DAE and Jacobian: rtol = atol = 1e-4 ... 1e-10;
* ncgen stepper, fixed steps h (``substeps``; unchecked, ``check=False``, so that runs too
  coarse to pass the stepper's own checks still give a point of the curve; the ones the
  checks reject are marked);
* ncgen stepper with error control (``rtol``: Richardson-extrapolated RATTLE, order 4);
* MuJoCo ``mj_step`` with RK4, and with its default integrator (Euler: semi-implicit), at
  fixed steps (``nstep`` steps in one call).

Times: best of ``--repeat`` runs, compilation and model loading excluded.  ncgen times are
**end to end**: the whole ``nc.simulate`` call (consistent start, stepping, derived
quantities, ``Trajectory``), measured around the call; for the stepper the stepping alone
(``info["stepping_time"]``, the C loop) is printed beside it with their ratio.  Ratios:
ncgen end-to-end time / MuJoCo RK4 time at equal tip error, interpolated log-log on each
curve (targets: 1e-3 for the stepper, 1e-6 for IDAS), and the joints/shared ratio: from the
two curves, and measured directly with the two forms run alternately at the same settings
(robust to a machine whose load changes between the cases).  Error-controlled stepper runs
include their shadow run (the global error estimate, about half the work again), as
``nc.simulate`` does by default.

    python benchmarks/work_precision.py                     the targets (about 10 minutes)
    python benchmarks/work_precision.py --smoke             N = 2, 1e-3 only (seconds; CI)
    python benchmarks/work_precision.py --curves            all curves (several minutes)
    python benchmarks/work_precision.py --curves --cases shared joints --repeat 5
    python benchmarks/work_precision.py --sweep --plot wp.png   sweeps and envelope ratios (about an hour loaded)
    python benchmarks/work_precision.py --sweep --cases joints --configs hanging
"""
from __future__ import annotations

import argparse
import os
import sys
import time
import warnings

import numpy as np

from common import AXIAL_INERTIA, chain_quaternions, chain_system, ends, machine, mujoco_run, ncgen_tip, time_at

T_END = 2.0
OUTPUT_DT = 0.1
TARGETS = {"stepper": 1e-3, "stepper rtol": 1e-3, "idas": 1e-6}
LENGTH, MASS = 1.0, 1.0
SPIN = 10.0

FULL = {
    "cases": ["shared", "joints", "spinning", "stiff"],
    "n": {"shared": 20, "joints": 20, "spinning": 5, "stiff": 1},
    "rtols": [1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10],
    "steps": [1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4],
    "stepper_rtols": [1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8],
    "mujoco_steps": [1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4, 1e-4],
    "reference_step": 2e-5,
}
SMOKE = {
    "cases": ["shared", "joints"],
    "n": {"shared": 2, "joints": 2, "spinning": 2, "stiff": 1},
    "rtols": [1e-5, 1e-7],
    "steps": [1e-2, 5e-3],
    "stepper_rtols": [1e-4, 1e-6],
    "mujoco_steps": [1e-2, 5e-3],
    "reference_step": 1e-3,
}


#: Initial configurations of the chains (released from rest): name -> (what, direction of bar
#: k = 1..n as a function of k; bars of LENGTH).  "staircase" is benchmarks/common.py's.
CONFIGS = {
    "staircase": ("as the horizontal staircase", None),
    "horizontal": ("straight and horizontal along x", lambda k: (1.0, 0.0, 0.0)),
    "tilted": ("straight, 30 degrees below the horizontal", lambda k: (np.cos(np.pi / 6), 0.0, -np.sin(np.pi / 6))),
    "hanging": ("as a spiral hanging 25 degrees off the vertical",
                lambda k: (np.sin(np.radians(25)) * np.cos(2 * np.pi * k / 7),
                           np.sin(np.radians(25)) * np.sin(2 * np.pi * k / 7), -np.cos(np.radians(25)))),
}


def chain_points(config: str, n: int) -> list[np.ndarray]:
    """The n + 1 joint positions of a chain of n bars of LENGTH in configuration ``config``."""
    direction = CONFIGS[config][1]
    if direction is None:
        return ends(n, LENGTH)
    pts = [np.zeros(3)]
    for k in range(1, n + 1):
        d = np.asarray(direction(k), float)
        pts.append(pts[-1] + LENGTH * d / np.linalg.norm(d))
    return pts


class Case:
    """A benchmark model: its ncgen form, initial rates, tip and MuJoCo twin (or None)."""

    def __init__(self, kind: str, n: int, config: str = "staircase", model=None):
        import ncgen as nc

        self.kind, self.n, self.config = kind, n, config
        if kind == "stiff":
            s = nc.System("stiff_pendulum", gravity=(0.0, 0.0, -9.81))
            bar = s.add_bar("bar", "rr", mass=1.0, ends=[s.ground.point((0.0, 0.0, 0.0)), (1.0, 0.0, 0.0)])
            mass = s.add_point("mass", mass=0.5, position=(1.25, 0.0, 0.0), velocity=(0.0, 0.0, 0.3))
            s.add_force(nc.Spring(bar, (0.5, 0.0, 0.0), mass, (0.0, 0.0, 0.0), k=1e4, rest_length=0.25))
            self.title = "stiff-spring pendulum (1e4 N/m point mass at the tip of a 1 m bar)"
        else:
            s = chain_system(n, LENGTH, MASS, joints="explicit" if kind == "joints" else "shared")
            how = "explicit nc.Spherical joints" if kind == "joints" else "shared points"
            spin = f", spinning at {SPIN:g} rad/s about the vertical" if kind == "spinning" else ""
            start = "" if config == "staircase" else f", released from rest {CONFIGS[config][0]}"
            self.title = f"chain of N = {n} bars of {LENGTH:g} m, {MASS:g} kg, {how}{spin}{start}"
        if model is None:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                model = s.build()
        self.model = model
        self.points = chain_points(config, n) if kind != "stiff" else None
        self.q0 = None if config == "staircase" else np.concatenate(self.points[1:])
        self.v0 = None
        if kind == "spinning":
            self.v0 = np.cross([0.0, 0.0, SPIN], self.model.q0.reshape(-1, 3)).reshape(-1)

    @property
    def has_mujoco(self) -> bool:
        return self.kind != "stiff"

    def simulate(self, t_end, dt, **kw):
        import ncgen as nc

        start = time.perf_counter()
        traj = nc.simulate(self.model, t_end, dt, q0=self.q0, v0=self.v0, **kw)
        return traj, time.perf_counter() - start

    def mujoco(self, integrator, dt, axial=AXIAL_INERTIA):
        return mujoco_run(self.n, integrator, dt, T_END, axial=axial, length=LENGTH, mass=MASS,
                          spin=SPIN if self.kind == "spinning" else 0.0,
                          qpos=None if self.q0 is None else chain_quaternions(self.points))


def ncgen_runs(case: Case, reference, config, repeat):
    """Curves ``{method: [(label, error, end-to-end s, stepping s or nan, note)]}``."""
    from ncgen.errors import SimulationError

    curves = {"idas": [], "stepper": [], "stepper rtol": []}
    case.simulate(OUTPUT_DT, OUTPUT_DT, backend="compiled")                     # compile outside timings
    case.simulate(OUTPUT_DT, OUTPUT_DT, method="stepper", substeps=100, check=False)

    def best(runs):
        return (min(w for _, w in runs), min(r.info.get("stepping_time", np.nan) for r, _ in runs), runs[-1][0])

    for rtol in config["rtols"]:
        wall, _, traj = best([case.simulate(T_END, OUTPUT_DT, rtol=rtol, atol=rtol, backend="compiled",
                                            max_steps=10**6) for _ in range(repeat)])
        curves["idas"].append((f"rtol {rtol:.0e}", _err(traj.q[-1], reference), wall, np.nan, ""))
    for h in config["steps"]:
        sub = int(round(OUTPUT_DT / h))
        try:
            wall, stepping, traj = best([case.simulate(T_END, OUTPUT_DT, method="stepper", substeps=sub, check=False)
                                         for _ in range(repeat)])
        except SimulationError as e:
            curves["stepper"].append((f"h {h:.0e}", np.nan, np.nan, np.nan, f"failed at t = {e.time:g} s"))
            continue
        try:
            case.simulate(T_END, OUTPUT_DT, method="stepper", substeps=sub)
            note = "passes its checks"
        except SimulationError as e:
            note = "REJECTED by its checks: " + str(e).split("trustworthy: ")[-1].split(" by t")[0][:60]
        curves["stepper"].append((f"h {h:.0e}", _err(traj.q[-1], reference), wall, stepping, note))
    for rtol in config["stepper_rtols"]:
        wall, stepping, traj = best([case.simulate(T_END, OUTPUT_DT, method="stepper", rtol=rtol, check=False)
                                     for _ in range(repeat)])
        estimate = traj.info["error_estimate"]
        size = float(np.max(np.abs(case.model.q0)))
        verdict = ("REJECTED by its checks (estimate above 1 % of the size)" if estimate["q"] > 0.01 * size
                   else "warns: estimate above 100x the tolerance" if estimate["exceeds_tolerance"] else "passes")
        note = f"{traj.info['stats']['nsteps']} steps, global estimate {estimate['q']:.1e}, {verdict}"
        curves["stepper rtol"].append((f"rtol {rtol:.0e}", _err(traj.q[-1], reference), wall, stepping, note))
    return curves


def mujoco_runs(case: Case, reference, config, repeat):
    curves = {"mujoco RK4": [], "mujoco Euler (default)": []}
    for name, integrator in (("mujoco RK4", "RK4"), ("mujoco Euler (default)", "Euler")):
        for dt in config["mujoco_steps"]:
            runs = [case.mujoco(integrator, dt) for _ in range(repeat)]
            curves[name].append((f"dt {dt:.0e}", _err(runs[-1][1], reference), min(r[0] for r in runs), np.nan, ""))
    return curves


def _err(tip, reference) -> float:
    return float(np.linalg.norm(np.asarray(tip).reshape(-1)[-3:] - reference))


def reference_tip(case: Case, config) -> tuple[np.ndarray, dict[str, float]]:
    """The reference tip (IDAS, rtol 1e-12) and its distances to the cross-checks."""
    traj, _ = case.simulate(T_END, OUTPUT_DT, rtol=1e-12, atol=1e-12, backend="compiled", max_steps=10**7)
    ref = ncgen_tip(traj.q[-1])
    stepper, _ = case.simulate(T_END, OUTPUT_DT, method="stepper", rtol=1e-9)
    checks = {"ncgen stepper, rtol 1e-9": _err(ncgen_tip(stepper.q[-1]), ref)}
    if case.has_mujoco:
        h = config["reference_step"]
        for axial in (AXIAL_INERTIA, 1e-4):
            _, tip = case.mujoco("RK4", h, axial=axial)
            checks[f"MuJoCo RK4, dt = {h:.0e}, axial inertia {axial:.0e}"] = _err(tip, ref)
    return ref, checks


def curve_time(runs, target) -> float:
    return time_at([r[1] for r in runs], [r[2] for r in runs], target)


def report(case: Case, curves, checks) -> dict[str, float]:
    """Prints the curves and ratios; returns the stepper's end-to-end times at 1e-3."""
    m = case.model
    print(f"\n=== {case.title}: nq = {m.nq}, nc = {m.nc}; tip error after {T_END:g} s vs wall time ===")
    for what, dist in checks.items():
        print(f"  reference check: |tip({what}) - tip(IDAS rtol 1e-12)| = {dist:.2e} m")
    for method, runs in curves.items():
        print(f"  {method}")
        for label, err, secs, stepping, note in runs:
            line = f"    {label:<12} error {err:9.2e} m   end-to-end {secs * 1e3:10.3f} ms"
            if np.isfinite(stepping):
                line += f"   stepping {stepping * 1e3:9.3f} ms (x{secs / stepping:4.2f})"
            print(line + (f"   {note}" if note else ""))
    times = {}
    if case.has_mujoco:
        rk4 = curves["mujoco RK4"]
        for method, target in TARGETS.items():
            mine, theirs = curve_time(curves[method], target), curve_time(rk4, target)
            times[method] = mine
            if not (np.isfinite(mine) and np.isfinite(theirs)):
                who = " and ".join(n for n, x in ((f"ncgen {method}", mine), ("MuJoCo RK4", theirs))
                                   if not np.isfinite(x))
                print(f"  RATIO ncgen {method} (end to end) / MuJoCo RK4 at tip error {target:.0e}: none "
                      f"({who} not reaching it at the steps or tolerances run, or rejected by the checks)")
                continue
            print(f"  RATIO ncgen {method} (end to end) / MuJoCo RK4 at tip error {target:.0e}: "
                  f"{mine / theirs:.2f} ({mine * 1e3:.2f} ms vs {theirs * 1e3:.2f} ms)")
        euler = curves["mujoco Euler (default)"]
        best = min((e for _, e, *_ in euler if np.isfinite(e)), default=float("nan"))
        if not best <= TARGETS["stepper"]:
            print(f"  MuJoCo Euler (default) does not reach {TARGETS['stepper']:.0e} at these steps "
                  f"(best tip error {best:.2e} m)")
        else:
            theirs = curve_time(euler, TARGETS["stepper"])
            mine = curve_time(curves["stepper"], TARGETS["stepper"])
            print(f"  RATIO ncgen stepper / MuJoCo Euler at tip error {TARGETS['stepper']:.0e}: "
                  f"{mine / theirs:.2f} ({mine * 1e3:.2f} ms vs {theirs * 1e3:.2f} ms)")
    else:
        for method in ("stepper", "stepper rtol"):
            times[method] = curve_time(curves[method], TARGETS[method])
            print(f"  ncgen {method} at tip error {TARGETS[method]:.0e}: {times[method] * 1e3:.2f} ms end to end")
    ratios = [r[2] / r[3] for method in ("stepper", "stepper rtol") for r in curves[method] if np.isfinite(r[3])]
    if ratios:
        print(f"  end-to-end / stepping time of the stepper runs: {min(ratios):.2f} ... {max(ratios):.2f}")
    return times


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--smoke", action="store_true", help="tiny and coarse: runs in seconds (CI)")
    parser.add_argument("--curves", action="store_true",
                        help="the whole curves (IDAS, stepper, MuJoCo RK4 and Euler) instead of the targets")
    parser.add_argument("--cases", nargs="+", choices=FULL["cases"],
                        help="cases to run (default all; the targets have joints and spinning)")
    parser.add_argument("--repeat", type=int, default=None,
                        help="runs per point, the fastest counts (--curves, default 3); interleaved timing "
                             "rounds (targets, default 7)")
    parser.add_argument("--sweep", action="store_true",
                        help="work-precision sweeps over >= 20 step sizes per method, chains from several "
                             "configurations, ratios at the envelope steps, plotted (issue 38)")
    parser.add_argument("--configs", nargs="+", choices=list(CONFIGS),
                        help="--sweep: the 20-bar chain's configurations (default all)")
    parser.add_argument("--plot", help="--sweep: the PNG to write (default work_precision.png)")
    args = parser.parse_args(argv)
    if args.sweep:
        return sweep_main(args)
    if not args.curves:
        return targets_main(args)
    config = dict(SMOKE if args.smoke else FULL)
    if args.cases:
        config["cases"] = args.cases
    repeat = 1 if args.smoke else (args.repeat or 3)
    print(machine())
    warnings.simplefilter("ignore")
    times, cases = {}, {}
    for kind in config["cases"]:
        case = cases[kind] = Case(kind, config["n"][kind])
        reference, checks = reference_tip(case, config)
        curves = ncgen_runs(case, reference, config, repeat)
        if case.has_mujoco:
            curves.update(mujoco_runs(case, reference, config, repeat))
        times[kind] = report(case, curves, checks)
    if "shared" in times and "joints" in times:
        for method in ("stepper", "stepper rtol"):
            a, b = times["joints"].get(method, np.nan), times["shared"].get(method, np.nan)
            print(f"\nRATIO explicit joints / shared points, ncgen {method} at tip error "
                  f"{TARGETS[method]:.0e}: {a / b:.2f} ({a * 1e3:.2f} ms vs {b * 1e3:.2f} ms)")
        paired(cases["joints"], cases["shared"], config, max(repeat, 5))
    return 0


def paired(joints: Case, shared: Case, config, repeat: int) -> None:
    """The joints/shared ratio at equal settings (the stepper at h = 1 ms and with rtol
    1e-3, both end to end), the two forms run alternately ``repeat`` times each, best of each."""
    settings = {"stepper h 1e-03": {"substeps": int(round(OUTPUT_DT / 1e-3)), "check": False},
                "stepper rtol 1e-03": {"rtol": 1e-3, "check": False}}
    for label, kw in settings.items():
        best = {"joints": np.inf, "shared": np.inf}
        for _ in range(repeat):
            for name, case in (("joints", joints), ("shared", shared)):
                best[name] = min(best[name], case.simulate(T_END, OUTPUT_DT, method="stepper", **kw)[1])
        print(f"RATIO explicit joints / shared points, {label}, run alternately (best of {repeat}): "
              f"{best['joints'] / best['shared']:.2f} ({best['joints'] * 1e3:.2f} ms vs {best['shared'] * 1e3:.2f} ms)")


#: The targets of issue 26: (case, N, tip error after T_END (m), ratio ncgen / MuJoCo RK4 to reach).
GOALS = [("joints", 20, 1e-3, 0.5), ("joints", 20, 1e-6, 0.3), ("spinning", 5, 1e-3, 0.5)]
SMOKE_GOALS = [("joints", 2, 1e-3, 0.5)]
#: ncgen's fixed-step settings, each at its own searched step: (label, order, keywords of simulate).
SETTINGS = [("ncgen rattle", 2, {"scheme": "rattle", "estimate": False}),
            ("ncgen rattle4", 4, {"scheme": "rattle4", "estimate": False})]
#: rattle4 at its step with each error estimate: label -> ``estimate``.
ESTIMATES = {"ncgen rattle4 + shadow estimate": "shadow", "ncgen rattle4 + local estimate": "local"}


def smallest_count(error, n0: int, order: int, target: float, n_max: int = 10**6):
    """``(n, error(n), scanned)``: the smallest step count ``n`` (step = span / n) whose
    error is within ``target``: from the error at ``n0`` the count predicted by ``order``,
    a bracket [failing, passing] widened by factors of 1.25, then bisection on the integer
    count down to neighbours (the error is taken monotone near the boundary; a run that
    fails counts as failing); ``scanned``: every count tried and its error.  None if
    ``n_max`` steps do not reach the target."""
    seen = {}

    def passes(n):
        if n not in seen:
            seen[n] = error(n)
        return seen[n] <= target

    n, e0 = n0, error(n0)
    seen[n0] = e0
    if np.isfinite(e0) and e0 > 0:
        n = int(min(n_max, max(1, np.ceil(n0 * (e0 / target) ** (1 / order)))))
    if passes(n):
        hi, lo = n, None
        while lo is None:
            if hi == 1:
                lo = 0
                break
            down = min(hi - 1, int(hi / 1.25))
            if passes(down):
                hi = down
            else:
                lo = down
    else:
        lo, hi = n, None
        while hi is None:
            up = max(lo + 1, int(np.ceil(lo * 1.25)))
            if up > n_max:
                return None
            if passes(up):
                hi = up
            else:
                lo = up
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if passes(mid):
            hi = mid
        else:
            lo = mid
    return hi, seen[hi], seen


def ncgen_error(case: Case, reference, substeps: int, **kw) -> float:
    from ncgen.errors import SimulationError

    try:
        traj, _ = case.simulate(T_END, OUTPUT_DT, method="stepper", substeps=substeps, check=False, **kw)
    except SimulationError:
        return float("inf")
    return _err(ncgen_tip(traj.q[-1]), reference)


def first_runs(kind: str, n: int) -> tuple[Case, dict]:
    """The case built and run once from a cold compile cache (the process's, set by
    :func:`targets_main`), and MuJoCo's model compile and first run: the first-run costs."""
    import mujoco

    from common import chain_mjcf

    start = time.perf_counter()
    case = Case(kind, n)
    built = time.perf_counter() - start
    case.simulate(OUTPUT_DT, OUTPUT_DT, method="stepper", substeps=10, check=False)
    ncgen_first = time.perf_counter() - start
    start = time.perf_counter()
    mujoco.MjModel.from_xml_string(chain_mjcf(n, length=LENGTH, mass=MASS))
    mj_compile = time.perf_counter() - start
    return case, {"ncgen build": built, "ncgen build + C compile + first run (0.1 s)": ncgen_first,
                  "MuJoCo MJCF compile": mj_compile}


def targets_main(args) -> int:
    """Each goal: MuJoCo RK4 and ncgen's settings at their own largest step reaching the tip
    error (:func:`smallest_count`), timed interleaved, min and median ratios."""
    import tempfile

    os.environ["NCGEN_CACHE_DIR"] = tempfile.mkdtemp(prefix="ncgen-wp-")    # first runs compile
    rounds = 1 if args.smoke else (args.repeat or 7)
    print(machine())
    warnings.simplefilter("ignore")
    cases = {}
    goals = SMOKE_GOALS if args.smoke else GOALS
    for kind, n, target, goal in [g for g in goals if not args.cases or g[0] in args.cases]:
        if (kind, n) not in cases:
            case, first = cases[(kind, n)] = first_runs(kind, n)
            reference, checks = reference_tip(case, {"reference_step": 1e-3 if args.smoke else 2e-5})
            cases[(kind, n)] = case, first, reference
            print(f"\n=== {case.title}: nq = {case.model.nq}, nc = {case.model.nc}; tip error after {T_END:g} s ===")
            for what, dist in checks.items():
                print(f"  reference check: |tip({what}) - tip(IDAS rtol 1e-12)| = {dist:.2e} m")
            print("  first run (cold compile cache): " + ", ".join(f"{k} {v:.2f} s" for k, v in first.items()))
        case, first, reference = cases[(kind, n)]
        goal_run(case, first, reference, target, goal, rounds)
    return 0


def goal_run(case: Case, first: dict, reference, target: float, goal: float, rounds: int) -> None:
    found = {"mujoco RK4": smallest_count(lambda k: _err(case.mujoco("RK4", T_END / k)[1], reference),
                                          int(T_END / 2e-3), 4, target)}
    for label, order, kw in SETTINGS:
        found[label] = smallest_count(lambda k, kw=kw: ncgen_error(case, reference, k, **kw), 20, order, target)
    runs = {label: (lambda k, kw=kw: case.simulate(T_END, OUTPUT_DT, method="stepper", substeps=k, check=False,
                                                   **kw)) for label, _, kw in SETTINGS}
    for label, how in ESTIMATES.items():
        found[label] = found["ncgen rattle4"]
        runs[label] = (lambda k, how=how: case.simulate(T_END, OUTPUT_DT, method="stepper", substeps=k,
                                                        scheme="rattle4", check=False, estimate=how))
    times = {name: [] for name, f in found.items() if f is not None}
    estimates = {label: [] for label in ESTIMATES}
    load = os.getloadavg()[0]
    for _ in range(rounds):
        for name in times:
            k = found[name][0]
            if name == "mujoco RK4":
                times[name].append(case.mujoco("RK4", T_END / k)[0])
                continue
            traj, wall = runs[name](k)
            times[name].append(wall)
            if name in estimates:
                estimates[name].append(traj.info["error_estimate"]["q"])
    load = max(load, os.getloadavg()[0])
    print(f"\n  target tip error {target:.0e} m; {rounds} interleaved rounds; load average "
          f"{load:.2f} (1 min, max of start and end)")
    for name, f in found.items():
        if f is None:
            print(f"    {name:<32} does not reach the target")
            continue
        k, e, scanned = f
        h = T_END / k if name == "mujoco RK4" else OUTPUT_DT / k
        t = np.array(times[name])
        print(f"    {name:<32} step {h:.4e} s  error {e:.2e} m  min {t.min() * 1e3:9.2f} ms  "
              f"median {np.median(t) * 1e3:9.2f} ms")
        if name not in ESTIMATES:
            what = "steps to 2 s" if name == "mujoco RK4" else f"substeps per {OUTPUT_DT:g} s"
            print(f"      bisection on the {what}: " + ", ".join(f"{c}: {v:.2e}" for c, v in sorted(scanned.items())))
    if "mujoco RK4" not in times:
        return
    mj = np.array(times["mujoco RK4"])
    for name in times:
        if name != "mujoco RK4":
            t = np.array(times[name])
            print(f"  RATIO {name} / MuJoCo RK4 at {target:.0e}: min {t.min() / mj.min():.2f}, "
                  f"median {np.median(t) / np.median(mj):.2f}")
    best = min((n for n in times if n.startswith("ncgen") and n not in ESTIMATES), key=lambda n: np.median(times[n]),
               default=None)
    if best is not None:
        ratio = np.median(times[best]) / np.median(mj)
        print(f"  BEST ncgen setting at {target:.0e}: {best}, median ratio {ratio:.2f} (goal <= {goal:g}: "
              f"{'met' if ratio <= goal else 'NOT met'})")
    with_estimate = [n for n in ESTIMATES if n in times]
    if with_estimate:
        best_e = min(with_estimate, key=lambda n: np.median(times[n]))
        ratio = np.median(times[best_e]) / np.median(mj)
        print(f"  BEST ncgen with an error estimate at {target:.0e}: {best_e}, median ratio {ratio:.2f} "
              f"(goal <= {goal:g}: {'met' if ratio <= goal else 'NOT met'})")
    plain = np.median(times["ncgen rattle4"]) if "ncgen rattle4" in times else np.nan
    for label in ESTIMATES:
        if label in times:
            est, tip = np.median(estimates[label]), found[label][1]
            print(f"  {label[len('ncgen rattle4 + '):]}: {est:.2e} (largest component of q) against a true tip "
                  f"error of {tip:.2e} m (ratio {est / tip:.2f}); overhead "
                  f"{np.median(times[label]) / plain - 1:+.0%} (median end to end)")
    once = first["ncgen build + C compile + first run (0.1 s)"]
    if best is not None:
        print(f"  with the first-run cost (one run from a cold cache): ncgen {once + np.median(times[best]):.2f} s, "
              f"MuJoCo {first['MuJoCo MJCF compile'] + np.median(mj):.2f} s")


#: The sweep (``--sweep``, issue 38): cases (kind, N, configuration), step counts per method
#: (substeps per OUTPUT_DT for ncgen, steps to T_END for MuJoCo: ``points`` counts spaced
#: geometrically between the two), tip-error targets, and the goals (kind, target) -> ratio.
SWEEP = {
    "cases": [("joints", 20, c) for c in CONFIGS] + [("spinning", 5, "staircase"), ("stiff", 1, "staircase")],
    "points": 24, "ncgen_counts": (2, 400), "mujoco_counts": (100, 40000), "rtol_counts": (24, 240),
    "targets": (1e-3, 1e-6), "reference_step": 2e-5,
}
SWEEP_SMOKE = {
    "cases": [("joints", 2, "staircase"), ("joints", 2, "hanging"), ("stiff", 1, "staircase")],
    "points": 20, "ncgen_counts": (1, 60), "mujoco_counts": (20, 6000), "rtol_counts": (24, 200),
    "targets": (1e-3,), "reference_step": 1e-3,
}
SWEEP_GOALS = {("joints", 1e-3): 0.5, ("joints", 1e-6): 0.3, ("spinning", 1e-3): 0.5}
#: ncgen as users run it (``method="stepper"``, checks on): label -> keywords of simulate.
USER_SETTINGS = {"ncgen default (rattle4, shadow estimate)": {},
                 "ncgen rattle4, local estimate": {"estimate": "local"},
                 "ncgen rattle4 rtol (error control)": {"scheme": "rattle4", "rtol": None}}
#: Tolerances of the error-controlled runs: count k -> rtol = atol = 10^(-k / RTOL_STEPS) (a
#: larger count is finer, as for steps).
RTOL_STEPS = 24


def rtol_of(count: int) -> float:
    return 10.0 ** (-count / RTOL_STEPS)


def step_counts(lo: int, hi: int, points: int) -> list[int]:
    """At least ``points`` distinct integers from lo to hi, spaced about geometrically."""
    m = points
    while True:
        counts = sorted({int(round(c)) for c in np.geomspace(lo, hi, m)})
        if len(counts) >= min(points, hi - lo + 1):
            return counts
        m += 1


def user_run(case: Case, reference, count: int, kw: dict) -> dict:
    """One ncgen run as users run it (checks on) at ``count`` substeps per OUTPUT_DT (with
    ``rtol`` in ``kw``: at rtol = atol = :func:`rtol_of` (count)): error, wall time, the run's
    error estimate, and whether its checks rejected it (then the error is that of the same
    run unchecked; an error-controlled run's warnings count as passing, as for users)."""
    from ncgen.errors import SimulationError

    kw = dict(kw, rtol=rtol_of(count), atol=rtol_of(count)) if "rtol" in kw else dict(kw, substeps=count)
    try:
        traj, wall = case.simulate(T_END, OUTPUT_DT, method="stepper", **kw)
        rejected = ""
    except SimulationError as e:
        rejected = str(e).split(". ")[0][-90:]
        try:
            traj, wall = case.simulate(T_END, OUTPUT_DT, method="stepper", check=False, **kw)
        except SimulationError:
            return {"error": float("inf"), "time": float("nan"), "estimate": float("nan"), "rejected": rejected}
    return {"error": _err(ncgen_tip(traj.q[-1]), reference), "time": wall,
            "estimate": traj.info["error_estimate"]["q"], "rejected": rejected}


def mujoco_point(case: Case, reference, count: int) -> dict:
    wall, tip = case.mujoco("RK4", T_END / count)
    return {"error": _err(tip, reference), "time": wall, "estimate": float("nan"), "rejected": ""}


def envelope(points: dict[int, dict], target: float):
    """The smallest swept count from which every finer one (larger count) reaches ``target``
    (a run its checks reject does not), and the largest count below it; (None, None) if the
    finest misses it."""
    counts = sorted(points)
    ok = [points[c]["error"] <= target and not points[c]["rejected"] for c in counts]
    if not ok[-1]:
        return None, None
    i = len(counts) - 1
    while i > 0 and ok[i - 1]:
        i -= 1
    return counts[i], (counts[i - 1] if i > 0 else None)


def fine_search(run, points: dict[int, dict], target: float):
    """Bisection on the count between the envelope's count and the failing count below it
    (runs added to ``points``): the smallest count found reaching the target."""
    hi, lo = envelope(points, target)
    if hi is None:
        return None
    lo = lo or 0
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if mid not in points:
            points[mid] = run(mid)
        if points[mid]["error"] <= target and not points[mid]["rejected"]:
            hi = mid
        else:
            lo = mid
    return hi


def sweep_case(kind: str, n: int, config: str, models: dict, settings: dict, rounds: int) -> dict:
    """One case: the swept curves, each method's envelope count per target (finely searched),
    interleaved timing there, ratios to MuJoCo RK4; returns the curves for the plot."""
    case = Case(kind, n, config, model=models.get((kind, n)))
    models[(kind, n)] = case.model
    case.simulate(OUTPUT_DT, OUTPUT_DT, method="stepper", substeps=10, check=False)      # compiled outside timings
    reference, checks = reference_tip(case, settings)
    print(f"\n=== {case.title}: nq = {case.model.nq}, nc = {case.model.nc}; tip error after {T_END:g} s ===")
    for what, dist in checks.items():
        print(f"  reference check: |tip({what}) - tip(IDAS rtol 1e-12)| = {dist:.2e} m")
    runs = {label: (lambda k, kw=kw: user_run(case, reference, k, kw)) for label, kw in USER_SETTINGS.items()}
    if case.has_mujoco:
        runs["mujoco RK4"] = lambda k: mujoco_point(case, reference, k)
    curves = {}
    for label, run in runs.items():
        key = "mujoco_counts" if label == "mujoco RK4" else "rtol_counts" if "rtol" in label else "ncgen_counts"
        lo, hi = settings[key]
        curves[label] = {k: run(k) for k in step_counts(lo, hi, settings["points"])}
        what = "steps to 2 s" if label == "mujoco RK4" else (f"k, rtol = atol = 10^(-k/{RTOL_STEPS})" if "rtol"
                                                            in label else f"substeps per {OUTPUT_DT:g} s")
        print(f"  {label}: {len(curves[label])} step sizes ({what}: error m / wall ms"
              + (", R: rejected by its checks" if label != "mujoco RK4" else "") + ")")
        print("    " + ", ".join(f"{k}: {p['error']:.1e}/{p['time'] * 1e3:.1f}{' R' if p['rejected'] else ''}"
                               for k, p in sorted(curves[label].items())))
    spread = max(checks.values())
    for target in settings["targets"]:
        if spread > target / 10:
            print(f"  target {target:.0e} m: skipped, the reference checks differ by {spread:.1e} m (more than a "
                  f"tenth of it)")
            continue
        found = {label: fine_search(run, curves[label], target) for label, run in runs.items()}
        times = {label: [] for label, k in found.items() if k is not None}
        load = os.getloadavg()[0]
        for _ in range(rounds):
            for label in times:
                times[label].append(runs[label](found[label])["time"])
        load = max(load, os.getloadavg()[0])
        print(f"  target {target:.0e} m: each method at its envelope step (every smaller swept step reaches the "
              f"target, then bisection), {rounds} interleaved rounds, load average {load:.2f}")
        for label, k in found.items():
            if k is None:
                print(f"    {label:<42} does not reach the target at the steps swept")
                continue
            p, t = curves[label][k], np.array(times[label])
            h = f"rtol {rtol_of(k):.2e}" if "rtol" in label else \
                f"step {T_END / k if label == 'mujoco RK4' else OUTPUT_DT / k:.3e} s"
            est = f"  estimate {p['estimate']:.1e} ({p['estimate'] / p['error']:.2g}x the error)" \
                if np.isfinite(p["estimate"]) else ""
            print(f"    {label:<42} {h}  error {p['error']:.2e} m  min {t.min() * 1e3:8.2f} ms  "
                  f"median {np.median(t) * 1e3:8.2f} ms{est}")
        if "mujoco RK4" not in times:
            continue
        mj = np.array(times["mujoco RK4"])
        for label in times:
            if label == "mujoco RK4":
                continue
            t = np.array(times[label])
            lo_, med = t.min() / mj.min(), np.median(t) / np.median(mj)
            goal = SWEEP_GOALS.get((kind, target))
            verdict = "" if goal is None else f"  (goal <= {goal:g}: {'met' if max(lo_, med) <= goal else 'NOT met'})"
            print(f"  RATIO {label} / MuJoCo RK4 at {target:.0e}, {config}: min {lo_:.2f}, median {med:.2f}{verdict}")
    return {"title": case.title, "curves": curves, "targets": settings["targets"]}


def plot(results: list[dict], path: str) -> None:
    """Error against wall time, one panel per case (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = min(3, len(results))
    rows = (len(results) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(5.5 * cols, 4.2 * rows), squeeze=False)
    for ax, res in zip(axes.flat, results):
        for label, points in res["curves"].items():
            pts = [(p["time"], p["error"], bool(p["rejected"])) for _, p in sorted(points.items())
                   if np.isfinite(p["error"]) and p["error"] > 0 and np.isfinite(p["time"])]    # by step
            line, = ax.loglog([p[0] for p in pts], [p[1] for p in pts], ".-", label=label, lw=1)
            bad = [p for p in pts if p[2]]
            if bad:
                ax.loglog([p[0] for p in bad], [p[1] for p in bad], "x", color=line.get_color(), ms=7)
        for target in res["targets"]:
            ax.axhline(target, color="grey", lw=0.6, ls="--")
        ax.set_title(res["title"].replace(", explicit nc.Spherical joints", "").replace(" of 1 m, 1 kg", ""),
                     fontsize=7)
        ax.set_xlabel("wall time (s)")
        ax.set_ylabel("tip error after 2 s (m)")
        ax.legend(fontsize=6)
    for ax in list(axes.flat)[len(results):]:
        ax.axis("off")
    fig.suptitle("work-precision (x: rejected by the stepper's checks, error of the unchecked run)", fontsize=9)
    fig.tight_layout()
    tmp = path + ".tmp.png"
    fig.savefig(tmp, dpi=110)
    os.replace(tmp, path)
    plt.close(fig)


def sweep_main(args) -> int:
    """``--sweep``: the cases of SWEEP, plotted to ``--plot``."""
    import tempfile

    settings = SWEEP_SMOKE if args.smoke else SWEEP
    rounds = 1 if args.smoke else (args.repeat or 5)
    path = args.plot or (os.path.join(tempfile.mkdtemp(prefix="ncgen-wp-"), "work_precision.png") if args.smoke
                         else "work_precision.png")
    print(machine())
    warnings.simplefilter("ignore")
    models, results = {}, []
    for kind, n, config in settings["cases"]:
        if args.cases and kind not in args.cases:
            continue
        if args.configs and kind == "joints" and config not in args.configs:
            continue
        results.append(sweep_case(kind, n, config, models, settings, rounds))
    if results:
        plot(results, path)
        print(f"\nplot written to {path}")
    print(f"load average at the end: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
