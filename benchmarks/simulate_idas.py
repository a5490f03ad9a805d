"""IDAS simulation cost: VM vs compiled DAE, sparse vs dense linear solvers, chunking.

Model: a 3D chain of N uniform rr bars (shared end points, first end on the ground) falling
from a nearly horizontal zig-zag, 2 s at the default tolerances (rtol 1e-8, atol 1e-10),
output every 10 ms.  Run ``python benchmarks/simulate_idas.py [N ...]``; the compile cache is
a fresh temporary directory, so "compile" is the first build of the model's C package.
Times are wall-clock seconds of ``simulate`` (integration and output evaluation, without
the compile); they depend on the machine and its load.
"""
from __future__ import annotations

import os
import sys
import tempfile
import time

os.environ["NCGEN_CACHE_DIR"] = tempfile.mkdtemp(prefix="ncgen-bench-")

import ncgen as nc  # noqa: E402  (the cache directory must be set first)
import ncgen.runtime.idas_integrator as idas_integrator  # noqa: E402
from ncgen.runtime.dae import load_dae  # noqa: E402
from ncgen.runtime.idas import ChunkedIDAS  # noqa: E402


def chain(n: int) -> nc.Model:
    s = nc.System(f"chain{n}")
    prev = s.ground.point((0.0, 0.0, 0.0))
    for i in range(n):
        bar = s.add_bar(f"b{i}", mass=1.0, ends=[prev, (0.3 * (i + 1), 0.05 * (i % 2), 0.0)])
        prev = bar.end(1)
    return s.build()


def jacobian_density(model) -> str:
    dae, _ = load_dae(model, "vm")
    runner = ChunkedIDAS(dae, h=0.01, nu=0, hold="zoh", rtol=1e-8, atol=1e-10, max_steps=10,
                         linear_solver="csparse", expand=True)
    jac = runner.integrator(1).get_function("jacF")
    nnz = sum(jac.nnz_out(i) for i in range(jac.n_out()))
    n = 2 * model.nq + model.nc
    return f"{nnz}/{n * n} ({100 * nnz / n**2:.0f}%)"


def run(model, **kw) -> tuple[float, dict]:
    traj = nc.simulate(model, 2.0, 0.01, **kw)
    return traj.info["wall_time"], traj.info["stats"]


def main(sizes: list[int]) -> None:
    print(f"{'N':>3} {'nq':>4} {'nc':>3} {'jac nnz':>16} {'case':<28} {'time (s)':>9} {'steps':>6} {'jac':>5}")
    for n in sizes:
        model = chain(n)
        head = f"{n:>3} {model.nq:>4} {model.nc:>3} {jacobian_density(model):>16}"
        start = time.perf_counter()
        load_dae(model, "compiled")
        cases = [("compile (first build)", None, time.perf_counter() - start)]
        for backend in ("vm", "compiled"):
            for solver in ("csparse", "qr", "lapacklu"):
                cases.append((f"{backend}, {solver}", dict(backend=backend, linear_solver=solver), None))
        for name, kw, elapsed in cases:
            if kw is None:
                print(f"{head} {name:<28} {elapsed:9.2f}")
                continue
            elapsed, stats = run(model, **kw)
            print(f"{head} {name:<28} {elapsed:9.2f} {stats['nsteps']:6d} {stats['nlinsetups']:5d}")
        chunks = idas_integrator.CHUNKS
        try:
            idas_integrator.CHUNKS = 1
            elapsed, stats = run(model, backend="compiled")
            print(f"{head} {'compiled, csparse, 1 chunk':<28} {elapsed:9.2f} {stats['nsteps']:6d} "
                  f"{stats['nlinsetups']:5d}")
        finally:
            idas_integrator.CHUNKS = chunks


if __name__ == "__main__":
    main([int(a) for a in sys.argv[1:]] or [3, 10, 20])
