"""The Python doors of the compiled tree algorithms vs Pinocchio's, per call, in one process
(issue 37: a call from Python should cost what calling Pinocchio costs).

Robots of example-robot-data as shipped: the Panda (7 arm joints and a finger mimicked by a
second one: 8 independent rates), the UR10 (6) and the xArm7 (7), fixed base, and Talos (reduced,
a free-flying base: 38 rates).  One random state
per robot, the same in both engines.  Pairs, each a ratio ncgen / Pinocchio of the time per
call, through the public functions with their argument checks:

* ``nc.inverse_dynamics(model, qj, vj, aj)`` and ``nc.rnea(model, qj, vj, aj)`` vs
  ``pinocchio.rnea`` (with the mimic joint for the Panda; target ≤ 1.5×);
* ``nc.aba(model, qj, vj, tau)`` and ``nc.joint_forward_dynamics(model, qj, vj, u)`` vs
  ``pinocchio.aba`` (Pinocchio's model without the mimic joint for the Panda: its ABA refuses
  them; target ≤ 1.0×);
* ``nc.rnea(model, QJ, VJ, AJ)`` with one row per state (1000 rows, one C loop) vs a Python
  loop of ``pinocchio.rnea`` over them (target ≤ 0.5×).

Interleaved rounds (``interleaved`` of ``tree_algorithms.py``) in CPU time (``time.process_time``:
under a load of L processes on 2 cores a batch's wall time is about L/2 times its CPU time, which
made single calls look 10-20 µs in earlier runs): the min and median of the per-round ratios of
the best batches, and each side's best µs per call.  The CPU model and the
load average are printed before and after: on a shared machine the medians move with the load.
Agreement with Pinocchio (max |difference|) is printed for each pair that has the same rates.

``--alone``: each door's best time per call against its kernel alone in a C loop (the door's
overhead; ``benchmarks/kernel_alone.py``).  ``--kernels``: ``nc.rnea`` on the tree tables against
the flat kernel, one state and 1000 (what ``kernels="auto"`` rests on).  ``--cpp``: ncgen's RNEA, ABA and CRBA kernels alone
against Pinocchio's C++ ones alone, a C++ program written from Pinocchio's model (its results
compared with Pinocchio's Python ones first).

    python benchmarks/call_overhead.py [--robots panda ur10 xarm7 talos] [--calls 2000] [--rounds 9]
                                       [--alone] [--kernels] [--cpp] [--smoke]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))

from common import machine, terminal_sigint  # noqa: E402
from tree_algorithms import batch_time, interleaved as interleaved_wall  # noqa: E402

terminal_sigint()


def interleaved(ours, theirs, calls: int, rounds: int) -> dict:
    """:func:`tree_algorithms.interleaved` in CPU time (``time.process_time``)."""
    return interleaved_wall(ours, theirs, calls, rounds, clock=time.process_time)

ROBOTS = {"panda": "panda_description/urdf/panda.urdf", "ur10": "ur_description/urdf/ur10_robot.urdf",
          "xarm7": "xarm_description/urdf/xarm7.urdf", "talos": "talos_data/robots/talos_reduced.urdf"}
#: Robots with a free-flying base (both engines: a free joint at the root).
FLOATING = {"talos"}


def robot_pairs(name: str, calls: int, rounds: int, alone: bool = False, cpp: bool = False,
                kernels: bool = False) -> dict:
    import pinocchio as pin

    import ncgen as nc
    from ncgen.runtime.tree_algorithm_kernels import algorithm_kernels, kernels_reason
    from ncgen.assembly.tree_dynamics import MimicMap
    from pinocchio_robots import JointMap, random_configuration, robot_file
    from test_tree_algorithms_pinocchio import _mimic_q, _mimic_rates

    text = robot_file(ROBOTS[name]).read_text()
    model = nc.System.from_urdf(text, floating_base=name in FLOATING).build()
    root = (pin.JointModelFreeFlyer(),) if name in FLOATING else ()
    pm_mimic, pm = pin.buildModelFromXML(text, *root, mimic=True), pin.buildModelFromXML(text, *root)
    jm, mimic = JointMap(model, pm), MimicMap(model)
    G = mimic.G
    rng = np.random.default_rng(0)
    qj = jm.q_to_ncgen(random_configuration(pm, rng))
    for i, (lead, k, off) in mimic.position.items():
        qj[i] = k * qj[lead] + off
    qp = jm.q_to_pin(qj, pm.nq)
    n_i = G.shape[1]
    v_i, a_i, tau_i = rng.normal(size=n_i), rng.normal(size=n_i), rng.normal(size=n_i)
    vj, aj = G @ v_i, G @ a_i
    P = jm.P @ G                                     # Pinocchio's rates (no mimic) from the independent ones
    d, out = pm.createData(), {"nv": int(n_i)}
    joints = "all" if name in FLOATING else "actuated"      # a free base has no actuator

    if mimic.relations:
        Pm = _mimic_rates(pm_mimic, model, mimic)
        dm, qm, vm, am = pm_mimic.createData(), _mimic_q(pm_mimic, pm, qp), Pm @ v_i, Pm @ a_i
        pin_rnea = lambda: pin.rnea(pm_mimic, dm, qm, vm, am)               # noqa: E731
        tau = nc.inverse_dynamics(model, qj, vj, aj, joints=joints)
        out["rnea_agreement"] = float(np.max(np.abs(Pm @ tau - pin_rnea())))
    else:
        vp, ap = P @ v_i, P @ a_i
        pin_rnea = lambda: pin.rnea(pm, d, qp, vp, ap)                        # noqa: E731
        tau = nc.inverse_dynamics(model, qj, vj, aj, joints=joints)
        out["rnea_agreement"] = float(np.max(np.abs(P @ tau - pin_rnea())))
    out["inverse_dynamics"] = interleaved(lambda: nc.inverse_dynamics(model, qj, vj, aj, joints=joints), pin_rnea,
                                          calls, rounds)
    out["rnea"] = interleaved(lambda: nc.rnea(model, qj, vj, aj), pin_rnea, calls, rounds)
    QJ, VJ, AJ = (np.tile(x, (BATCH, 1)) for x in (qj, vj, aj))
    out["rnea_batch"] = interleaved(lambda: nc.rnea(model, QJ, VJ, AJ), lambda: [pin_rnea() for _ in range(BATCH)],
                                    max(1, calls // BATCH), rounds)

    act = [model.joint_space.slices(rates=True)[n].start for n in model.actuated_joints]
    u = tau_i[[mimic.independent.index(i) for i in act]]
    full = jm.P @ (jm.P.T @ P @ tau_i)              # the efforts on Pinocchio's rates (a follower: none)
    vp = P @ v_i
    pin_aba = lambda: pin.aba(pm, d, qp, vp, full)                            # noqa: E731
    if not mimic.relations:
        out["aba_agreement"] = float(np.max(np.abs(P @ nc.aba(model, qj, vj, tau_i) - pin_aba())))
        tau_u = np.zeros(n_i)                       # the inputs' efforts only (a free base has none)
        tau_u[[mimic.independent.index(i) for i in act]] = u
        out["fd_agreement"] = float(np.max(np.abs(P @ nc.joint_forward_dynamics(model, qj, vj, u)
                                                  - pin.aba(pm, d, qp, vp, P @ tau_u))))
    else:
        out["aba_note"] = out["fd_note"] = "Pinocchio's ABA refuses mimic joints: its model without them"
    out["aba"] = interleaved(lambda: nc.aba(model, qj, vj, tau_i), pin_aba, calls, rounds)
    out["fd"] = interleaved(lambda: nc.joint_forward_dynamics(model, qj, vj, u), pin_aba, calls, rounds)
    out["chosen"] = {name: (algorithm_kernels(model, name), kernels_reason(model, name))
                     for name in ("rnea", "crba", "aba")}
    if kernels:
        out["kernels"] = {
            "rnea": interleaved(lambda: nc.rnea(model, qj, vj, aj, kernels="tables"),
                                lambda: nc.rnea(model, qj, vj, aj, kernels="flat"), calls, rounds),
            "rnea_batch": interleaved(lambda: nc.rnea(model, QJ, VJ, AJ, kernels="tables"),
                                      lambda: nc.rnea(model, QJ, VJ, AJ, kernels="flat"), max(1, calls // BATCH),
                                      rounds)}
    if alone:
        out["alone"] = doors_alone(model, (qj, vj, aj, tau_i, u), calls, rounds, out)
    if cpp:
        out["cpp"] = cpp_alone(model, pm, qp, vp, P @ a_i, full, (qj, vj, aj, tau_i), calls, rounds)
    return out


def doors_alone(model, state, calls: int, rounds: int, pairs: dict) -> dict:
    """Each door's best µs per call from Python and its kernel's time alone in a C loop
    (:func:`kernel_alone.kernel_ns`): the door's overhead is their difference."""
    import ncgen as nc
    from ncgen.runtime.tree_algorithm_kernels import door

    from kernel_alone import kernel_ns

    qj, vj, aj, tau, u = state
    joints = "all" if model.joint_space.slices().get("root") is not None else "actuated"
    doors = {"rnea": lambda: nc.rnea(model, qj, vj, aj),
             "inverse_dynamics": lambda: nc.inverse_dynamics(model, qj, vj, aj, joints=joints),
             "crba": lambda: nc.crba(model, qj), "aba": lambda: nc.aba(model, qj, vj, tau),
             "fd": lambda: nc.joint_forward_dynamics(model, qj, vj, u)}
    kernels = {"rnea": door(model, "rnea").kernel, "inverse_dynamics": door(model, "rnea").kernel,
               "crba": door(model, "crba").kernel, "aba": door(model, "aba").kernel,
               "fd": model.data.tree_kernel}
    res = {}
    for key, f in doors.items():
        f()
        k = kernels[key]
        direct = getattr(k, "direct", None) or k._shim
        ns_min, ns_median = kernel_ns(direct, calls, rounds)
        us = pairs[key]["ncgen_us"] if key in pairs else \
            min(batch_time(f, calls, time.process_time) for _ in range(rounds)) * 1e6
        res[key] = {"door_us": us, "kernel_us": ns_min / 1e3, "kernel_median_us": ns_median / 1e3,
                    "overhead_us": us - ns_min / 1e3}
    return res


def cpp_alone(model, pm, qp, vp, ap, tau_p, state, calls: int, rounds: int) -> dict:
    """ncgen's kernels alone in C against Pinocchio's C++ ``rnea``, ``aba``, ``crba`` alone
    (:func:`kernel_alone.pinocchio_cpp_ns`, the model without mimic joints), and the largest
    difference of the C++ program's ``rnea``/``aba`` from Pinocchio's Python results (the same model)."""
    import pinocchio as pin

    import ncgen as nc
    from ncgen.runtime.tree_algorithm_kernels import door

    from kernel_alone import kernel_ns, pinocchio_cpp_ns

    qj, vj, aj, tau = state
    ref = pinocchio_cpp_ns(pm, qp, vp, ap, tau_p, calls=max(calls, 2000) * 5, rounds=rounds)
    d = pm.createData()
    res = {"same_model": max(float(np.max(np.abs(ref["rnea_result"] - pin.rnea(pm, d, qp, vp, ap)))),
                             float(np.max(np.abs(ref["aba_result"] - pin.aba(pm, d, qp, vp, tau_p)))))}
    nc.rnea(model, qj, vj, aj), nc.aba(model, qj, vj, tau), nc.crba(model, qj)
    for name in ("rnea", "aba", "crba"):
        k = door(model, name).kernel
        ours = kernel_ns(getattr(k, "direct", None) or k._shim, max(calls, 2000) * 5, rounds)
        res[name] = {"ncgen_ns": ours, "pinocchio_ns": ref[name], "ratio_min": ours[0] / ref[name][0],
                     "ratio_median": ours[1] / ref[name][1]}
    return res


#: States of the batched call (``nc.rnea`` with one row per state against a Python loop of ``pinocchio.rnea``).
BATCH = 1000
LABELS = (("inverse_dynamics", "nc.inverse_dynamics / pinocchio.rnea"), ("rnea", "nc.rnea / pinocchio.rnea"),
          ("rnea_batch", f"nc.rnea over {BATCH} states in one call / a Python loop of pinocchio.rnea"),
          ("aba", "nc.aba / pinocchio.aba"), ("fd", "nc.joint_forward_dynamics / pinocchio.aba"))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robots", nargs="+", default=list(ROBOTS), choices=list(ROBOTS))
    ap.add_argument("--calls", type=int, default=2000, help="calls per timed batch (default 2000)")
    ap.add_argument("--rounds", type=int, default=9, help="interleaved rounds (default 9, 3 batch pairs each)")
    ap.add_argument("--smoke", action="store_true", help="tiny run (UR10, few calls) to check the script works")
    ap.add_argument("--alone", action="store_true",
                    help="each door's overhead over its kernel timed alone in a C loop (benchmarks/kernel_alone.py)")
    ap.add_argument("--kernels", action="store_true",
                    help="nc.rnea on the tree tables against the flat kernel (one state, 1000 states)")
    ap.add_argument("--cpp", action="store_true",
                    help="ncgen's kernels alone against Pinocchio's C++ rnea/aba/crba alone (compiles a C++ program)")
    args = ap.parse_args(argv)
    if args.smoke:
        args.robots, args.calls, args.rounds = ["ur10"], 50, 2
    print(machine())
    print(f"load average: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    for name in args.robots:
        res = robot_pairs(name, args.calls, args.rounds, args.alone, args.cpp, args.kernels)
        print(f"\n=== {name} ({res['nv']} independent rates)")
        for alg, (kernels, why) in res["chosen"].items():
            print(f"  kernels of {alg}: {kernels} ({why})")
        for key, label in LABELS:
            r = res[key]
            print(f"  {label}: ncgen {r['ncgen_us']:.2f} µs, pinocchio {r['pinocchio_us']:.2f} µs per call"
                  + (f" ({res[key + '_note']})" if key + "_note" in res else ""))
            print(f"RATIO {name} {label}: min {r['ratio_min']:.2f}  median {r['ratio_median']:.2f}  "
                  f"best/best {r['ncgen_us'] / r['pinocchio_us']:.2f}")
        for key in ("rnea_agreement", "aba_agreement", "fd_agreement"):
            if key in res:
                print(f"  {key} (max |ncgen - pinocchio|): {res[key]:.2e}")
        for key, r in res.get("kernels", {}).items():
            print(f"KERNELS {name} {key} tables / flat: min {r['ratio_min']:.2f}  median {r['ratio_median']:.2f}  "
                  f"(tables {r['ncgen_us']:.2f} µs, flat {r['pinocchio_us']:.2f} µs per call)")
        for key, r in res.get("alone", {}).items():
            print(f"ALONE {name} {key}: door {r['door_us']:.2f} µs, kernel alone in C {r['kernel_us']:.2f} µs "
                  f"(median {r['kernel_median_us']:.2f}): door overhead {r['overhead_us']:.2f} µs")
        if "cpp" in res:
            print(f"  C++ program vs Pinocchio's Python (same model): max |difference| {res['cpp']['same_model']:.2e}")
            for key in ("rnea", "aba", "crba"):
                r = res["cpp"][key]
                print(f"KERNEL {name} {key} alone, ncgen C / Pinocchio C++: min {r['ratio_min']:.2f}  median "
                      f"{r['ratio_median']:.2f}  (ncgen {r['ncgen_ns'][0]:.0f} / {r['ncgen_ns'][1]:.0f} ns, "
                      f"Pinocchio {r['pinocchio_ns'][0]:.0f} / {r['pinocchio_ns'][1]:.0f} ns min / median)")
    print(f"\nload average: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
