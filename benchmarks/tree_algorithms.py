"""Compiled rigid-body algorithms of URDF robots vs Pinocchio, from Python, in one process.

Robots of example-robot-data as shipped: the Panda (7 arm joints + a finger mimicked by a
second one: 8 independent rates; Pinocchio built with ``mimic=True`` for RNEA, without for ABA
and its derivatives, which refuse mimic joints), the UR5 (6) and Talos (``talos_reduced.urdf``,
free flyer, 38 rates).  One random state per robot, the same in both engines.  Pairs, each a
ratio ncgen / Pinocchio of the time per call:

* forward dynamics: ``k = nc.joint_forward_dynamics_kernel(model)``; ``k(qj, vj, u)`` vs
  ``pinocchio.aba(model, data, q, v, tau)`` (target ≤ 0.7×);
* inverse dynamics: ``k = nc.algorithm_kernel(model, "rnea")``; ``k(qj, vj, aj)`` vs
  ``pinocchio.rnea`` (target ≤ 1.0×);
* ABA derivatives: ``nc.algorithm_kernel(model, "aba_derivatives")`` vs
  ``pinocchio.computeABADerivatives`` (target ≤ 1.0×; Talos only with ``--talos-derivatives``:
  its kernel is a long C function, see the build times printed).

Interleaved: ``--rounds`` rounds, each timing three batches of ``--calls`` calls of each side,
alternating, so that both see the same machine load; the ratio of each round's best batches
is kept and the minimum and median ratios are printed with each side's best time
per call and their ratio ("best/best": on a loaded machine the per-round ratios swing when
one side's batches are all preempted; the best times are the least disturbed).  The machine (CPU model, load average) is printed first: on a shared machine the
medians move with the load, the minima less.

Then the build: seconds from the URDF text to the loaded forward-dynamics kernel
(``System.from_urdf`` → ``build`` → ``joint_forward_dynamics_kernel``) in a fresh process,
with an empty compile cache and again with the cache filled (targets: 7-DOF arm ≤ 1 s empty,
≤ 50 ms cached; Talos ≤ 5 s), split into stages.

    python benchmarks/tree_algorithms.py [--robots panda ur5 talos] [--calls 1000] [--rounds 9]
                                         [--talos-derivatives] [--skip-build] [--smoke]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))

from common import machine  # noqa: E402

ROBOT_ARGS = {"panda": False, "ur5": False, "talos": True}


def batch_time(fn, calls: int, clock=time.perf_counter) -> float:
    t = clock()
    for _ in range(calls):
        fn()
    return (clock() - t) / calls


def interleaved(ours, theirs, calls: int, rounds: int, pairs: int = 3, clock=time.perf_counter) -> dict:
    """Best µs per call of each side and the min and median of the per-round ratios; a round
    alternates ``pairs`` batches of each side and compares their best batches (a preempted
    batch does not make a ratio).  ``clock``: wall time by default; ``time.process_time`` for
    CPU time (on a loaded machine the wall time of a batch is its CPU time times the share of
    the cores it gets)."""
    for f in (ours, theirs):                       # warm up
        batch_time(f, max(1, calls // 10), clock)
    ratios, best_ours, best_theirs = [], float("inf"), float("inf")
    for r in range(rounds):
        a = b = float("inf")
        for k in range(pairs):
            if (r + k) % 2:
                b, a = min(b, batch_time(theirs, calls, clock)), min(a, batch_time(ours, calls, clock))
            else:
                a, b = min(a, batch_time(ours, calls, clock)), min(b, batch_time(theirs, calls, clock))
        ratios.append(a / b)
        best_ours, best_theirs = min(best_ours, a), min(best_theirs, b)
    return {"ncgen_us": best_ours * 1e6, "pinocchio_us": best_theirs * 1e6,
            "ratio_min": min(ratios), "ratio_median": statistics.median(ratios)}


def robot_pairs(name: str, calls: int, rounds: int, derivatives: bool) -> dict:
    import pinocchio as pin

    import ncgen as nc
    from ncgen.assembly.tree_dynamics import MimicMap
    from pinocchio_robots import JointMap, pinocchio_models, urdf_text

    model = nc.System.from_urdf(urdf_text(name), floating_base=ROBOT_ARGS[name]).build()
    pm_mimic, pm = pinocchio_models(name)
    jm, mimic = JointMap(model, pm), MimicMap(model)
    G = mimic.G
    rng = np.random.default_rng(0)
    qj = jm.q_to_ncgen(pin.randomConfiguration(pm, -np.full(pm.nq, 1.5), np.full(pm.nq, 1.5)))
    for i, (lead, k, off) in mimic.position.items():
        qj[i] = k * qj[lead] + off
    qp = jm.q_to_pin(qj, pm.nq)
    n_i = G.shape[1]
    v_i, a_i, tau_i = rng.normal(size=n_i), rng.normal(size=n_i), rng.normal(size=n_i)
    vj, aj = G @ v_i, G @ a_i
    P = jm.P @ G
    vp, ap = P @ v_i, P @ a_i
    d = pm.createData()
    out = {"nv": int(n_i)}

    t = time.perf_counter()
    fd = nc.joint_forward_dynamics_kernel(model)
    out["fd_build_s"] = time.perf_counter() - t
    act = [i for n in model.actuated_joints for i in range(*model.joint_space.slices(rates=True)[n].indices(10**6))]
    cols = [mimic.independent.index(i) for i in act]
    tau_i[[c for c in range(n_i) if c not in cols]] = 0.0                 # a free base is not actuated
    u = tau_i[cols]                                                    # URDF: the actuated rates are the independent ones
    full = jm.P @ (jm.P.T @ P @ tau_i)                                 # Pinocchio's efforts (followers: none)
    out["fd_agreement"] = float(np.max(np.abs(fd(qj, vj, u) - nc.aba(model, qj, vj, tau_i))))
    out["fd"] = interleaved(lambda: fd(qj, vj, u), lambda: pin.aba(pm, d, qp, vp, full), calls, rounds)
    if mimic.relations:
        out["fd_note"] = "Pinocchio's ABA refuses mimic joints: its model without them (one more rate)"
    t = time.perf_counter()
    rnea = nc.algorithm_kernel(model, "rnea")
    out["rnea_build_s"] = time.perf_counter() - t
    if mimic.relations:
        from test_tree_algorithms_pinocchio import _mimic_q, _mimic_rates
        Pm = _mimic_rates(pm_mimic, model, mimic)
        dm, qm = pm_mimic.createData(), _mimic_q(pm_mimic, pm, qp)
        vm, am = Pm @ v_i, Pm @ a_i
        out["rnea_agreement"] = float(np.max(np.abs(Pm @ rnea(qj, vj, aj) - pin.rnea(pm_mimic, dm, qm, vm, am))))
        out["rnea"] = interleaved(lambda: rnea(qj, vj, aj), lambda: pin.rnea(pm_mimic, dm, qm, vm, am), calls, rounds)
    else:
        out["rnea_agreement"] = float(np.max(np.abs(jm.P @ rnea(qj, vj, aj) - pin.rnea(pm, d, qp, vp, ap))))
        out["rnea"] = interleaved(lambda: rnea(qj, vj, aj), lambda: pin.rnea(pm, d, qp, vp, ap), calls, rounds)

    if derivatives:
        t = time.perf_counter()
        abad = nc.algorithm_kernel(model, "aba_derivatives")
        out["aba_derivatives_build_s"] = time.perf_counter() - t
        out["aba_derivatives_instructions"] = abad.direct.function.n_instructions()
        out["aba_derivatives"] = interleaved(lambda: abad(qj, vj, tau_i),
                                             lambda: pin.computeABADerivatives(pm, d, qp, vp, full),
                                             max(1, calls // 4), rounds)
        if mimic.relations:
            out["aba_derivatives_note"] = "Pinocchio's model without the mimic joint (one more rate)"
    return out


BUILD_SCRIPT = r"""
import json, sys, time
t0 = time.perf_counter()
sys.path[:0] = [{root!r}, {tests!r}]
import ncgen as nc
from pinocchio_robots import urdf_text
t1 = time.perf_counter()
text = urdf_text({name!r})
s = nc.System.from_urdf(text, floating_base={floating!r})
t2 = time.perf_counter()
m = s.build()
t3 = time.perf_counter()
k = nc.joint_forward_dynamics_kernel(m)
t4 = time.perf_counter()
print(json.dumps({{"import": t1 - t0, "from_urdf": t2 - t1, "build": t3 - t2, "kernel": t4 - t3, "urdf_to_kernel": t4 - t1}}))
"""


def build_times(name: str) -> dict:
    """Seconds per stage in fresh processes: empty compile cache, then filled."""
    out = {}
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NCGEN_CACHE_DIR": cache, "PYTHONWARNINGS": "ignore"}
        code = BUILD_SCRIPT.format(root=str(HERE.parent), tests=str(HERE.parent / "tests"), name=name,
                                   floating=ROBOT_ARGS[name])
        for label in ("empty_cache", "cached"):
            run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
            out[label] = json.loads(run.stdout.strip().splitlines()[-1])
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robots", nargs="+", default=list(ROBOT_ARGS), choices=list(ROBOT_ARGS))
    ap.add_argument("--calls", type=int, default=1000, help="calls per timed batch (default 1000)")
    ap.add_argument("--rounds", type=int, default=9, help="interleaved rounds (default 9, 3 batch pairs each)")
    ap.add_argument("--talos-derivatives", action="store_true", help="also build and time Talos' ABA derivatives")
    ap.add_argument("--skip-build", action="store_true", help="leave out the URDF-to-kernel build times")
    ap.add_argument("--smoke", action="store_true", help="tiny run (UR5, few calls) to check the script works")
    args = ap.parse_args(argv)
    if args.smoke:
        args.robots, args.calls, args.rounds = ["ur5"], 50, 3
    print(machine())
    print(f"load average: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    for name in args.robots:
        res = robot_pairs(name, args.calls, args.rounds, name != "talos" or args.talos_derivatives)
        print(f"\n=== {name} ({res['nv']} independent rates)")
        for key, label in (("fd", "forward dynamics / pinocchio.aba"), ("rnea", "RNEA / pinocchio.rnea"),
                           ("aba_derivatives", "ABA derivatives / pinocchio.computeABADerivatives")):
            if key in res:
                r = res[key]
                print(f"  {label}: ncgen {r['ncgen_us']:.2f} µs, pinocchio {r['pinocchio_us']:.2f} µs per call"
                      + (f" ({res[key + '_note']})" if key + "_note" in res else ""))
                print(f"RATIO {name} ncgen {label}: min {r['ratio_min']:.2f}  median {r['ratio_median']:.2f}  "
                      f"best/best {r['ncgen_us'] / r['pinocchio_us']:.2f}")
        for key in ("fd_agreement", "rnea_agreement"):       # fd: the kernel vs nc.aba; rnea: vs Pinocchio
            if key in res:
                print(f"  {key}: {res[key]:.2e}")
        for key in ("fd_build_s", "rnea_build_s", "aba_derivatives_build_s"):
            if key in res:
                print(f"  {key}: {res[key]:.2f} s" + (f" ({res['aba_derivatives_instructions']} instructions)"
                                                      if key == "aba_derivatives_build_s" else ""))
        if not args.skip_build and not args.smoke:
            b = build_times(name)
            for label, stages in b.items():
                print(f"  URDF -> loaded kernel, {label:11s}: " + "  ".join(f"{k} {v:.2f} s" for k, v in stages.items()))
    print(f"\nload average: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
