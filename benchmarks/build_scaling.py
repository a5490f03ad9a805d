"""Build scaling: model -> C -> loaded library for chains of N bars, and SymPy's KanesMethod
deriving an n-link pendulum, side by side.

ncgen, per N (chain of benchmarks/common.py), in a fresh child process with a fresh compile
cache: ``System`` construction and ``build()`` (SymPy per coordinate type, CasADi assembly,
consistent initial state), ``nc.generate`` (the model's C package: system functions, DAE
Jacobian, stepper), ``compile_package`` (gcc; ncgen's default flags, -O2 and -O1 for the
files holding very long functions, unless ``--cflags``; files in parallel on all cores) and
``load_functions`` (casadi.external).  Wall time per phase and peak resident memory: of
the Python process (``RUSAGE_SELF``) and of the largest compiler process
(``RUSAGE_CHILDREN``, measured in the child).

SymPy: ``sympy.physics.mechanics.KanesMethod`` deriving the equations of motion (mass
matrix and forcing, ``kanes_equations``) of a planar n-link pendulum of uniform rods, for
n = 1, 2, ... while one derivation takes less than ``--kane-cap`` seconds; the growth is
fitted as a power law t = c n^k on the measured points and extrapolated, labelled as such.
Each n runs in a child process too (time and peak memory).

    python benchmarks/build_scaling.py                 N = 10, 100, 1000
    python benchmarks/build_scaling.py --smoke         N = 2, 4 and n <= 3 (CI)
    python benchmarks/build_scaling.py --sizes 10 100 --cflags=-O2   -O2 on every file

``--build-cpu ROOT...``: only ``System`` -> ``build()``, in CPU seconds, for each ncgen checkout
``ROOT`` (e.g. ``/work/main`` before a change and ``.`` after it), interleaved, each in fresh
child processes (imports excluded): the system's construction; ``build()`` with the store of
built models off; then every function of ``model.functions`` made (what a lazy build left for
later; ~0 where they are made eagerly); ``build()`` with an empty store (it writes the entry);
and in another process the same ``System`` -> ``build()`` on that warm store.

    python benchmarks/build_scaling.py --build-cpu /work/main . --sizes 10 40 160 1000
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from common import machine

HERE = Path(__file__).resolve().parent


def child_ncgen(n: int, cflags: str | None) -> dict:
    """Runs in the child process: the four phases for the chain of ``n`` bars."""
    import resource

    start = time.perf_counter()
    import ncgen as nc
    from ncgen.codegen import compile_package, load_functions
    from common import chain_system
    times = {"import": time.perf_counter() - start}
    start = time.perf_counter()
    model = chain_system(n).build()
    times["build"] = time.perf_counter() - start
    with tempfile.TemporaryDirectory(prefix="ncgen-build-") as tmp:
        os.environ["NCGEN_CACHE_DIR"] = f"{tmp}/cache"
        start = time.perf_counter()
        pkg = nc.generate(model, f"{tmp}/pkg")
        times["generate"] = time.perf_counter() - start
        size = sum(p.stat().st_size for p in Path(pkg.path).iterdir())
        start = time.perf_counter()
        built = compile_package(pkg, cflags=cflags)
        times["compile"] = time.perf_counter() - start
        start = time.perf_counter()
        functions = load_functions(built, backend="compiled")
        times["load"] = time.perf_counter() - start
    residual = float(np.max(np.abs(np.array(functions["phi"](model.t0, model.q0, model.p0))), initial=0.0))
    return {"n": n, "phi_q0": residual, "nq": model.nq, "times": times, "source_bytes": size,
            "rss_self_kb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
            "rss_children_kb": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss}


def child_build(n: int) -> dict:
    """Runs in the child process (the ncgen of ``$PYTHONPATH``): CPU seconds of the chain's
    ``System``, its ``build()`` and then of every remaining function of ``model.functions``."""
    import ncgen  # noqa: F401  (imports are not timed)
    from common import chain_system
    from ncgen.model import system as _  # noqa: F401

    start = time.process_time()
    system = chain_system(n)
    built = time.process_time()
    model = system.build()
    done = time.process_time()
    made = getattr(model.functions, "made", None)
    made = list(made()) if made else None
    dict(model.functions)
    rest = time.process_time()
    return {"n": n, "nq": model.nq, "system": built - start, "build": done - built, "rest": rest - done,
            "made": made, "store_key": getattr(model.data, "store_key", None) is not None}


def build_cpu(roots: list[str], sizes: list[int], rounds: int, timeout: float) -> None:
    """The ``--build-cpu`` table (see the module docstring)."""
    base = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    with tempfile.TemporaryDirectory(prefix="ncgen-build-cpu-") as tmp:
        def child(root: str, n: int, extra: dict) -> dict | None:
            env = {**base, "PYTHONPATH": str(Path(root).resolve()), "PYTHONPYCACHEPREFIX": f"{tmp}/pyc", **extra}
            cmd = [sys.executable, str(Path(__file__).resolve()), "--child", "build", str(n)]
            try:
                out = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=HERE, env=env)
            except subprocess.TimeoutExpired:
                return None
            if out.returncode != 0:
                raise RuntimeError(f"build N = {n} ({root}) failed:\n{out.stderr[-2000:]}")
            return json.loads(out.stdout.strip().splitlines()[-1])

        for root in roots:                  # bytecode written once per checkout, not timed
            child(root, 2, {"NCGEN_MODEL_CACHE": "0"})
        print(f"\n=== System -> build() of the chain of N bars, CPU s (fresh processes, imports excluded; "
              f"min of {rounds}) ===")
        print(f"  {'N':>5} {'checkout':<28} {'System':>8} {'build, store off':>17} {'then all functions':>19} "
              f"{'build, empty store':>19} {'System+build, stored':>21}")
        for n in sizes:
            for r in range(rounds):
                order = roots if r % 2 == 0 else roots[::-1]
                for root in order:
                    off = child(root, n, {"NCGEN_MODEL_CACHE": "0"})
                    cache = {"NCGEN_MODEL_CACHE": "1", "NCGEN_CACHE_DIR": f"{tmp}/cache-{abs(hash(root))}-{n}-{r}"}
                    first = child(root, n, cache)
                    warm = child(root, n, cache)
                    if None in (off, first, warm):
                        print(f"  {n:>5} {root:<28} did not finish within {timeout:g} s")
                        continue
                    stored = "" if warm["store_key"] else " (no store)"
                    print(f"  {n:>5} {root[-28:]:<28} {off['system']:>8.2f} {off['build']:>17.2f} {off['rest']:>19.2f} "
                          f"{first['build']:>19.2f} {warm['system'] + warm['build']:>21.2f}{stored}", flush=True)
                    if off["made"] is not None and r == 0:
                        print(f"  {'':>5} made by build(): {', '.join(off['made'])}")
        print(f"  load average at the end: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")


def child_kane(n: int) -> dict:
    """Runs in the child process: KanesMethod for the planar n-link pendulum of rods."""
    import resource

    import sympy as sp
    from sympy.physics import mechanics as me

    start = time.perf_counter()
    q, u = me.dynamicsymbols(f"q:{n}"), me.dynamicsymbols(f"u:{n}")
    m, l, g = sp.symbols("m l g", positive=True)
    frame = me.ReferenceFrame("N")
    origin = me.Point("O")
    origin.set_vel(frame, 0)
    bodies, loads, joint = [], [], origin
    for i in range(n):
        link = frame.orientnew(f"B{i}", "Axis", (q[i], frame.z))
        link.set_ang_vel(frame, u[i] * frame.z)
        centre = joint.locatenew(f"G{i}", l / 2 * link.x)
        centre.v2pt_theory(joint, frame, link)
        end = joint.locatenew(f"P{i}", l * link.x)
        end.v2pt_theory(joint, frame, link)
        inertia = me.inertia(link, 0, 0, m * l**2 / 12)
        bodies.append(me.RigidBody(f"rod{i}", centre, link, m, (inertia, centre)))
        loads.append((centre, -m * g * frame.y))
        joint = end
    kane = me.KanesMethod(frame, q_ind=q, u_ind=u, kd_eqs=[qd - ud for qd, ud in zip(me.dynamicsymbols(f"q:{n}", 1), u)])
    kane.kanes_equations(bodies, loads)
    ops = sp.count_ops(kane.mass_matrix) + sp.count_ops(kane.forcing)
    return {"n": n, "time": time.perf_counter() - start, "ops": int(ops),
            "rss_self_kb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss}


def spawn(kind: str, n: int, timeout: float, cflags: str | None) -> dict | None:
    """Run one measurement in a child process; None if it exceeded ``timeout`` s."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", kind, str(n)]
    if cflags:
        cmd.append(f"--cflags={cflags}")
    try:
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=HERE)
    except subprocess.TimeoutExpired:
        return None
    if out.returncode != 0:
        raise RuntimeError(f"{kind} N = {n} failed:\n{out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def power_law(ns, ts) -> tuple[float, float]:
    """``(c, k)`` of t = c n^k fitted (least squares in logs) on the points with n at least
    half the largest (the growth at small n is dominated by fixed costs)."""
    keep = [i for i, n in enumerate(ns) if 2 * n >= ns[-1]]
    x, y = np.log(np.asarray(ns, float)[keep]), np.log(np.asarray(ts, float)[keep])
    k, logc = np.polyfit(x, y, 1) if len(x) > 1 else (1.0, y[0])
    return float(np.exp(logc)), float(k)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--smoke", action="store_true", help="tiny: runs in seconds (CI)")
    parser.add_argument("--sizes", type=int, nargs="+", help="numbers of bars (default 10 100 1000)")
    parser.add_argument("--cflags", default=None,
                        help="compiler flags for every file (default: ncgen's, -O2 and -O1 for files with very long functions)")
    parser.add_argument("--no-kane", action="store_true", help="skip the SymPy KanesMethod comparison")
    parser.add_argument("--timeout", type=float, default=1800.0, help="seconds allowed per N")
    parser.add_argument("--kane-cap", type=float, default=60.0, help="stop KanesMethod after a run this long (s)")
    parser.add_argument("--build-cpu", nargs="+", metavar="ROOT",
                        help="only System -> build() CPU, for each ncgen checkout ROOT (see the docstring)")
    parser.add_argument("--rounds", type=int, default=1, help="rounds of --build-cpu (min shown)")
    parser.add_argument("--child", nargs=2, metavar=("KIND", "N"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        kind, n = args.child[0], int(args.child[1])
        child = {"ncgen": lambda: child_ncgen(n, args.cflags), "build": lambda: child_build(n)}.get(kind)
        print(json.dumps(child() if child else child_kane(n)))
        return 0
    if args.build_cpu:
        print(machine())
        build_cpu(args.build_cpu, args.sizes or ([2, 4] if args.smoke else [10, 40, 160, 1000]), args.rounds,
                  args.timeout)
        return 0
    sizes = args.sizes or ([2, 4] if args.smoke else [10, 100, 1000])
    kane_cap, kane_max = (5.0, 3) if args.smoke else (args.kane_cap, 40)
    print(machine())
    flags = args.cflags or "ncgen default: -O2, -O1 for very long functions"
    print(f"\n=== ncgen: chain of N bars, model -> C -> loaded library (cflags: {flags}) ===")
    print(f"  {'N':>5} {'nq':>5} {'build':>8} {'generate':>9} {'compile':>8} {'load':>7} {'total':>8} "
          f"{'C source':>9} {'RSS python':>11} {'RSS cc':>8}")
    rows = []
    for n in sizes:
        r = spawn("ncgen", n, args.timeout, args.cflags)
        if r is None:
            print(f"  {n:>5}  did not finish within {args.timeout:g} s")
            continue
        t = r["times"]
        total = t["build"] + t["generate"] + t["compile"] + t["load"]
        rows.append((n, total, t["build"]))
        print(f"  {n:>5} {r['nq']:>5} {t['build']:>7.2f}s {t['generate']:>8.2f}s {t['compile']:>7.2f}s "
              f"{t['load']:>6.2f}s {total:>7.2f}s {r['source_bytes'] / 2**20:>7.1f}MB "
              f"{r['rss_self_kb'] / 2**20:>9.2f}GB {r['rss_children_kb'] / 2**20:>6.2f}GB")
    if len(rows) > 1:
        (n1, t1, _), (n2, t2, _) = rows[-2], rows[-1]
        print(f"  growth from N = {n1} to {n2}: time x{t2 / t1:.1f} for N x{n2 / n1:.0f} "
              f"(exponent {np.log(t2 / t1) / np.log(n2 / n1):.2f}; 1 = linear)")
        totals = [r[1] for r in rows]
        steps = [f"{a[0]}->{b[0]}" for a, b in zip(rows, rows[1:]) if b[1] < a[1]]
        print(f"  monotonic in N: {'yes' if not steps else 'NO, falls at ' + ', '.join(steps)}; "
              f"largest total {max(totals):.2f} s")
    if args.no_kane:
        return 0
    print("\n=== sympy.physics.mechanics KanesMethod: planar n-link pendulum, derivation only ===")
    print(f"  {'n':>3} {'time':>9} {'ops (M, f)':>11} {'RSS':>8}")
    ns, ts = [], []
    for n in range(1, kane_max + 1):
        r = spawn("kane", n, max(10 * kane_cap, 60.0), None)
        if r is None:
            print(f"  {n:>3}  exceeded {max(10 * kane_cap, 60.0):g} s")
            break
        ns.append(n)
        ts.append(r["time"])
        print(f"  {n:>3} {r['time']:>8.2f}s {r['ops']:>11} {r['rss_self_kb'] / 2**10:>6.0f}MB")
        if r["time"] > kane_cap:
            break
    if len(ns) >= 2:
        c, k = power_law(ns, ts)
        print(f"  fit on n = {min(n for n in ns if 2 * n >= ns[-1])}..{ns[-1]}: t = {c:.3g} s * n^{k:.2f}")
        for n in (10, 20, 100, 1000):
            if n > ns[-1]:
                print(f"  EXTRAPOLATED (not measured): n = {n}: {c * n**k:.3g} s")
    if rows and ns:
        n_cmp = max(r[0] for r in rows if r[0] <= max(ns)) if any(r[0] <= max(ns) for r in rows) else None
        if n_cmp is not None:
            total, build = next((r[1], r[2]) for r in rows if r[0] == n_cmp)
            theirs = ts[ns.index(n_cmp)]
            print(f"  RATIO KanesMethod derivation / ncgen build() (equations as CasADi functions) at "
                  f"n = N = {n_cmp}: {theirs / build:.2f}; / ncgen model->C->library: {theirs / total:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
