"""Many runs: ``nc.simulate_batch`` on one and two threads, and against ``mujoco.rollout``.

Model: the 5-bar chain of benchmarks/common.py (bars of 0.3 m, 0.2 kg, shared ends, the
first end on the ground), released from the rest staircase with random angular velocities
(seeded): bar k turns at ω_k (perpendicular to the bar, normal with σ = 0.5 rad/s per axis), so that the
natural-coordinate rates are ``v_end(k) = v_end(k−1) + ω_k × d_k`` and MuJoCo's ball joint
rates are ``ω_k − ω_(k−1)`` (body frames are parallel to the world at rest: the same motion).
ncgen's kernels: ``--kernels`` (default flat, the faster for this small model).

1. **Scaling**: ``--runs`` runs of ``--t-end`` s, stepper with h = ``--h``, every run checked as
   a single run is (``check=True``: shadow run and energy check), states trusted
   (``project=False``), on 1 and on 2 threads, run alternately ``--repeat`` times; RATIO
   one thread / two threads (target ≥ 1.8), and the CPU time per run (process time: the
   threads' C and all Python), the CPU / wall time of each call (about 2 when the two threads
   were each given a core, 1 when the process got one core's worth: then the ratio says
   nothing) and the wall time per run outside the threads.  Also the per-run
   overhead: a batch of one-step runs, split into the preparation (Python, and the KKT
   solves of λ0 in one compiled call) and the compiled loop.
2. **mujoco.rollout**: ``--rollout-runs`` runs, equal accuracy.  The tip error after
   ``--t-end`` s against IDAS (rtol 1e-12) on the first three runs fixes the steps: ncgen's
   stepper at h = ``--h``, MuJoCo RK4 at the largest step of STEPS whose error is at most
   ncgen's, refined by bisection on its number of steps (the largest step ``t_end / n`` as
   accurate as ncgen's).  Both then run the whole batch unchecked (``check=False``: MuJoCo
   checks nothing either; ncgen checked is timed beside them) on 1 and 2 threads
   (``Rollout(nthread=...)``), alternately; RATIO ncgen time / MuJoCo time (< 1: ncgen
   faster; wall time, and CPU RATIO of the process times, which at one thread says what the
   work costs however loaded the machine is); where no step of STEPS brackets it, the same
   with MuJoCo's time scaled to the step at which its error equals ncgen's (log-log
   interpolation).  ``mujoco.rollout`` records the state after every step (its only mode);
   ``simulate_batch`` records every output time, here every 0.1 s.

    python benchmarks/batch.py                     1000 runs of 2 s (minutes on a loaded machine)
    python benchmarks/batch.py --smoke             seconds (CI)
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

from common import L, chain_mjcf, chain_system, ends, machine, mujoco_tip, terminal_sigint

terminal_sigint()

N_BARS = 5
OUTPUT_DT = 0.1
STEPS = (8e-3, 4e-3, 2e-3, 1e-3, 5e-4)


def initial_rates(n_runs: int, seed: int = 0):
    """``(V0, QVEL)``: natural-coordinate rates (n_runs × 3 N) and MuJoCo ball-joint rates
    (n_runs × 3 N) of random bar angular velocities at the rest staircase."""
    rng = np.random.default_rng(seed)
    pts = ends(N_BARS)
    V0, QVEL = np.zeros((n_runs, 3 * N_BARS)), np.zeros((n_runs, 3 * N_BARS))
    for r in range(n_runs):
        v_end, w_prev = np.zeros(3), np.zeros(3)
        for k in range(N_BARS):
            d = pts[k + 1] - pts[k]
            w = 0.5 * rng.normal(size=3)
            w -= (w @ d) / (d @ d) * d              # no spin about the bar
            v_end = v_end + np.cross(w, d)
            V0[r, 3 * k:3 * k + 3] = v_end
            QVEL[r, 3 * k:3 * k + 3] = w - w_prev
            w_prev = w
    return V0, QVEL


def mujoco_setup(timestep: float, QVEL: np.ndarray):
    import mujoco
    model = mujoco.MjModel.from_xml_string(chain_mjcf(N_BARS, integrator="RK4", timestep=timestep))
    data = mujoco.MjData(model)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    states = np.zeros((len(QVEL), mujoco.mj_stateSize(model, spec)))
    for r, qvel in enumerate(QVEL):
        mujoco.mj_resetData(model, data)
        data.qvel[:] = qvel
        mujoco.mj_getState(model, data, states[r], spec)
    return model, states


def mujoco_rollout(model, states, t_end: float, threads: int, cpu: list | None = None):
    """``(seconds, final qpos per run)``: the batch through ``mujoco.rollout`` (wall time; its
    process time appended to ``cpu`` if given)."""
    import mujoco
    from mujoco import rollout
    nstep = int(round(t_end / model.opt.timestep))
    datas = [mujoco.MjData(model) for _ in range(threads)]
    with rollout.Rollout(nthread=threads) as pool:
        start, process = time.perf_counter(), time.process_time()
        out, _ = pool.rollout(model, datas, states, nstep=nstep)
        seconds = time.perf_counter() - start
        if cpu is not None:
            cpu.append(time.process_time() - process)
    return seconds, out[:, -1, 1:1 + model.nq]


def mujoco_tips(model, qpos: np.ndarray) -> np.ndarray:
    import mujoco
    data = mujoco.MjData(model)
    tips = []
    for q in qpos:
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        tips.append(mujoco_tip(N_BARS, data, L))
    return np.array(tips)


def ncgen_batch(model, V0, t_end, h, threads, check, kernels="flat"):
    import ncgen as nc
    substeps = int(round(OUTPUT_DT / h))
    cpu, wall = time.process_time(), time.perf_counter()
    r = nc.simulate_batch(model, t_end, OUTPUT_DT, v0=V0, substeps=substeps, project=False, check=check,
                          outputs=check, workers=threads, kernels=kernels)
    r.info["cpu_time"], r.info["call_wall_time"] = time.process_time() - cpu, time.perf_counter() - wall
    return r


def scaling(model, args) -> None:
    V0, _ = initial_rates(args.runs)
    print(f"\n=== scaling: {args.runs} runs of the {N_BARS}-bar chain, {args.t_end:g} s each, stepper h = {args.h:g} s, "
          f"checked (check=True), states trusted (project=False) ===")
    ncgen_batch(model, V0[:2], args.t_end, args.h, 1, True, args.kernels)          # load, warm up
    times, cpu, checking, cores = {1: [], 2: []}, {1: [], 2: []}, {1: [], 2: []}, {1: [], 2: []}
    for _ in range(args.repeat):
        for threads in (1, 2):
            r = ncgen_batch(model, V0, args.t_end, args.h, threads, True, args.kernels)
            times[threads].append(r.info["wall_time"])
            cpu[threads].append(r.info["cpu_time"] / args.runs)
            cores[threads].append(r.info["cpu_time"] / r.info["call_wall_time"])
            checking[threads].append((r.info["wall_time"] - r.info["stepping_time"]) / args.runs)
    failed = int(np.sum(~r.ok))
    print(f"kernels: {r.info['kernels']}; runs checked on their own (failed or flagged by the screen): "
          f"{r.info['checked_alone']}")
    for threads, ts in times.items():
        print(f"{threads} thread(s): best {min(ts):.3f} s, median {np.median(ts):.3f} s "
              f"({args.runs / min(ts):.0f} runs/s); {failed} run(s) failed their checks; CPU time per run "
              f"best {1e3 * min(cpu[threads]):.2f} ms, median {1e3 * np.median(cpu[threads]):.2f} ms; "
              f"wall time per run outside the threads (preparation and the batch's checks, the main thread) "
              f"{1e3 * np.median(checking[threads]):.3f} ms; CPU / wall of the call (cores this process was "
              f"given) min {min(cores[threads]):.2f}, median {np.median(cores[threads]):.2f}")
    ratios = np.array(times[1]) / np.array(times[2])
    print(f"RATIO one thread / two threads: min {ratios.min():.2f}, median {np.median(ratios):.2f} "
          f"(paired runs; target >= 1.8)")
    n = max(100, args.runs)
    import ncgen as nc
    over = []
    for _ in range(args.repeat):
        r = nc.simulate_batch(model, args.h, args.h, v0=initial_rates(n)[0], project=False, check=False,
                              outputs=False, workers=1, kernels=args.kernels)
        over.append((r.info["wall_time"] / n, (r.info["wall_time"] - r.info["stepping_time"]) / n,
                     r.info["stepping_time"] / n))
    total, prep, loop = min(over)
    print(f"per-run cost of one-step runs: {1e6 * total:.1f} µs = preparation {1e6 * prep:.1f} µs (Python and λ0) "
          f"+ compiled call {1e6 * loop:.1f} µs (the first, cold step included)")


def against_rollout(model, args) -> None:
    import ncgen as nc
    n = args.rollout_runs
    V0, QVEL = initial_rates(n, seed=1)
    k = min(3, n)
    print(f"\n=== simulate_batch vs mujoco.rollout: {n} runs of {args.t_end:g} s, equal tip error on the "
          f"first {k} runs ===")
    ref = np.array([nc.simulate(model, args.t_end, OUTPUT_DT, v0=V0[r], rtol=1e-12, atol=1e-12, backend="compiled",
                                max_steps=10**7).q[-1, -3:] for r in range(k)])
    ours = ncgen_batch(model, V0[:k], args.t_end, args.h, 1, False, args.kernels)
    err_ncgen = float(np.max(np.linalg.norm(ours.q[:, -1, -3:] - ref, axis=1)))
    print(f"ncgen stepper h = {args.h:g} s: tip error {err_ncgen:.2e} m")
    chosen, errors = None, {}
    for step in STEPS:
        mj, states = mujoco_setup(step, QVEL[:k])
        _, qpos = mujoco_rollout(mj, states, args.t_end, 1)
        err = errors[step] = float(np.max(np.linalg.norm(mujoco_tips(mj, qpos) - ref, axis=1)))
        print(f"MuJoCo RK4 dt = {step:g} s: tip error {err:.2e} m")
        if chosen is None and err <= err_ncgen:
            chosen = step
    equal = equal_error_step(errors, err_ncgen)
    if chosen is None:
        print(f"no MuJoCo step of {STEPS} is as accurate as ncgen's; using the smallest")
        chosen = STEPS[-1]
    elif chosen != STEPS[0]:
        chosen = finest_step(QVEL[:k], ref, args.t_end, chosen, STEPS[STEPS.index(chosen) - 1], err_ncgen)
        equal = None             # searched: the step is the largest as accurate as ncgen's, no scaling
    mj, states = mujoco_setup(chosen, QVEL)
    print(f"MuJoCo RK4 at dt = {chosen:g} s ({int(round(args.t_end / chosen))} steps per run), ncgen at h = "
          f"{args.h:g} s ({int(round(args.t_end / args.h))} steps per run)")
    ncgen_batch(model, V0[:2], args.t_end, args.h, 1, False, args.kernels)
    for threads in (1, 2):
        t_nc, t_mj, t_checked, cpu = [], [], [], {"nc": [], "mj": [], "checked": []}
        for _ in range(args.repeat):
            r = ncgen_batch(model, V0, args.t_end, args.h, threads, False, args.kernels)
            t_nc.append(r.info["wall_time"])
            cpu["nc"].append(r.info["cpu_time"])
            t_mj.append(mujoco_rollout(mj, states, args.t_end, threads, cpu["mj"])[0])
            r = ncgen_batch(model, V0, args.t_end, args.h, threads, True, args.kernels)
            t_checked.append(r.info["wall_time"])
            cpu["checked"].append(r.info["cpu_time"])
        ratio, checked = np.array(t_nc) / np.array(t_mj), np.array(t_checked) / np.array(t_mj)
        cores = {k: np.array(v) / np.array(w) for (k, v), w in zip(cpu.items(), (t_nc, t_mj, t_checked))}
        print(f"{threads} thread(s): CPU / wall of the calls (cores given; about {threads} when each thread had "
              f"a core) median: ncgen {np.median(cores['nc']):.2f}, MuJoCo {np.median(cores['mj']):.2f}, "
              f"ncgen checked {np.median(cores['checked']):.2f}")
        for name, key in (("ncgen", "nc"), ("ncgen checked", "checked")):
            c = np.array(cpu[key]) / np.array(cpu["mj"])
            print(f"CPU RATIO {name} / mujoco.rollout, {threads} thread(s): min {c.min():.2f}, median "
                  f"{np.median(c):.2f} (process time: the work, whatever share of the cores the process got)")
        print(f"{threads} thread(s): ncgen simulate_batch best {min(t_nc):.3f} s ({n / min(t_nc):.0f} runs/s), "
              f"checked {min(t_checked):.3f} s; mujoco.rollout best {min(t_mj):.3f} s ({n / min(t_mj):.0f} runs/s)")
        print(f"RATIO ncgen / mujoco.rollout, {threads} thread(s): min {ratio.min():.2f}, median {np.median(ratio):.2f}"
              f"; ncgen checked (check=True, shadow run) / mujoco.rollout: min {checked.min():.2f}, "
              f"median {np.median(checked):.2f}")
        if equal is not None:
            scale = equal / chosen       # MuJoCo's time goes as its number of steps: chosen / equal of it
            print(f"  at exactly equal error (MuJoCo dt = {equal:.3g} s, log-log interpolated; its time scaled by the "
                  f"step count): RATIO min {ratio.min() * scale:.2f}, median {np.median(ratio) * scale:.2f}")



def finest_step(QVEL, ref, t_end: float, good: float, bad: float, target: float) -> float:
    """The largest MuJoCo step ``t_end / n`` (n whole) whose tip error is at most ``target``,
    by bisection on n between the steps ``good`` (error at most ``target``) and ``bad``."""
    n_good, n_bad = int(round(t_end / good)), int(round(t_end / bad))
    while n_good - n_bad > 1:
        n = (n_good + n_bad) // 2
        mj, states = mujoco_setup(t_end / n, QVEL)
        _, qpos = mujoco_rollout(mj, states, t_end, 1)
        err = float(np.max(np.linalg.norm(mujoco_tips(mj, qpos) - ref, axis=1)))
        print(f"MuJoCo RK4 dt = {t_end / n:.4g} s ({n} steps): tip error {err:.2e} m")
        n_good, n_bad = (n, n_bad) if err <= target else (n_good, n)
    return t_end / n_good


def equal_error_step(errors: dict, target: float) -> float | None:
    """MuJoCo's step at which its tip error equals ``target``, log-log interpolated between
    the two steps bracketing it, or None."""
    pts = sorted(errors.items())
    for (h1, e1), (h2, e2) in zip(pts, pts[1:]):
        if e1 <= target <= e2 and e1 > 0 and e2 > e1:
            w = np.log(target / e1) / np.log(e2 / e1)
            return float(np.exp(np.log(h1) + w * (np.log(h2) - np.log(h1))))
    return None


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=int, default=1000)
    p.add_argument("--rollout-runs", type=int, default=200)
    p.add_argument("--t-end", type=float, default=2.0)
    p.add_argument("--h", type=float, default=1e-3, help="ncgen's step (s)")
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--kernels", default="flat", choices=("flat", "tables", "auto"),
                   help="the stepper's kernels (flat: the faster for this small model, benchmarks/table_stepper.py)")
    p.add_argument("--smoke", action="store_true", help="tiny: seconds")
    args = p.parse_args(argv)
    if args.smoke:
        args.runs, args.rollout_runs, args.t_end, args.repeat = 8, 4, 0.2, 1
    print(machine())
    print(f"load average now: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    model = chain_system(N_BARS).build()
    scaling(model, args)
    against_rollout(model, args)
    print(f"load average at the end: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
