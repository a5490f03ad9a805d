"""Control: exact step Jacobians against MuJoCo's finite-differenced ones, and the cart-pole
MPC step against re-solving the same horizon problem with IPOPT.

1. Step Jacobians of the 20-bar chain (benchmarks/common.py: 20 'rr' bars sharing their ends,
   60 natural coordinates; its MuJoCo twin: 20 bodies on ball joints).  ncgen:
   ``st.jacobians(x, u)`` of ``nc.step_function(model, h)`` — the RATTLE step solved by a
   Newton rootfinder and ``A = ∂x⁺/∂x`` (120 × 120) by the implicit function theorem, generated
   C called through ctypes (the call from Python included).  MuJoCo:
   ``mujoco.mjd_transitionFD(m, d, eps=1e-6, flg_centered)`` on the twin (Euler, its default
   integrator, same step), forward and centred differences (``A``: 2nv × 2nv = 120 × 120, nv = 60
   ball-joint rates), also called from Python.  Not the same step nor the same coordinates:
   the same job (the linearisation of one step of the same chain).  Interleaved, min and
   median over ``--repeat`` batches of ``--calls`` calls.
2. Cart-pole MPC (examples/cartpole_mpc.toml: N = 20, h = 0.05 s): one control step of
   ``nc.MPC`` (one real-time SQP iteration, generated C, from Python) at the states of a
   closed loop from a 0.2 rad tilt with a push, against re-solving the same discrete horizon
   problem with IPOPT at the same states (``ncgen.control.reference.DiscreteOCP``: built once,
   warm-started from the MPC's converged solution at that state, the most favourable start;
   solve time only), and against ``nc.MPC(ocp, "fatrop")`` (Fatrop on the stage-wise problem,
   solved to its tolerance from the same state's converged solution: the warm start of a
   quiet closed loop).  The controllers take turns state by state, each calling ``--repeat``
   times in a row (as in a control loop: another solver's call in between evicts the caches),
   each state's time the minimum over those calls.  At a converged guess the SQP's line search often finds
   no step that decreases the cost beyond round-off and tries all its step lengths, so the
   step of the closed loop itself (a new state and the shifted guess at every call: what a
   controller does) is timed too, with the SQP loop in Python and in C (``nc.MPC(ocp,
   loop="c")``: the whole control step one compiled call) and Fatrop's joint form (one solve a
   step from the shifted solution), the three loops' runs interleaved, each step the minimum
   over ``--repeat`` runs.  The controller's quality: the closed-loop
   cost ``Σ ℓ(x_k, u_k)`` of the real-time iteration against the converged MPC's (10 SQP
   iterations a step, checked against 20).  All times are CPU times (``time.process_time``;
   the C driver's ``CLOCK_PROCESS_CPUTIME_ID``).  ``--export``: the same closed loop in the
   exported C package (``nc.export_mpc``, built by its Makefile at its default flags), each
   ``cartpole_mpc_step`` call timed in a C driver of its own, and its
   inputs compared with the Python loop's; ``--peer ROOT``: also the package exported by the
   ncgen tree ROOT (a child process), the two packages' runs alternating, their ratio.

    python benchmarks/control.py [--calls 200] [--repeat 7] [--smoke] [--mpc-only] [--export] [--peer ROOT]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import batches, chain_mjcf, chain_system, machine, terminal_sigint  # noqa: E402

terminal_sigint()

import ncgen as nc  # noqa: E402

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
H = 1e-3


def step_jacobians(n: int, calls: int, repeat: int) -> None:
    import mujoco
    model = chain_system(n).build()
    st = nc.step_function(model, H)
    x = np.concatenate([model.q0, model.v0])
    x = st.rollout(x, np.zeros((50, 0)))[-1]          # moving, on both constraint levels
    m = mujoco.MjModel.from_xml_string(chain_mjcf(n, integrator="Euler", timestep=H))
    d = mujoco.MjData(m)
    mujoco.mj_step(m, d, nstep=50)
    nxm = 2 * m.nv + m.na
    A = np.zeros((nxm, nxm))
    B = np.zeros((nxm, m.nu))
    # accuracy of ncgen's A against its own central differences (a check, not timed)
    _, Aj, _ = st.jacobians(x, np.zeros(0))
    eps = 1e-6
    cols = [(st(x + e, np.zeros(0)) - st(x - e, np.zeros(0))) / (2 * eps) for e in np.eye(x.size) * eps]
    err = np.max(np.abs(Aj - np.column_stack(cols))) / np.max(np.abs(Aj))
    fns = {
        "ncgen st.jacobians (exact, IFT)": lambda: st.jacobians(x, np.zeros(0)),
        "mujoco mjd_transitionFD forward": lambda: mujoco.mjd_transitionFD(m, d, 1e-6, False, A, B, None, None),
        "mujoco mjd_transitionFD centred": lambda: mujoco.mjd_transitionFD(m, d, 1e-6, True, A, B, None, None),
    }
    t = batches(fns, calls, repeat)
    print(f"\n=== step Jacobians: chain of N = {n} bars, h = {H} s: A is {2 * model.nq}×{2 * model.nq} "
          f"(ncgen, natural coordinates), {nxm}×{nxm} (MuJoCo, ball joints); ncgen's A vs its central "
          f"differences: rel. {err:.1e}")
    ref = t["ncgen st.jacobians (exact, IFT)"]
    for name, ts in t.items():
        print(f"  {name:36s} min {1e6 * min(ts):9.1f} µs   median {1e6 * np.median(ts):9.1f} µs")
    for name in list(t)[1:]:
        r = np.array(ref) / np.array(t[name])
        print(f"  RATIO ncgen / {name}: min {min(ref) / min(t[name]):.2f}, median of pairs {np.median(r):.2f}"
              " (target ≤ 0.5)")


class _TimedCalls:
    """``mpc`` with each control step's CPU time (s) appended to :attr:`times`."""

    def __init__(self, mpc):
        self.mpc, self.times = mpc, []

    def __getattr__(self, name):
        return getattr(self.mpc, name)

    def __call__(self, x, t):
        start = time.process_time()
        u = self.mpc(x, t)
        self.times.append(time.process_time() - start)
        return u


def closed_loop_cost(problem, X, U) -> float:
    """``Σ_k ℓ(x_k, u_k)``: the horizon problem's stage cost summed along a closed loop."""
    import casadi as ca
    x, u = ca.SX.sym("x", X.shape[1]), ca.SX.sym("u", U.shape[1])
    stage = ca.Function("stage", [x, u], [problem.stage(x, u)])
    return float(np.sum(np.array(stage.map(len(U))(X.T, U.T))))


#: The exported package's closed loop with each controller call timed (``--export``): the
#: demo's loop (warm-up, plant substeps, the push) around ``cartpole_mpc_step``.
C_DRIVER = r"""
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "cartpole.h"
#define NX CARTPOLE_MPC_NX
static double now(void) { struct timespec s; clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &s); return s.tv_sec + 1e-9 * s.tv_nsec; }
int main(int argc, char** argv) {
    static cartpole_mpc m;
    const long steps = atol(argv[1]), repeat = atol(argv[2]);
    const double h = CARTPOLE_MPC_H, hs = h / CARTPOLE_PLANT_SUBSTEPS;
    for (long r = 0; r < repeat; ++r) {
        double x[NX], u[1], up[1], start;
        for (int i = 0; i < NX; ++i) x[i] = atof(argv[3 + i]);
        if (cartpole_mpc_init(&m, x, 0.0, 10)) return 1;
        for (long k = 0; k < steps; ++k) {
            double t = k * h;
            start = now();
            if (cartpole_mpc_step(&m, x, t, u)) return 1;
            printf("%ld %.17g %.9g\n", k, u[0], now() - start);
            for (int j = 0; j < CARTPOLE_PLANT_SUBSTEPS; ++j) {
                double ts = t + j * hs;
                up[0] = u[0] + ((ts >= 1.0 && ts < 1.1) ? 8.0 : 0.0);
                if (cartpole_plant(x, up, ts, x)) return 1;
            }
        }
    }
    return 0;
}
"""


#: Exports the cart-pole MPC package as :func:`cartpole_mpc` does, in a child process on another
#: ncgen tree (``--peer``): argv = output directory, then x0.
PEER_EXPORT = """
import sys
from pathlib import Path
import numpy as np
import ncgen as nc
from ncgen.control.export import export_mpc
from ncgen.optim.problem_file import load_problem
examples = Path(nc.__file__).resolve().parents[1] / "examples"
ocp = load_problem(examples / "cartpole_mpc.toml", nc.System.from_toml(examples / "cartpole.toml").build())[0]
export_mpc(ocp, sys.argv[1], name="cartpole", terminal_weight=100.0, x0=np.array([float(v) for v in sys.argv[2:]]),
           disturbance=[(1.0, 1.1, [8.0])])
"""


def build_exported(out: Path, ocp, x0, peer: str | None = None) -> Path:
    """The exported package in ``out`` (by this tree, or by the ncgen tree ``peer`` in a child
    process), built by its Makefile at its default flags, with :data:`C_DRIVER` as ``timing``."""
    import subprocess
    from ncgen.control.export import export_mpc
    if peer is None:
        export_mpc(ocp, out, name="cartpole", terminal_weight=100.0, x0=x0, disturbance=[(1.0, 1.1, [8.0])])
    else:
        subprocess.run([sys.executable, "-c", PEER_EXPORT, str(out), *(repr(float(v)) for v in x0)], check=True,
                       env={**os.environ, "PYTHONPATH": peer}, cwd=peer, capture_output=True)   # cwd: `-c` imports from it
    subprocess.run(["make", "demo"], cwd=out, check=True, capture_output=True)
    (out / "timing.c").write_text(C_DRIVER)
    objects = [f.name for f in sorted(out.glob("*.o")) if f.name not in ("demo.o", "main.o")]
    subprocess.run(["cc", "-O2", "-o", "timing", "timing.c", *objects, "-lm"], cwd=out, check=True)
    return out


def exported_loop(ocp, x0, steps: int, repeat: int, peer: str | None = None) -> dict:
    """``{tree: (U, T)}``: the exported package's closed loop (:data:`C_DRIVER`): its inputs and
    each step's time, the minimum over ``repeat`` runs; with ``peer``, also the package exported
    by that ncgen tree, the two packages' runs alternating."""
    import subprocess
    import tempfile
    with tempfile.TemporaryDirectory() as tmp:
        trees = {"this tree": build_exported(Path(tmp) / "this", ocp, x0)}
        if peer:
            trees[f"peer {peer}"] = build_exported(Path(tmp) / "peer", ocp, x0, peer)
        rows = {tree: [] for tree in trees}
        for r in range(repeat):
            for tree in (list(trees) if r % 2 == 0 else list(trees)[::-1]):
                run = subprocess.run(["./timing", str(steps), "1", *(repr(float(v)) for v in x0)], cwd=trees[tree],
                                     check=True, capture_output=True, text=True)
                rows[tree].append([[float(v) for v in line.split()] for line in run.stdout.splitlines()])
    return {tree: (np.array(r)[0, :, 1], np.array(r)[:, :, 2].min(axis=0)) for tree, r in rows.items()}


def cartpole_mpc(steps: int, repeat: int, export: bool = False, peer: str | None = None) -> None:
    from ncgen.control.export import closed_loop
    from ncgen.control.reference import DiscreteOCP
    from ncgen.optim.problem_file import load_problem
    model = nc.System.from_toml(EXAMPLES / "cartpole.toml").build()
    ocp = load_problem(EXAMPLES / "cartpole_mpc.toml", model)[0]
    mpc = nc.MPC(ocp, terminal_weight=100.0)
    th = 0.2
    x0 = np.concatenate([[0, 0, 1, 0, 0, 1, 0.5 * np.sin(th), 0.5 * np.cos(th)], np.zeros(8)])
    _, _, X = closed_loop(mpc, x0, steps * mpc.h, disturbance=[(1.0, 1.1, [8.0])])
    st = nc.step_function(model, mpc.h)
    ipopt = DiscreteOCP(st, mpc.N, (mpc.problem.stage, mpc.problem.terminal), tol=1e-8)
    fatrops = {form: nc.MPC(ocp, "fatrop", terminal_weight=100.0, fatrop_form=form) for form in ("joint", "natural")}
    t_mpc, t_ip = [], []
    t_fat, iters, t_fun = ({form: [] for form in fatrops} for _ in range(3))
    for x in X[::max(1, len(X) // 10)]:
        mpc.reset(x, iterations=10)
        guess = mpc.U.copy()
        converged = {}
        for form, fatrop in fatrops.items():
            fatrop.reset(x, iterations=1)
            converged[form] = fatrop.X, fatrop.U, fatrop.Z
        # each controller's calls in a row (as in a control loop), the controllers in turn at
        # each state: a natural-form Fatrop solve (≈ 12 ms of other code) between two calls of
        # the joint form evicts its caches and doubled its time (0.47 → 0.96 ms at load 14)
        runs, runs_f = [], {form: [] for form in fatrops}
        for _ in range(repeat):
            mpc.X, mpc.U = mpc.initial_guess(x)
            mpc.reset(x, iterations=10)
            start = time.process_time()
            mpc(x, 0.0)
            runs.append(time.process_time() - start)
        for form, fatrop in fatrops.items():
            for _ in range(repeat):
                fatrop.X, fatrop.U, fatrop.Z = converged[form]
                start = time.process_time()
                fatrop(x, 0.0)
                runs_f[form].append(time.process_time() - start)
                iters[form] += fatrop.fatrop.iteration_counts
                if form == "natural":           # the joint form's compiled solver keeps no stats
                    stats = fatrop.fatrop.nlp.solver.stats()
                    t_fun[form].append(sum(v for k, v in stats.items() if k.startswith("t_proc_nlp")))
        t_mpc.append(min(runs))
        for form in fatrops:
            t_fat[form].append(min(runs_f[form]))
        start = time.process_time()
        ipopt.solve(x, guess)
        t_ip.append(time.process_time() - start)
    t_mpc, t_ip = np.array(t_mpc), np.array(t_ip)
    print(f"\n=== cart-pole MPC (N = {mpc.N}, h = {mpc.h} s, 1 SQP iteration, qrqp), {len(t_mpc)} states "
          "of a closed loop:")
    print(f"  nc.MPC control step       min {1e3 * t_mpc.min():.3f} ms   median {1e3 * np.median(t_mpc):.3f} ms "
          f"(target ≤ 1 ms)")
    for form, fatrop in fatrops.items():
        t = np.array(t_fat[form])
        controls = len(fatrop.fatrop.nlp.input[0]) + len((fatrop.fatrop.nlp.unknowns or [[]])[0])
        print(f"  nc.MPC 'fatrop' step, {form} form ({len(fatrop.fatrop.nlp.state[0])} states, "
              f"{controls} control{'s' * (controls > 1)} a stage) "
              f"min {1e3 * t.min():.3f} ms   median {1e3 * np.median(t):.3f} ms (target ≤ 1 ms; "
              f"{min(iters[form])}–{max(iters[form])} interior-point iterations, median {np.median(iters[form]):g}"
              + (f"; the NLP's functions (Fatrop's stats, t_proc_nlp_*) median {1e3 * np.median(t_fun[form]):.3f} ms)"
                 if t_fun[form] else "; the whole solver compiled C)"))
    print(f"  IPOPT re-solve (warm)     min {1e3 * t_ip.min():.1f} ms   median {1e3 * np.median(t_ip):.1f} ms")
    r = t_ip / t_mpc
    print(f"  RATIO IPOPT re-solve / MPC step: min {r.min():.0f}, median {np.median(r):.0f} (for scale: what the "
          "real-time iteration saves against solving each horizon again; not a target)")
    loops = {"python": _TimedCalls(mpc), "c": _TimedCalls(nc.MPC(ocp, terminal_weight=100.0, loop="c")),
             "fatrop": _TimedCalls(fatrops["joint"])}
    for _ in range(repeat):                     # interleaved: a run of each loop per round
        runs = {k: closed_loop(m, x0, steps * mpc.h, disturbance=[(1.0, 1.1, [8.0])]) for k, m in loops.items()}
    U_py, X_py = runs["python"][1], runs["python"][2]
    t_py, t_cl, t_fj = (np.array(loops[k].times).reshape(repeat, -1).min(axis=0) for k in ("python", "c", "fatrop"))
    print(f"  closed loop, CPU time of each step the minimum of {repeat} interleaved runs ({len(t_py)} steps):")
    for what, t_loop in (("nc.MPC (SQP loop in Python)", t_py), ("nc.MPC(loop='c')", t_cl),
                         ("nc.MPC('fatrop'), joint form", t_fj)):
        print(f"  {what:28s} min {1e3 * t_loop.min():.3f} ms   median {1e3 * np.median(t_loop):.3f} ms   "
              f"max {1e3 * t_loop.max():.3f} ms (target ≤ 1 ms)")
    r = t_cl / t_py
    print(f"  RATIO loop='c' / Python loop: min {r.min():.2f}, median {np.median(r):.2f}; inputs max |ΔU| "
          f"{np.max(np.abs(runs['c'][1] - U_py)):.1e} N")
    r = t_fj / t_cl
    print(f"  RATIO Fatrop joint form / loop='c': min {r.min():.2f}, median {np.median(r):.2f}; its closed-loop cost "
          f"{closed_loop_cost(mpc.problem, runs['fatrop'][2], runs['fatrop'][1]):.6f} (a converged MPC on the "
          f"midpoint step in joint space; inputs vs the real-time SQP's: max |ΔU| "
          f"{np.max(np.abs(runs['fatrop'][1] - U_py)):.2f} N)")
    # the controller's quality: the real-time iteration against the converged MPC (10 SQP
    # iterations per step; 20 as its own convergence check), same start, push and plant
    J_rti = closed_loop_cost(mpc.problem, X_py, U_py)
    conv = {n: closed_loop(nc.MPC(ocp, terminal_weight=100.0, iterations=n, loop="c"), x0, steps * mpc.h,
                           disturbance=[(1.0, 1.1, [8.0])]) for n in (10, 20)}
    J10, J20 = (closed_loop_cost(mpc.problem, conv[n][2], conv[n][1]) for n in (10, 20))
    print(f"  closed-loop cost Σ ℓ(x_k, u_k): real-time iteration {J_rti:.6f}, converged MPC (10 iterations a "
          f"step) {J10:.6f}: {100 * (J_rti / J10 - 1):+.3f} %; 20 iterations {J20:.6f} (inputs vs 10: "
          f"max |ΔU| {np.max(np.abs(conv[20][1] - conv[10][1])):.1e} N); RTI inputs vs converged: max |ΔU| "
          f"{np.max(np.abs(U_py - conv[10][1])):.2e} N")
    if export:
        loops = exported_loop(ocp, x0, len(t_py), repeat, peer)
        for tree, (U_c, t_c) in loops.items():
            print(f"  exported C closed-loop step ({tree}) min {1e3 * t_c.min():.3f} ms   median "
                  f"{1e3 * np.median(t_c):.3f} ms (target ≤ 1 ms; inputs vs Python's: max |ΔU| "
                  f"{np.max(np.abs(U_c - U_py[:, 0])):.1e} N)")
        if peer:
            (_, t_c), (_, t_p) = loops.values()
            print(f"  RATIO exported step this tree / peer: min {t_c.min() / t_p.min():.2f}, median "
                  f"{np.median(t_c) / np.median(t_p):.2f}, median of the steps' ratios {np.median(t_c / t_p):.2f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--calls", type=int, default=200)
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--bars", type=int, default=20)
    ap.add_argument("--smoke", action="store_true", help="tiny sizes: check that the script runs")
    ap.add_argument("--mpc-only", action="store_true", help="only the cart-pole MPC")
    ap.add_argument("--export", action="store_true", help="also the exported C package's closed loop (builds it)")
    ap.add_argument("--peer", metavar="ROOT", help="with --export: also the package exported by the ncgen tree ROOT "
                    "(a checkout of main, say), the two packages' runs alternating")
    args = ap.parse_args(argv)
    if args.smoke:
        args.calls, args.repeat, args.bars = 5, 2, 3
    print(machine())
    if not args.mpc_only:
        step_jacobians(args.bars, args.calls, args.repeat)
    cartpole_mpc(20 if args.smoke else 80, args.repeat, args.export or bool(args.peer), args.peer)
    print(f"load average at end: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
