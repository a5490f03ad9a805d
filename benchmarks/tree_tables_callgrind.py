"""Instructions per state of the tree tables and of the flat per-robot kernels (issue 34), counted
by callgrind: robust to the load of a shared machine, where CPU times of sub-microsecond calls
spread by tens of percent (``benchmarks/tree_tables.py`` times them).

For each robot (example-robot-data's URDFs) one C program is written and compiled with the
package's own flags (``-O2``; a flat kernel at the flags ``compile_tree_function`` gives it): the
tree library's package (``write_tree_package``), the robot's tables as C arrays, its flat
RNEA, ABA and CRBA packages, and ``--states`` random states (unit quaternions, mimic followers
on their leaders).  The program runs one algorithm on one side over all states, the tables in
one batch call (``ncgen_trees_<alg>``), the flat kernel once per state; callgrind counts the
instructions of that function alone (``--toggle-collect``), printed per state with the ratio
tables / flat.  The program's outputs of both sides are compared (the sum of every result:
the same to 1e-12 relative; the script fails when they differ).

    python benchmarks/tree_tables_callgrind.py [--robots panda ur5 ur10 xarm7 talos] [--states 200]
    python benchmarks/tree_tables_callgrind.py --smoke        the UR5, 5 states
    python benchmarks/tree_tables_callgrind.py --robots panda ur5 --loops-cflags=-O1   the loops at -O1
    python benchmarks/tree_tables_callgrind.py --robots panda --time-rounds 7   also CPU time per state

``--time-rounds N``: the same programs timed without valgrind (CPU time per state, ``clock()``,
``--time-reps`` repetitions of the batch), tables and flat in turn in each of N rounds (the order
alternating), min and median over the rounds and their ratios.
"""
from __future__ import annotations

import argparse
import importlib.metadata as md
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

from common import machine  # noqa: E402

ROBOTS = {"panda": ("panda_description/urdf/panda.urdf", False), "ur5": ("ur_description/urdf/ur5_robot.urdf", False),
          "ur10": ("ur_description/urdf/ur10_robot.urdf", False), "xarm7": ("xarm_description/urdf/xarm7.urdf", False),
          "talos": ("talos_data/robots/talos_reduced.urdf", True)}
ALGORITHMS = ("rnea", "aba", "crba")

MAIN = r"""#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "data.h"
int ncgen_trees_rnea(const ncgen_tree *T, int n, const double *q, const double *v, const double *a, double *tau,
                     double *w);
int ncgen_trees_crba(const ncgen_tree *T, int n, const double *q, double *M, double *w);
int ncgen_trees_aba(const ncgen_tree *T, int n, const double *q, const double *v, const double *tau, double *a,
                    double *check, double *w);
long ncgen_trees_work_size(const ncgen_tree *T);
int FLAT_RNEA(const double **, double **, long long *, double *, int);
int FLAT_ABA(const double **, double **, long long *, double *, int);
int FLAT_CRBA(const double **, double **, long long *, double *, int);
static double out[NS * NI * NI + NS * NV], chk[2 * NS], fw[FLAT_W];

/* algorithm alg (0 RNEA, 1 ABA, 2 CRBA) over the NS states, the tables or the flat kernel */
__attribute__((noinline)) int bench(int alg, int tables, double *w) {
  int k, e = 0;
  double t = 0.0, p = 0.0;
  if (tables) {
    if (alg == 0) return ncgen_trees_rnea(&TREE, NS, Q, V, A, out, w);
    if (alg == 1) return ncgen_trees_aba(&TREE, NS, Q, V, TAU, out, chk, w);
    return ncgen_trees_crba(&TREE, NS, Q, out, w);
  }
  for (k = 0; k < NS; ++k) {
    const double *arg[5];
    double *res[2];
    arg[0] = &t;
    arg[1] = Q + k * NQ;
    if (alg == 2) {
      arg[2] = &p;
      res[0] = out + k * NI * NI;
      e |= FLAT_CRBA(arg, res, 0, fw, 0);
      continue;
    }
    arg[2] = V + k * NV;
    arg[3] = alg == 0 ? A + k * NV : TAU + k * NI;
    arg[4] = &p;
    res[0] = out + k * (alg == 0 ? NI : NV);
    res[1] = chk + 2 * k;
    e |= (alg == 0 ? FLAT_RNEA : FLAT_ABA)(arg, res, 0, fw, 0);
  }
  return e;
}

int main(int argc, char **argv) {
  int alg, tables, i, n;
  double s = 0.0, *w;
  if (argc != 3 && argc != 4) return 2;
  alg = atoi(argv[1]);
  tables = atoi(argv[2]);
  w = (double *)calloc((size_t)ncgen_trees_work_size(&TREE), sizeof(double));
  if (!w || bench(alg, tables, w)) return 1;
  if (argc == 4) {                              /* CPU ns per state over reps repetitions */
    int r, reps = atoi(argv[3]);
    clock_t c0 = clock();
    for (r = 0; r < reps; ++r) bench(alg, tables, w);
    printf("%.6g\n", 1e9 * (double)(clock() - c0) / CLOCKS_PER_SEC / ((double)reps * NS));
    free(w);
    return 0;
  }
  n = NS * (alg == 0 ? NI : alg == 1 ? NV : NI * NI);
  for (i = 0; i < n; ++i) s += out[i];
  printf("%.17g\n", s);
  free(w);
  return 0;
}
"""


def urdf_text(rel: str) -> str:
    for f in md.files("example-robot-data") or []:
        if str(f).endswith(rel):
            return Path(f.locate()).read_text()
    raise SystemExit(f"example-robot-data has no {rel}")


def c_array(ctype: str, name: str, values) -> str:
    values = list(values)
    text = ", ".join(repr(float(x)) if ctype == "double" else str(int(x)) for x in values) or "0"
    return f"static const {ctype} {name}[{max(1, len(values))}] = {{{text}}};"


def states(model, tables, n: int, rng):
    """``n`` random states (rows): q with unit quaternions and followers on their leaders, v, a, τ."""
    from ncgen.assembly.tree_dynamics import MimicMap

    js, mimic = model.joint_space, MimicMap(model)
    Q = rng.uniform(-1.0, 1.0, (n, tables.nq))
    for name, s in js.slices().items():
        if js.nq_joint[name] in (4, 7):
            Q[:, s.stop - 4:s.stop] /= np.linalg.norm(Q[:, s.stop - 4:s.stop], axis=1, keepdims=True)
    for i, (lead, k, off) in mimic.position.items():
        Q[:, i] = k * Q[:, lead] + off
    G = mimic.G
    return Q, rng.normal(size=(n, tables.ni)) @ G.T, rng.normal(size=(n, tables.ni)) @ G.T, \
        rng.normal(size=(n, tables.ni))


def write_robot(name: str, n_states: int, lib: Path, out: Path, cc: str) -> Path:
    """The program of ``name`` in ``out`` (compiled); returns its path."""
    import ncgen as nc
    from ncgen.assembly import tree_algorithms
    from ncgen.codegen.package import LARGE_FUNCTION_INSTRUCTIONS, write_package
    from ncgen.codegen.tree_check import O1_INSTRUCTIONS
    from ncgen.codegen.tree_tables import tree_tables
    from ncgen.runtime.tree_library import TREE_FIELDS

    rel, floating = ROBOTS[name]
    model = nc.System.from_urdf(urdf_text(rel), floating_base=floating).build()
    T = tree_tables(model)
    sizes = {"nb": T.nb, "nq": T.nq, "nv": T.nv, "ni": T.ni}
    lines = ['#include "ncgen_tree_tables.h"']
    lines += [c_array("int" if "int" in t else "double", f"A_{f}", T.arrays[f]) for t, f in TREE_FIELDS if "*" in t]
    lines.append("static const ncgen_tree TREE = {" + ", ".join(f"A_{f}" if "*" in t else str(sizes[f])
                                                                for t, f in TREE_FIELDS) + "};")
    for label, X in zip(("Q", "V", "A", "TAU"), states(model, T, n_states, np.random.default_rng(0))):
        lines.append(c_array("double", label, X.reshape(-1)))
    objects, defines, fw = [], [], 1
    for alg in ALGORITHMS:
        f = getattr(tree_algorithms, f"{alg}_function")(model)
        pkg = write_package(f"{name}_{alg}", [f], out / f"flat_{alg}")
        c_name = next(x["c_name"] for x in pkg.manifest["functions"] if x["name"] == f.name())
        flags = "-O1" if LARGE_FUNCTION_INSTRUCTIONS < f.n_instructions() <= O1_INSTRUCTIONS else "-O2"
        for src in pkg.manifest["build"]["sources"]:
            obj = out / f"{alg}_{src}.o"
            subprocess.run([cc, flags, "-fPIC", "-c", str(pkg.path / src), "-o", str(obj)], check=True)
            objects.append(str(obj))
        defines.append(f"-DFLAT_{alg.upper()}={c_name}")
        fw = max(fw, f.sz_w())
    lines.append(f"#define NS {n_states}\n#define NQ {T.nq}\n#define NV {T.nv}\n#define NI {T.ni}\n#define FLAT_W {fw}")
    (out / "data.h").write_text("\n".join(lines) + "\n")
    (out / "main.c").write_text(MAIN)
    exe = out / "bench"
    subprocess.run([cc, "-O2", "-std=c99", f"-I{out}", f"-I{lib}", *defines, str(out / "main.c"), *objects,
                    *(str(o) for o in sorted(lib.glob("*.o"))), "-lm", "-o", str(exe)], check=True)
    return exe


def instructions(exe: Path, alg: int, tables: int, n_states: int) -> tuple[float, float]:
    """(instructions per state in ``bench``, the program's result)."""
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "cg.out"
        run = subprocess.run(["valgrind", "--tool=callgrind", "--toggle-collect=bench", f"--callgrind-out-file={log}",
                              str(exe), str(alg), str(tables)], capture_output=True, text=True, check=True)
        total = next(int(line.split()[1]) for line in log.read_text().splitlines()
                     if line.startswith(("summary:", "totals:")))
    return total / n_states, float(run.stdout)


def cpu_times(exe: Path, alg: int, rounds: int, reps: int) -> dict[int, list[float]]:
    """CPU ns per state of the tables (1) and the flat kernel (0), interleaved over ``rounds``."""
    times: dict[int, list[float]] = {1: [], 0: []}
    for r in range(rounds):
        for tables in ((1, 0) if r % 2 == 0 else (0, 1)):
            run = subprocess.run([str(exe), str(alg), str(tables), str(reps)], capture_output=True, text=True,
                                 check=True)
            times[tables].append(float(run.stdout))
    return times


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--robots", nargs="+", default=list(ROBOTS), choices=list(ROBOTS))
    ap.add_argument("--states", type=int, default=200)
    ap.add_argument("--smoke", action="store_true")
    ap.add_argument("--loops-cflags", default="-O2", help="flags of the tables' loops (tree_tables.c; the tree "
                    "library's units: -O1, the inverse unit -O3: ncgen/runtime/tree_library.py UNIT_CFLAGS)")
    ap.add_argument("--time-rounds", type=int, default=0, help="also time each side (CPU, interleaved rounds)")
    ap.add_argument("--time-reps", type=int, default=50, help="batches per timed run")
    a = ap.parse_args()
    if a.smoke:
        a.robots, a.states = ["ur5"], 5
    if shutil.which("valgrind") is None:
        raise SystemExit("valgrind is not on PATH: callgrind counts the instructions")
    from ncgen.codegen.compiler import CANDIDATES
    from ncgen.codegen.tree_kernels import write_tree_package

    cc = os.environ.get("CC") or next((shutil.which(c) for c in CANDIDATES if shutil.which(c)), None)
    if cc is None:
        raise SystemExit("no C compiler on PATH")
    print(machine())
    differ = []
    with tempfile.TemporaryDirectory() as tmp:
        lib = write_tree_package(Path(tmp) / "lib").path
        for src, flag in (("ncgen_trees_kernels_0.c", "-O2"), ("tree_tables.c", a.loops_cflags)):
            subprocess.run([cc, *flag.split(), "-fPIC", "-std=c99", f"-I{lib}", "-c", str(lib / src), "-o",
                            str(lib / f"{src}.o")], check=True)
        for name in a.robots:
            out = Path(tmp) / name
            out.mkdir()
            exe = write_robot(name, a.states, lib, out, cc)
            print(f"\n=== {name}: instructions per state over {a.states} states (callgrind)")
            for i, alg in enumerate(ALGORITHMS):
                (t, yt), (f, yf) = instructions(exe, i, 1, a.states), instructions(exe, i, 0, a.states)
                agree = abs(yt - yf) <= 1e-12 * max(1.0, abs(yf))
                print(f"{name} {alg}: tables {t:,.0f}, flat {f:,.0f}; results {'agree' if agree else 'DIFFER'}")
                print(f"RATIO {name} {alg} instructions: tables / flat = {t / f:.2f}")
                if not agree:
                    differ.append(f"{name} {alg}: tables {yt!r}, flat {yf!r}")
                if a.time_rounds:
                    c = cpu_times(exe, i, a.time_rounds, a.time_reps)
                    lo = {k: min(v) for k, v in c.items()}
                    med = {k: statistics.median(v) for k, v in c.items()}
                    print(f"{name} {alg}: CPU ns per state min / median: tables {lo[1]:.0f} / {med[1]:.0f}, "
                          f"flat {lo[0]:.0f} / {med[0]:.0f}; RATIO min {lo[1] / lo[0]:.2f}, median {med[1] / med[0]:.2f}")
    print(f"load average at end: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    if differ:
        raise SystemExit(f"the tables and the flat kernels differ: {'; '.join(differ)}")


if __name__ == "__main__":
    main()
