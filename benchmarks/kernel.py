"""Kernel: one evaluation of the DAE residual and of its Jacobian — generated C vs CasADi's
virtual machine vs NumPy.

Model: the chain of N bars (benchmarks/common.py).  The DAE is the one IDAS integrates
(``model.functions["dae"]``: x = [q; v], z = [a; λ], ode = [v; a],
alg = [M a + Aᵀλ − F; A a − γ + 2αΦ̇ + β²Φ]); the Jacobian is ∂(ode, alg)/∂(x, z), as IDAS needs it.  Three
SX functions — ``residual``, ``jacobian`` and ``both`` (residual and Jacobian from one
evaluation, sharing subexpressions) — are timed

* as generated C: written by ``ncgen.codegen.write_package`` and called in a C loop
  (column "C": the generated code alone, gcc -O2), and loaded with ``casadi.external`` and
  called by CasADi (column "C ext": adds CasADi's per-call overhead for external functions,
  which dominates small kernels);
* on CasADi's virtual machine (the SX functions themselves);
* in NumPy: the same equations written by hand for the chain with dense arrays, checked
  against CasADi's values.

C and VM are evaluated ``BATCH`` times in one call of a serial ``map`` (CasADi's loop, no
Python between evaluations) of the function followed by the sum of its outputs (scalar
output: no batch of outputs to allocate; the sum adds one addition per output nonzero to
C and VM alike), NumPy in a Python loop (that is how NumPy code runs).
Times: microseconds per evaluation, best of ``--repeat``.

The looped mode times the form of large models instead: the residual and the Jacobian
rerolled into loops of short kernels (``ncgen.codegen.reroll``, from 1000 SX instructions
on, as ``nc.generate`` does for models over 40 k instructions) against the same functions
as straight-line code at -O0 and -O2, each called in a C loop that writes its outputs, and
the VM; it prints the compile times too (straight-line -O2 takes minutes beyond ~300 bars).

    python benchmarks/kernel.py                    N = 5, 20, 50
    python benchmarks/kernel.py --looped           N = 20, 300, 1000
    python benchmarks/kernel.py [--looped] --smoke N = 3, few evaluations (CI)
"""
from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import casadi as ca
import numpy as np

from common import L, best_time, chain_system, machine

from ncgen.codegen.looped import LARGE_MODEL_REROLL

BATCH = 2000
#: SX instructions of work per timing repetition in the looped mode (sets its loop counts).
LOOP_INSTRUCTIONS = 2e7


def kernels(model) -> list[ca.Function]:
    """``residual``, ``jacobian`` and ``both`` (see the module docstring)."""
    dae = model.functions["dae"]
    t, x, z, u, p = (ca.SX.sym(n, dae.sparsity_in(i)) for i, n in enumerate(dae.name_in()))
    ode, alg = dae(t, x, z, u, p)
    res = ca.vertcat(ode, alg)
    jac = ca.jacobian(res, ca.vertcat(x, z))
    names = ["t", "x", "z", "u", "p"]
    return [ca.Function("residual", [t, x, z, u, p], [res], names, ["res"]),
            ca.Function("jacobian", [t, x, z, u, p], [jac], names, ["jac"]),
            ca.Function("both", [t, x, z, u, p], [res, jac], names, ["res", "jac"])]


def summed(f: ca.Function) -> ca.Function:
    """``f`` followed by the sum of all its output nonzeros: the same work with a scalar
    output, so that a batch of evaluations does not allocate a batch of outputs."""
    ins = f.sx_in()
    total = sum(ca.sum1(o.nz[:]) for o in f.call(ins))
    return ca.Function(f"{f.name()}_sum", ins, [total], f.name_in(), ["sum"])


class NumpyChain:
    """The chain's DAE residual and Jacobian in NumPy (dense; see the module docstring)."""

    def __init__(self, model):
        n = model.nc
        self.n, self.nq = n, model.nq
        self.M = model.M
        self.F = model.F(model.q0, model.v0)            # gravity only: constant
        self.alpha, self.beta = model.baumgarte
        D = np.eye(3 * n)                                # bar vectors U = D q (point k minus point k-1)
        D[3:, :-3] -= np.eye(3 * (n - 1))
        self.D = D

    def _B(self, X):
        """N × 3N: row k holds X_k (3 values) in block k."""
        B = np.zeros((self.n, 3 * self.n))
        B[np.repeat(np.arange(self.n), 3), np.arange(3 * self.n)] = X.reshape(-1)
        return B

    def residual(self, x, z, jacobian: bool = False):
        """``[ode; alg]`` of ``dae`` (x = [q; v], z = [a; λ]) and, if asked, its Jacobian."""
        nq, n = self.nq, self.n
        q, v, a, lam = x[:nq], x[nq:], z[:nq], z[nq:]
        U, dU = (self.D @ q).reshape(-1, 3), (self.D @ v).reshape(-1, 3)
        A = 2 * self._B(U) @ self.D
        phi = np.sum(U * U, axis=1) - L**2
        gamma = -2 * np.sum(dU * dU, axis=1)
        res = np.concatenate([v, a, self.M @ a + A.T @ lam - self.F,
                              A @ a - gamma + 2 * self.alpha * (A @ v) + self.beta**2 * phi])
        if not jacobian:
            return res
        Bdv = self._B(dU) @ self.D
        J = np.zeros((3 * nq + n, 3 * nq + n))
        J[:nq, nq:2 * nq] = np.eye(nq)
        J[nq:2 * nq, 2 * nq:3 * nq] = np.eye(nq)
        J[2 * nq:3 * nq, :nq] = 2 * self.D.T @ (np.repeat(lam, 3)[:, None] * self.D)
        J[2 * nq:3 * nq, 2 * nq:3 * nq] = self.M
        J[2 * nq:3 * nq, 3 * nq:] = A.T
        J[3 * nq:, :nq] = 2 * self._B((self.D @ a).reshape(-1, 3)) @ self.D + 4 * self.alpha * Bdv + self.beta**2 * A
        J[3 * nq:, nq:2 * nq] = 2 * self.alpha * A + 4 * Bdv
        J[3 * nq:, 2 * nq:3 * nq] = A
        return res, J


def compiled(functions, name: str, directory) -> dict[str, ca.Function]:
    """The functions as a generated C package in ``directory``, compiled (default flags)
    and loaded with ``casadi.external``."""
    from ncgen.codegen import load_functions, write_package

    return load_functions(write_package(name, functions, directory), backend="compiled")


HARNESS = """#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "{name}.h"
static const casadi_real x[] = {{{x}}}, z[] = {{{z}}};
static casadi_real out[{sz_out}];
static double now(void) {{ struct timespec t; clock_gettime(CLOCK_MONOTONIC, &t); return t.tv_sec + 1e-9 * t.tv_nsec; }}
int main(void) {{
  casadi_real t = 0, best, start;
  casadi_int n_arg, n_res, n_iw, n_w, *iw;
  const casadi_real **arg;
  casadi_real **res, *w;
  long k;
  int rep, mem;
{calls}
  return 0;
}}
"""
CALL = """  {fn}_work(&n_arg, &n_res, &n_iw, &n_w);
  arg = calloc(n_arg + 5, sizeof *arg); res = calloc(n_res + 1, sizeof *res);
  iw = calloc(n_iw + 1, sizeof *iw); w = calloc(n_w + 1, sizeof *w);
  arg[0] = &t; arg[1] = x; arg[2] = z;
{outputs}  mem = {fn}_checkout();
  for (best = 1e30, rep = 0; rep < {repeat}; ++rep) {{
    start = now();
    for (k = 0; k < {loops}; ++k) {{ {fn}(arg, res, iw, w, mem); t += 1e-300; }}
    if (now() - start < best) best = now() - start;
  }}
  {fn}_release(mem);
  free(arg); free(res); free(iw); free(w);
  printf("{label} %.6f\\n", best / {loops} * 1e6);
"""


def from_c(pkg_dir, name: str, timed: list[ca.Function], x, z, loops: int | dict[str, int], repeat: int,
           cflags: str = "-O2") -> dict[str, float]:
    """Microseconds per evaluation of each function of ``timed`` called in a C loop (the
    generated code alone, compiled with ``cflags`` together with the package's sources);
    each output is written to its own buffer.  ``loops``: evaluations per repetition, one
    number or one per function name.  Empty without a C compiler."""
    exe = build_harness(pkg_dir, name, timed, x, z, loops, repeat, cflags)
    return {} if exe is None else run_harness(exe)


def run_harness(exe: Path) -> dict[str, float]:
    """Run a program of :func:`build_harness`: microseconds per evaluation by function name."""
    out = subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout
    return {line.split()[0]: float(line.split()[1]) for line in out.splitlines()}


def build_harness(pkg_dir, name: str, timed: list[ca.Function], x, z, loops: int | dict[str, int], repeat: int,
                  cflags: str = "-O2") -> Path | None:
    """The timing program of :func:`from_c`, compiled in ``pkg_dir``; None without a C compiler."""
    cc = shutil.which("gcc") or shutil.which("cc")
    if cc is None:
        return None
    calls = []
    for f in timed:
        offsets = np.cumsum([0] + [f.nnz_out(i) for i in range(f.n_out())])
        outputs = "".join(f"  res[{i}] = out + {offsets[i]};\n" for i in range(f.n_out()))
        n = loops if isinstance(loops, int) else loops[f.name()]
        calls.append(CALL.format(outputs=outputs, repeat=repeat, loops=n, fn=f"{name}_{f.name()}", label=f.name()))
    text = HARNESS.format(name=name, x=", ".join(repr(float(v)) for v in x), z=", ".join(repr(float(v)) for v in z) or "0",
                          sz_out=max(1, max(f.nnz_out() for f in timed)), calls="".join(calls))
    (pkg_dir / "harness.c").write_text(text)
    sources = [p.name for p in sorted(pkg_dir.glob(f"{name}_kernels_*.c"))]
    subprocess.run([cc, *cflags.split(), "-o", "harness", "harness.c", *sources, "-lm"], cwd=pkg_dir, check=True)
    return pkg_dir / "harness"


def per_call(f: ca.Function, args, batch: int, repeat: int) -> float:
    """Microseconds per evaluation of ``f`` (a :func:`summed` kernel): ``batch`` evaluations
    in one call of ``f.map(batch, "serial")``."""
    mapped = f.map(batch, "serial")
    cols = [np.tile(np.asarray(a, float).reshape(-1, 1), (1, batch)) for a in args]
    secs, _ = best_time(lambda: mapped(*cols), repeat)
    return secs / batch * 1e6


def point(model) -> tuple[np.ndarray, np.ndarray]:
    """The evaluation point: x near the initial state, z random (fixed seed)."""
    rng = np.random.default_rng(0)
    x = np.concatenate([model.q0 + 0.01 * rng.standard_normal(model.nq), rng.standard_normal(model.nq)])
    return x, rng.standard_normal(model.nq + model.nc)


def run(n: int, batch: int, repeat: int) -> None:
    model = chain_system(n).build()
    functions = kernels(model)
    timed = [summed(f) for f in functions]
    x, z = point(model)
    name = f"kernel_chain{n}"
    with tempfile.TemporaryDirectory(prefix="ncgen-kernel-") as tmp:
        c = compiled(functions + timed, name, Path(tmp) / name)
        native = from_c(Path(tmp) / name, name, timed, x, z, loops=batch, repeat=repeat)
    args = [0.0, x, z, np.zeros(model.nu), model.p0]
    ref_res, ref_jac = (np.array(ca.densify(o)) for o in functions[2](*args))
    npc = NumpyChain(model)
    res, jac = npc.residual(x, z, jacobian=True)
    check = max(np.max(np.abs(res - ref_res.ravel())), np.max(np.abs(jac - ref_jac)))
    jc = np.array(ca.densify(c["both"](*args)[1]))
    print(f"\n=== chain of N = {n} bars: nx = {2 * model.nq}, nz = {model.nq + model.nc}, Jacobian nnz "
          f"{functions[1].nnz_out(0)} of {jac.size} ===")
    print(f"  NumPy vs CasADi values: max |difference| = {check:.1e}; C vs VM Jacobian: "
          f"{np.max(np.abs(jc - ref_jac)):.1e}")
    print(f"  {'kernel':<10} {'instructions':>12} {'C (us)':>10} {'C ext (us)':>11} {'VM (us)':>10} "
          f"{'NumPy (us)':>11} {'VM/C':>7} {'NumPy/C':>8}")
    numpy_calls = {"residual": lambda: npc.residual(x, z), "jacobian": lambda: npc.residual(x, z, True),
                   "both": lambda: npc.residual(x, z, True)}
    for f, g in zip(functions, timed):
        name = f.name()
        t_ext = per_call(c[g.name()], args, batch, repeat)
        t_c = native.get(g.name(), t_ext)
        t_vm = per_call(g, args, batch, repeat)
        loops = max(1, batch // 10)
        secs, _ = best_time(lambda: [numpy_calls[name]() for _ in range(loops)], repeat)
        t_np = secs / loops * 1e6
        print(f"  {name:<10} {f.n_instructions():>12} {t_c:>10.2f} {t_ext:>11.2f} {t_vm:>10.2f} {t_np:>11.2f} "
              f"{t_vm / t_c:>7.1f} {t_np / t_c:>8.1f}")
        if name == "both":
            print(f"  RATIO VM / generated C, residual + Jacobian: {t_vm / t_c:.1f}; NumPy / generated C: "
                  f"{t_np / t_c:.1f}")


def run_looped(n: int, repeat: int, flat_cap: int, loop_instructions: float, reroll: int) -> None:
    """Looped against straight-line generated C for the residual and the Jacobian of the
    N-bar chain, in a C loop (see the module docstring), and the VM.  ``reroll``: the
    functions are rerolled from this many SX instructions on (large models: 1000).  Needs a
    C compiler (loading the looped package compiles it)."""
    from ncgen.codegen import load_functions, write_package

    model = chain_system(n).build()
    functions = kernels(model)[:2]
    x, z = point(model)
    args = [0.0, x, z, np.zeros(model.nu), model.p0]
    loops = {f.name(): max(5, int(loop_instructions / f.n_instructions())) for f in functions}
    name = f"looped_chain{n}"
    times, builds = {}, {}
    with tempfile.TemporaryDirectory(prefix="ncgen-looped-") as tmp:
        looped = write_package(name, functions, Path(tmp) / "looped", reroll_instructions=reroll)
        n_loops = sum(len(re.findall(r"for \(i=0; i<\d+; \+\+i\)", p.read_text()))
                      for p in looped.path.glob("*_kernels_*.c"))
        c = load_functions(looped, backend="compiled")
        check = max(float(ca.mmax(ca.fabs(c[f.name()](*args) - f(*args)))) for f in functions)
        variants = [("looped -O2", looped, "-O2"), ("flat -O0", None, "-O0")]
        variants += [("flat -O2", None, "-O2")] if n <= flat_cap else []
        flat = None
        for label, pkg, flags in variants:
            if pkg is None:
                flat = flat or write_package(name, functions, Path(tmp) / "flat", reroll_instructions=None)
                pkg = flat
            start = time.perf_counter()
            exe = build_harness(pkg.path, name, functions, x, z, loops, repeat, flags)
            builds[label] = time.perf_counter() - start
            times[label] = run_harness(exe)
    vm = {f.name(): per_call(summed(f), args, loops[f.name()], repeat) for f in functions}
    labels = [label for label, *_ in variants]
    print(f"\n=== looped vs straight-line C: chain of N = {n} bars, nx = {2 * model.nq}, "
          f"nz = {model.nq + model.nc} ===")
    print(f"  looped vs SX values: max |difference| = {check:.1e}; loops in the looped C: {n_loops}")
    print("  compile (s, harness + package sources): " + ", ".join(f"{k} {v:.1f}" for k, v in builds.items())
          + ("" if n <= flat_cap else f"; flat -O2 skipped (N > --flat-cap {flat_cap})"))
    print(f"  {'kernel':<10} {'SX instr.':>10} " + " ".join(f"{k + ' (us)':>16}" for k in labels)
          + f" {'VM (us)':>10} {'flat-O0/looped':>15} {'VM/looped':>10}")
    for f in functions:
        t = {k: times[k][f.name()] for k in labels}
        print(f"  {f.name():<10} {f.n_instructions():>10} " + " ".join(f"{t[k]:>16.2f}" for k in labels)
              + f" {vm[f.name()]:>10.2f} {t['flat -O0'] / t['looped -O2']:>15.2f} {vm[f.name()] / t['looped -O2']:>10.1f}")
        if "flat -O2" in t:
            print(f"  RATIO looped -O2 / flat -O2, {f.name()}: {t['looped -O2'] / t['flat -O2']:.2f}")
        print(f"  RATIO VM / looped -O2, {f.name()}: {vm[f.name()] / t['looped -O2']:.1f}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--smoke", action="store_true", help="tiny: runs in seconds (CI)")
    parser.add_argument("--sizes", type=int, nargs="+",
                        help="numbers of bars (default 5 20 50; with --looped 20 300 1000)")
    parser.add_argument("--repeat", type=int, default=5, help="timing repetitions; the fastest counts")
    parser.add_argument("--looped", action="store_true",
                        help="time looped (rerolled) against straight-line generated C, the form of large models")
    parser.add_argument("--flat-cap", type=int, default=300,
                        help="with --looped: largest N whose straight-line code is compiled at -O2 "
                             "(minutes of gcc beyond ~300 bars)")
    args = parser.parse_args(argv)
    print(machine())
    start = time.perf_counter()
    if args.looped:
        sizes = args.sizes or ([3] if args.smoke else [20, 300, 1000])
        for n in sizes:
            run_looped(n, 1 if args.smoke else args.repeat, args.flat_cap, 2e4 if args.smoke else LOOP_INSTRUCTIONS,
                       100 if args.smoke else LARGE_MODEL_REROLL)
    else:
        sizes = args.sizes or ([3] if args.smoke else [5, 20, 50])
        batch, repeat = (20, 1) if args.smoke else (BATCH, args.repeat)
        for n in sizes:
            run(n, batch, repeat)
    print(f"\n(total {time.perf_counter() - start:.1f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
