"""Issue 41's target: the deploying two-stage tensegrity tower simulated with clustered
cables in at most the time of the same structure with independent cables.

The tower (two 3-prisms on a floor ring of 0.3 m, struts 0.7654 m) deploys in 1 s from
rings of 0.35 m (top at 0.796 m) to rings of 0.3 m (top at 1 m): every realised cable's
rest length is an input, ramped ``l₀A + (l₀B − l₀A)(1 − cos πt)/2`` between the two
designs of least prestress (cables ≥ 10 N, k = 2000 N/m, cable damping 2 N·s/m).
*Independent*: 12 cables (the 3 rings above the floor and the 6 vertical cables);
*clustered*: each vertical cable of the lower stage continues over the middle ring node into
one of the upper stage (3 ``ClusteredCable``s over frictionless pulleys, 6 ring cables).
Each model is simulated for 1.2 s (IDAS, compiled, rtol 1e-8, outputs every 10 ms) and by the
compiled stepper (RATTLE, h = 1 ms); after a warm-up (compile, caches) the two models run
in interleaved rounds, taking turns going first; wall and CPU time, min and median, and the
load average are printed with the ``RATIO clustered / independent`` lines: the ratios of the
minima and of the medians, and the median of the rounds' own ratios (each round's two runs
back to back, so a load that drifts between rounds cancels out of it).  The work, independent of
the load: IDAS's counters (steps, residual evaluations, factorisations) and the stepper's (steps,
Newton iterations, KKT solves).  The motion is checked once per model: IDAS's end state and
the stepper's on IDAS's output grid (``substeps=10``: the same h, the inputs held over the same
10 ms) must agree to ``END_AGREEMENT``, or the run stops (the timed stepper runs hold the inputs
over 1 ms, which moves the end by ≈ 1e-4 m).  ``--smoke``: 2 rounds, 0.2 s.

``--callgrind``: instead of times, instructions (valgrind's callgrind, deterministic, robust to
the load).  Each (integrator, model) pair runs in its own process under callgrind with the
instrumentation off; that process builds its model and simulates once (compiling into, or
loading from, the cache; run the script once without valgrind first so that nothing is
compiled under valgrind), then switches the instrumentation on (``callgrind_control -i on``
on its own pid), simulates once more, and switches it off: only that ``nc.simulate`` call is
counted.  Printed: the instructions (Ir) of each run, split by shared object (the model's
compiled kernels, CasADi, IDAS, libpython, NumPy, the rest), and the ``RATIO clustered /
independent`` of the totals.  ``--t-end`` shortens the simulated time (default 1.2 s).
"""
from __future__ import annotations

import argparse
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

from common import in_turn, machine

import ncgen as nc
from ncgen.analysis.tensegrity_model import rest_length_inputs
from ncgen.analysis.tensegrity_shapes import stacked_prisms, tower_of_radii

K, DAMPING, SUPPORTS = 2000.0, 2.0, [0, 1, 2]
CLUSTERS = [[9 + i, 12 + (i - 1) % 3] for i in range(3)]     # lower vertical i, then the upper one it meets


def deploying(clusters):
    """The actuated model and its input ramp ``u(t)`` (from design A to design B over 1 s)."""
    regular, struts, _ = stacked_prisms(3, stages=2, radius=0.3, height=0.5)
    s = np.linalg.norm(regular[struts[0][1]] - regular[struts[0][0]])
    (A, struts, cables), B = tower_of_radii([0.3, 0.35, 0.35], s), tower_of_radii([0.3, 0.3, 0.3], s)[0]
    l0 = [nc.inverse_statics(X, struts, cables, supports=SUPPORTS, cable_min=10.0, clusters=clusters)
          .rest_lengths(K)[:len(cables)] for X in (A, B)]
    model = nc.tensegrity_system(A, struts, cables, l0[0], K, supports=SUPPORTS, clusters=clusters, actuated=True,
                                 damping=DAMPING, node_mass=0.2).build()
    uA, uB = (rest_length_inputs(model, x, clusters) for x in l0)
    return model, lambda t: uA + 0.5 * (1 - np.cos(np.pi * min(t, 1.0))) * (uB - uA)


RUNS = {"IDAS": (dict(rtol=1e-8, method="idas", backend="compiled"), 0.01), "stepper": (dict(method="stepper"), 0.001)}
#: Largest difference (m, m/s) between a model's end state by IDAS and by the stepper with
#: the same inputs (measured 6e-10 m, 1.2e-8 m/s).
END_AGREEMENT = 1e-6


def _instrument(on: bool) -> None:
    """Switch callgrind's instrumentation of this process on or off."""
    subprocess.run(["callgrind_control", "-i", "on" if on else "off", str(os.getpid())],
                   check=True, capture_output=True)


def counted_run(how: str, name: str, t_end: float) -> None:
    """One ``nc.simulate`` of ``name`` by ``how`` with callgrind's instrumentation on (after a
    first, uncounted run that compiles or loads the model's library)."""
    model, u = deploying(CLUSTERS if name == "clustered" else None)
    opts, dt = RUNS[how]
    nc.simulate(model, t_end, dt, u=u, **opts)
    _instrument(True)
    nc.simulate(model, t_end, dt, u=u, **opts)
    _instrument(False)


NCGEN_CACHE = os.environ.get("NCGEN_CACHE_DIR", "ncgen")


def _group(obj: str) -> str:
    """The part of the program a shared object belongs to."""
    base = os.path.basename(obj)
    for key, label in (("sundials", "IDAS (SUNDIALS)"), ("integrator_idas", "IDAS (SUNDIALS)"),
                       ("casadi", "CasADi"), ("libpython", "libpython"), ("python3", "libpython"),
                       ("numpy", "NumPy"), ("openblas", "BLAS/LAPACK"), ("lapack", "BLAS/LAPACK"),
                       ("libc.so", "libc/libm"), ("libm.so", "libc/libm"), ("ld-linux", "libc/libm")):
        if key in obj.lower():
            return label
    if NCGEN_CACHE in obj or base.startswith(("ncgen", "lib_ncgen")):
        return "model kernels"
    return base


def self_cost_by_object(out: Path) -> Counter:
    """Instructions (self cost) of a callgrind output file, summed by shared object."""
    names, cost, ob, skip = {}, Counter(), "?", False
    text = out.read_text()
    for line in text.splitlines():
        if skip:
            skip = False
            continue
        m = re.match(r"(c?)ob=\((\d+)\)(?: (.*))?$", line)    # compressed names: defined where first met
        if m:
            called, key, obj = m.groups()
            if obj:
                names[key] = obj
            if not called:
                ob = names[key]
        elif line.startswith("calls="):
            skip = True                                      # the next line is the call's inclusive cost
        elif line[:1].isdigit() or line[:1] in "+-*":
            fields = line.split()                            # position, then the cost (omitted when 0)
            cost[_group(ob)] += int(fields[1]) if len(fields) > 1 else 0
    total = int(re.search(r"^totals: (\d+)", text, re.M).group(1))
    if sum(cost.values()) != total:
        raise RuntimeError(f"{out}: the self costs by object sum to {sum(cost.values())}, callgrind's total is {total}")
    return cost


def callgrind(t_end: float, keep: str | None) -> None:
    """Each (integrator, model) pair under callgrind: totals by shared object and the ratios."""
    if shutil.which("valgrind") is None or shutil.which("callgrind_control") is None:
        raise SystemExit("valgrind (callgrind_control) is not on PATH: callgrind counts the instructions")
    print(machine())
    with tempfile.TemporaryDirectory(prefix="tensegrity_callgrind_") as tmp:
        tmp = keep or tmp
        os.makedirs(tmp, exist_ok=True)
        totals = {}
        for how in RUNS:
            for name in ("independent", "clustered"):
                out = Path(tmp) / f"{how}.{name}.out"
                run = subprocess.run(["valgrind", "--tool=callgrind", "--instr-atstart=no",
                                      f"--callgrind-out-file={out}", sys.executable, __file__,
                                      "--counted", how, name, "--t-end", str(t_end)], capture_output=True, text=True)
                if run.returncode:
                    raise SystemExit(f"{how} {name} under callgrind failed:\n{run.stderr[-3000:]}")
                parts = self_cost_by_object(out)
                totals[(how, name)] = sum(parts.values())
                print(f"{how:8s} {name:12s} Ir {totals[(how, name)]:>15,d}   "
                      + ", ".join(f"{k} {v:,d}" for k, v in parts.most_common(6)))
    print(f"=== deploying tower, {t_end} s simulated, instructions of one nc.simulate (callgrind)")
    for how in RUNS:
        print(f"RATIO clustered / independent, {how}: instructions "
              f"{totals[(how, 'clustered')] / totals[(how, 'independent')]:.3f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--smoke", action="store_true")
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--callgrind", action="store_true", help="count instructions with callgrind instead of timing")
    ap.add_argument("--t-end", type=float, default=1.2, help="simulated time, s (callgrind mode)")
    ap.add_argument("--keep", metavar="DIR", help="write callgrind's output files into DIR (callgrind mode)")
    ap.add_argument("--counted", nargs=2, metavar=("HOW", "MODEL"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.counted:
        return counted_run(*args.counted, args.t_end)
    if args.callgrind:
        return callgrind(args.t_end, args.keep)
    rounds, t_end = (2, 0.2) if args.smoke else (args.rounds, 1.2)
    print(machine())
    models = {"independent": deploying(None), "clustered": deploying(CLUSTERS)}
    for name, (model, _) in models.items():
        print(f"{name}: {model.nq} coordinates, {model.nc} constraints, {model.nu} inputs, "
              f"cables {', '.join(model.springs.names)}")
    runs = {how: opts for how, (opts, _) in RUNS.items()}
    dt = {how: step for how, (_, step) in RUNS.items()}
    tops, ends = {}, {}
    for how, opts in runs.items():
        for name, (model, u) in models.items():            # warm-up: compile and load
            traj = nc.simulate(model, t_end, dt[how], u=u, **opts)
            tops[(how, name)] = traj.q[-1, model.coordinate_names.index("n6.r_i.z")]
            ends[(how, name)] = np.concatenate([traj.q[-1], traj.v[-1]])
            stats = traj.info["stats"]                      # the work, independent of the machine's load
            if how == "IDAS":
                print(f"{how} {name}: {stats['nsteps']} steps, {stats['nfevals']} residual evaluations, "
                      f"{stats['nlinsetups']} Jacobian factorisations, {stats['netfails']} error-test failures")
            else:                                           # a KKT solve per Newton iteration and per step
                steps = traj.info["stages"] * stats["nsteps"]
                print(f"{how} {name}: main run {steps} RATTLE steps, {stats['newton_iterations']} Newton "
                      f"iterations, {steps + stats['newton_iterations']} KKT solves (and the "
                      f"{traj.info['estimate']} error estimate's run)")
    for name, (model, u) in models.items():               # the same motion by both integrators
        grid = nc.simulate(model, t_end, dt["IDAS"], u=u, substeps=round(dt["IDAS"] / dt["stepper"]), **runs["stepper"])
        gap = np.max(np.abs(ends[("IDAS", name)] - np.concatenate([grid.q[-1], grid.v[-1]])))
        print(f"{name}: end state by IDAS and by the stepper with IDAS's inputs, largest difference {gap:.1e}")
        if not gap <= END_AGREEMENT:
            raise SystemExit(f"{name}: IDAS and the stepper end {gap:.2e} apart (> {END_AGREEMENT:g}): "
                             f"they do not time the same motion")
    times = {key: ([], []) for key in tops}
    def timed_run(how, name):
        model, u = models[name]
        w, c = time.perf_counter(), time.process_time()
        nc.simulate(model, t_end, dt[how], u=u, **runs[how])
        times[(how, name)][0].append(time.perf_counter() - w)
        times[(how, name)][1].append(time.process_time() - c)

    for r in range(rounds):                                 # the two models take turns going first
        for how in runs:
            in_turn(r, {name: (lambda how=how, name=name: timed_run(how, name)) for name in models})
    print(f"=== deploying tower, {t_end} s simulated, {rounds} interleaved rounds, "
          f"load average {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    for (how, name), (wall, cpu) in times.items():
        print(f"{how:8s} {name:12s} top at {tops[(how, name)]:.4f} m   wall min {min(wall) * 1e3:8.1f} ms "
              f"median {statistics.median(wall) * 1e3:8.1f} ms   CPU min {min(cpu) * 1e3:8.1f} ms "
              f"median {statistics.median(cpu) * 1e3:8.1f} ms")
    for how in runs:
        (wi, ci), (wc, cc) = times[(how, "independent")], times[(how, "clustered")]
        print(f"RATIO clustered / independent, {how}: CPU min {min(cc) / min(ci):.3f}, "
              f"median {statistics.median(cc) / statistics.median(ci):.3f}, "
              f"median of the rounds' ratios {statistics.median(np.divide(cc, ci)):.3f}; "
              f"wall min {min(wc) / min(wi):.3f}, median {statistics.median(wc) / statistics.median(wi):.3f}")


if __name__ == "__main__":
    main()
