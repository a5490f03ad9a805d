"""Step Jacobians of URDF robots: the generated C, its compile and the call, checked against
central differences (issue 34's target: at most 2 MB of C, compiled in at most 10 s — Talos
30 s — with at most 1 GB of compiler memory; equal to central differences to 1e-6).

``nc.step_function(model, h)`` generates the RATTLE step (CasADi's ``fast_newton``
rootfinder, returning the step's unknowns ``z``) and, at a converged ``z``, the implicit
function theorem's ``∂z/∂y = −G_z⁻¹ G_y`` (sparse ``G_z``, ``G_y`` and CasADi's looped sparse
QR) and its transposed solve (:mod:`ncgen.control.discrete`).  Per robot, in a fresh
process with an empty compile cache:

* C: bytes of the package's ``.c`` and ``.h`` files (written as ``step_function`` writes them);
* compile: ncgen's own build of that package (its flags and parallel jobs), wall time, CPU
  time of the compiler processes and the peak resident memory of the largest of them
  (``getrusage(RUSAGE_CHILDREN)``: the kernel's ``ru_maxrss``, what ``/usr/bin/time -v``
  reports);
* calls: ``st(x, u)`` and ``st.jacobians(x, u)`` from Python (best of ``--repeat`` batches,
  wall and process CPU time: at a high load the wall time is mostly waiting);
  with ``--stepper``, also the compiled stepper's time per step on the same model and ``h``
  (``nc.simulate(method="stepper", scheme="rattle")``, 1000 steps from the same state with
  the same input held, its own compile excluded: the second of two runs), which a step
  should not be much slower than;
* check: ``A = ∂x⁺/∂x``, ``B = ∂x⁺/∂u`` against central differences of the compiled step
  (steps 1e-6 relative; for B fourth-order, steps 1e-3: its entries are small and x⁺ is
  converged to about 1e-11), as ``max |J − J_fd| / max |J_fd|``; at a moving state (random rates
  projected on the constraints, then three steps with random torques).

Robots (example-robot-data): z1, panda, ur10 (fixed base), talos_reduced (floating base,
``--talos``; slow to build).  ``--smoke``: the two-joint arm TwoDofs only.

    python benchmarks/step_jacobians.py [--h 0.001] [--repeat 5] [--talos] [--smoke] [--stepper]
                                        [--robots z1,panda]
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine  # noqa: E402

ROBOTS = {"z1": ("z1", False), "panda": ("panda", False), "ur10": ("ur10_robot", False),
          "talos": ("talos_reduced", True), "twodofs": ("TwoDofs", False)}
TARGETS = {"talos": 30.0}          # compile seconds; 10 s for the others
C_TARGET_MB, MEMORY_TARGET_MB = 2.0, 1024.0


def central(f, x, eps):
    cols = []
    for i in range(x.size):
        e = np.zeros_like(x)
        e[i] = eps * max(1.0, abs(x[i]))
        cols.append((f(x + e) - f(x - e)) / (2 * e[i]))
    return np.column_stack(cols)


def central4(f, x, eps):
    """Fourth-order central differences: for the inputs, whose columns are small (max |B|
    about 0.1), so that the step's Newton tolerance (x⁺ to about 1e-11) needs a larger step."""
    cols = []
    for i in range(x.size):
        e = np.zeros_like(x)
        e[i] = eps * max(1.0, abs(x[i]))
        cols.append((8 * (f(x + e) - f(x - e)) - (f(x + 2 * e) - f(x - 2 * e))) / (12 * e[i]))
    return np.column_stack(cols)


def rel_err(J, J_fd) -> float:
    return float(np.max(np.abs(J - J_fd)) / max(np.max(np.abs(J_fd)), 1e-300))


def best(fn, calls: int, repeat: int, clock=time.perf_counter) -> float:
    out = float("inf")
    for _ in range(repeat):
        start = clock()
        for _ in range(calls):
            fn()
        out = min(out, (clock() - start) / calls)
    return out


def children_usage() -> tuple[float, float]:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime, r.ru_maxrss / 1024.0


def measure(robot: str, h: float, repeat: int, stepper: bool) -> dict:
    """One robot, in this (fresh) process: see the module docstring."""
    import ncgen as nc
    from ncgen.codegen.compile_cache import compile_package
    from ncgen.codegen.package import write_package
    from ncgen.control.discrete import default_abstol, step_functions
    from ncgen.control.step import COMPILED, PACKAGE_OPTIONS, compile_flags

    urdf, floating = ROBOTS[robot]
    start = time.process_time()
    model = nc.System.from_urdf(nc.robots.urdf_path(urdf), floating_base=floating).build()
    out = {"robot": robot, "nq": model.nq, "nc": model.nc, "nu": model.nu, "build_cpu": time.process_time() - start}
    fs = step_functions(model, h, abstol=default_abstol(model))
    with tempfile.TemporaryDirectory() as tmp:
        # as ncgen.control.step._compile writes it, so that step_function below finds it cached
        pkg = write_package(f"{model.name}_step", [fs[k] for k in COMPILED], Path(tmp) / "pkg", **PACKAGE_OPTIONS)
        out["c_mb"] = sum(f.stat().st_size for f in pkg.path.iterdir() if f.suffix in (".c", ".h")) / 1e6
        cpu0, _ = children_usage()
        start = time.perf_counter()
        built = compile_package(pkg, cflags=compile_flags())
        out["compile_wall"] = time.perf_counter() - start
        cpu1, peak = children_usage()
        out["compile_cpu"], out["compiler_peak_mb"], out["compiled"] = cpu1 - cpu0, peak, not built.cached
    start = time.perf_counter()
    st = nc.step_function(model, h)
    out["step_function_wall"] = time.perf_counter() - start
    rng = np.random.default_rng(1)
    v = nc.project_velocity(model, model.q0, 0.5 * rng.normal(size=model.nq))
    x = np.concatenate([model.q0, v])
    for _ in range(3):
        x = st(x, rng.normal(size=model.nu))
    u = rng.normal(size=model.nu)
    _, A, B = st.jacobians(x, u)
    out["err_A"] = rel_err(A, central(lambda y: st(y, u), x, 1e-6))
    out["err_B"] = rel_err(B, central4(lambda y: st(x, y), u, 1e-3))
    out["step_us"] = 1e6 * best(lambda: st(x, u), 20, repeat)
    out["jacobians_us"] = 1e6 * best(lambda: st.jacobians(x, u), 5, repeat)
    out["step_cpu_us"] = 1e6 * best(lambda: st(x, u), 20, repeat, time.process_time)
    out["jacobians_cpu_us"] = 1e6 * best(lambda: st.jacobians(x, u), 5, repeat, time.process_time)
    if stepper:
        q, v = x[:model.nq], x[model.nq:]
        for _ in range(2):
            start = time.process_time()
            traj = nc.simulate(model, 1000 * h, h, method="stepper", scheme="rattle", check=False, q0=q, v0=v,
                               u=lambda t: u)
            cpu = time.process_time() - start
        stats = traj.info["stats"]
        out["stepper_us"] = 1e6 * traj.info["wall_time"] / stats["nsteps"]
        out["stepper_cpu_us"] = 1e6 * cpu / stats["nsteps"]
        out["stepper_newton"] = stats["newton_iterations"] / stats["nsteps"]
    return out


def report(r: dict) -> None:
    target = TARGETS.get(r["robot"], 10.0)
    ok = (r["c_mb"] <= C_TARGET_MB and r["compile_wall"] <= target and r["compiler_peak_mb"] <= MEMORY_TARGET_MB
          and max(r["err_A"], r["err_B"]) <= 1e-6)
    print(f"=== {r['robot']}: nq = {r['nq']}, nc = {r['nc']}, nu = {r['nu']}, G_z {2 * (r['nq'] + r['nc'])} rows "
          f"(model built in {r['build_cpu']:.1f} s CPU)")
    print(f"C: {r['c_mb']:.2f} MB; compile: {r['compile_wall']:.1f} s wall, {r['compile_cpu']:.1f} s CPU, "
          f"compiler peak RSS {r['compiler_peak_mb']:.0f} MB" + ("" if r["compiled"] else " (was cached!)"))
    print(f"nc.step_function after the compile: {r['step_function_wall']:.1f} s wall")
    print(f"calls from Python: st(x, u) {r['step_us']:.0f} µs, st.jacobians(x, u) {r['jacobians_us']:.0f} µs "
          f"(CPU: {r['step_cpu_us']:.0f} µs, {r['jacobians_cpu_us']:.0f} µs)")
    if "stepper_us" in r:
        print(f"compiled stepper on the same model and state: {r['stepper_us']:.0f} µs per step "
              f"(CPU: {r['stepper_cpu_us']:.0f} µs) "
              f"({r['stepper_newton']:.1f} Newton iterations per step)")
    print(f"central differences: A {r['err_A']:.1e}, B {r['err_B']:.1e} (relative to max |J_fd|)")
    print(f"TARGET {r['robot']}: ≤ {C_TARGET_MB} MB, ≤ {target:.0f} s, ≤ {MEMORY_TARGET_MB:.0f} MB, ≤ 1e-6: "
          + ("met" if ok else "NOT met"))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--h", type=float, default=1e-3, help="step (s)")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--talos", action="store_true", help="also Talos (floating base; slow to build)")
    ap.add_argument("--smoke", action="store_true", help="the two-joint arm TwoDofs only, seconds")
    ap.add_argument("--stepper", action="store_true", help="also the compiled stepper's time per step")
    ap.add_argument("--robots", help=f"comma-separated subset of {', '.join(ROBOTS)}")
    ap.add_argument("--one", help=argparse.SUPPRESS)          # worker: one robot, JSON on stdout
    a = ap.parse_args()
    if a.one:
        print(json.dumps(measure(a.one, a.h, a.repeat, a.stepper)))
        return
    print(machine())
    robots = ["twodofs"] if a.smoke else ["z1", "panda", "ur10"] + (["talos"] if a.talos else [])
    if a.robots:
        robots = a.robots.split(",")
        unknown = sorted(set(robots) - set(ROBOTS))
        if unknown:
            ap.error(f"--robots: unknown {unknown}; expected some of {', '.join(ROBOTS)}")
    for robot in robots:
        with tempfile.TemporaryDirectory() as cache:
            env = {**os.environ, "NCGEN_CACHE_DIR": cache}
            run = subprocess.run([sys.executable, __file__, "--one", robot, "--h", str(a.h), "--repeat",
                                  str(1 if a.smoke else a.repeat)] + (["--stepper"] if a.stepper else []),
                                 capture_output=True, text=True, env=env)
        if run.returncode:
            print(f"=== {robot}: FAILED\n{run.stderr[-3000:]}")
            sys.exit(1)
        report(json.loads(run.stdout.strip().splitlines()[-1]))
    print(f"load average at the end: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
