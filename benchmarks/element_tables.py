"""Element tables vs today's flat code: chains of N bars (benchmarks/common.py, shared points),
from ``System`` to a loaded library and an evaluated ``A = ∂Φ/∂q`` (issue 34).

Per N and round, interleaved (the order of the two paths alternates between rounds):

* build: ``chain_system(N).build()`` (the same for both paths, shown once);
* tables, empty cache: the element library compiled into a fresh compile cache (the same for
  every N: the kernels of the shipped kinds and the loops), then as below;
* tables, cached: ``model_tables(model)`` (pack the model's tables), the cached library
  loaded, ``A(q)`` evaluated — no compiler call;
* flat, empty cache: ``compile_direct`` of ``model.functions["A"]`` (today's flat, inlined
  expression of the whole model: CasADi C generation and gcc) into a fresh cache, ``A(q)``;
* flat, cached: the same with its library in the cache (C generation and hashing remain);
* one evaluation of ``A(q)``: the element library (ctypes call, loops over the tables) vs
  the flat kernel (``DirectFunction``), best of many calls.

Wall-clock seconds (CPU seconds of the process and its children in brackets), min and median
over the rounds.  The machine is shared: the load average is printed at start and end.

    python benchmarks/element_tables.py                 N = 10, 40, 160, 1000, 3 rounds
    python benchmarks/element_tables.py --smoke         N = 3, 6, 1 round
    python benchmarks/element_tables.py --sizes 10 40 --rounds 2
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
from pathlib import Path

import numpy as np

from common import best_time, chain_system, in_turn, machine, timed

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))


def tables_path(model, q, fresh_cache: str | None):
    from ncgen.codegen.model_tables import model_tables
    from ncgen.runtime import table_library

    if fresh_cache is not None:
        os.environ["NCGEN_CACHE_DIR"] = fresh_cache
        table_library._LOADED.clear()
    tf = table_library.TableFunctions(model_tables(model), table_library.load_element_library())
    return tf, tf.A(q)


def flat_path(model, q, fresh_cache: str | None):
    from ncgen.codegen.direct import compile_direct

    if fresh_cache is not None:
        os.environ["NCGEN_CACHE_DIR"] = fresh_cache
    f = compile_direct("flat_A", model.functions["A"])
    return f, f(0.0, q, model.p0)[0]


def fmt(samples) -> str:
    walls, cpus = [s[0] for s in samples], [s[1] for s in samples]
    return (f"min {min(walls):8.3f} s (CPU {min(cpus):7.3f}), median {statistics.median(walls):8.3f} s "
            f"(CPU {statistics.median(cpus):7.3f})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[10, 40, 160, 1000])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--smoke", action="store_true", help="N = 3, 6, one round")
    args = ap.parse_args()
    sizes, rounds = ([3, 6], 1) if args.smoke else (args.sizes, args.rounds)
    print(machine())
    keep = os.environ.get("NCGEN_CACHE_DIR")
    results = {n: {k: [] for k in ("build", "tables cold", "tables cached", "flat cold", "flat cached")}
               for n in sizes}
    calls = {n: {} for n in sizes}
    with tempfile.TemporaryDirectory(prefix="ncgen-bench-tables-") as tmp:
        for r in range(rounds):
            for n in sizes:
                wall, cpu, model = timed(lambda: chain_system(n).build())
                results[n]["build"].append((wall, cpu))
                q = model.q0 + 0.01 * np.random.default_rng(r).standard_normal(model.nq)
                def first_A(path, run):
                    wall, cpu, _ = timed(lambda: run(model, q, f"{tmp}/{path}-{n}-{r}"))
                    results[n][f"{path} cold"].append((wall, cpu))
                    wall, cpu, (fn, A) = timed(lambda: run(model, q, None))
                    results[n][f"{path} cached"].append((wall, cpu))
                    return fn, A

                done = in_turn(r, {"tables": lambda: first_A("tables", tables_path),
                                   "flat": lambda: first_A("flat", flat_path)})
                (tf, A_tables), (flat, A_flat) = done["tables"], done["flat"]
                calls[n]["tables"] = best_time(lambda: tf.A(q), 200)[0]
                calls[n]["flat"] = best_time(lambda: flat(0.0, q, model.p0), 200)[0]
                import casadi as ca
                dense_flat = np.array(ca.DM(flat.function.sparsity_out(0), A_flat))
                err = np.abs(tf.tables.dense_A(A_tables) - dense_flat).max()
                print(f"round {r + 1}, N = {n}: max |A_tables - A_flat| = {err:.1e}", flush=True)
    if keep is None:
        os.environ.pop("NCGEN_CACHE_DIR", None)
    for n in sizes:
        print(f"\n=== chain of N = {n} bars: System -> loaded library -> A(q) evaluated, {rounds} round(s)")
        for k, v in results[n].items():
            print(f"  {k:14s} {fmt(v)}")
        cold = [b[0] + t[0] for b, t in zip(results[n]["build"], results[n]["tables cold"])]
        print(f"  System -> A by tables, empty cache (build + tables cold): min {min(cold):.3f} s")
        for what in ("cold", "cached"):
            t = min(s[0] for s in results[n][f"tables {what}"])
            f = min(s[0] for s in results[n][f"flat {what}"])
            print(f"RATIO flat / tables, {what} cache, N = {n}: {f / t:.2f} (wall, min; build excluded)")
        print(f"  one A(q): tables {calls[n]['tables'] * 1e6:.1f} us, flat {calls[n]['flat'] * 1e6:.1f} us")
        print(f"RATIO tables / flat, one A(q) evaluation, N = {n}: {calls[n]['tables'] / calls[n]['flat']:.2f}")
    print(f"\nload average at the end: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
