"""Kernels timed alone in C, without Python: ncgen's compiled kernels in a C loop, and
Pinocchio's C++ ``rnea``, ``aba`` and ``crba`` in a C++ loop on the same model (issue 37:
where a call's time goes, the door or the kernel).

* :func:`kernel_ns` — a kernel of the CasADi calling convention (``fn(arg, res, iw, w, mem)``,
  the addresses a :class:`~ncgen.codegen.direct.DirectFunction` or the tree library's shim
  holds) called ``calls`` times by a C loop; CPU ns per call, min and median of ``rounds``.
* :func:`pinocchio_cpp_ns` — a C++ program (compiled once against the headers and library of
  the ``pin`` wheel, Eigen from CasADi's wheel) given a Pinocchio model on its input (its
  joints, placements and inertias: the model the Python bindings use) and one state; CPU ns per
  call of each algorithm, and its ``rnea``/``aba`` results, which the caller compares with
  Pinocchio's Python results to show it is the same model.

Both clocks are ``CLOCK_PROCESS_CPUTIME_ID``.  Binaries are cached under ``$NCGEN_CACHE_DIR``
(or the ncgen cache) by the hash of their source.
"""
from __future__ import annotations

import ctypes
import hashlib
import subprocess
from pathlib import Path

import numpy as np

LOOP = r"""
#include <time.h>
typedef int (*kernel_fn)(const double **, double **, long long *, double *, int);
static double now(void) { struct timespec t; clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t); return t.tv_sec + 1e-9 * t.tv_nsec; }
/* CPU seconds of n calls of fn; -1 when a call fails. */
double ncgen_kernel_seconds(void *fn, const double **arg, double **res, long long *iw, double *w, int mem, long n) {
    double t0 = now();
    for (long i = 0; i < n; i++)
        if (((kernel_fn)fn)(arg, res, iw, w, mem)) return -1.0;
    return now() - t0;
}
"""


def _cache() -> Path:
    from ncgen.codegen.compile_cache import cache_dir

    d = cache_dir() / "benchmark_kernel_alone"
    d.mkdir(parents=True, exist_ok=True)
    return d


def _built(source: str, suffix: str, command) -> Path:
    key = hashlib.sha256(source.encode() + " ".join(command("SRC", "OUT")).encode()).hexdigest()[:20]
    out = _cache() / f"{key}{suffix}"
    if not out.exists():
        src = _cache() / f"{key}{'.cpp' if suffix == '' else '.c'}"
        src.write_text(source)
        subprocess.run(command(str(src), str(out) + ".tmp"), check=True, capture_output=True, text=True)
        Path(str(out) + ".tmp").rename(out)
    return out


_LOOP_LIB: list = []


def kernel_ns(direct, calls: int, rounds: int) -> tuple[float, float]:
    """``(min, median)`` CPU ns per call of the kernel of ``direct`` (``_fn``, ``_args``) in a C loop."""
    if not _LOOP_LIB:
        lib = ctypes.CDLL(str(_built(LOOP, ".so", lambda s, o: ["cc", "-O2", "-shared", "-fPIC", s, "-o", o])))
        lib.ncgen_kernel_seconds.restype = ctypes.c_double
        lib.ncgen_kernel_seconds.argtypes = [ctypes.c_void_p] * 5 + [ctypes.c_int, ctypes.c_long]
        _LOOP_LIB.append(lib)
    f = _LOOP_LIB[0].ncgen_kernel_seconds
    fn = ctypes.cast(direct._fn, ctypes.c_void_p).value
    arg, res, iw, w, mem = direct._args
    times = []
    for _ in range(rounds):
        s = f(fn, arg, res, iw, w, mem, calls)
        if s < 0:
            raise RuntimeError("the kernel returned an error in the C loop")
        times.append(s / calls * 1e9)
    return min(times), float(np.median(times))


#: Joint kinds the C++ program builds (Pinocchio's short names), by code.
JOINT_KINDS = ("JointModelRX", "JointModelRY", "JointModelRZ", "JointModelPX", "JointModelPY", "JointModelPZ",
               "JointModelFreeFlyer", "JointModelRevoluteUnaligned", "JointModelPrismaticUnaligned",
               "JointModelRUBX", "JointModelRUBY", "JointModelRUBZ", "JointModelRevoluteUnboundedUnaligned")

PROGRAM = r"""// benchmarks/kernel_alone.py: Pinocchio's C++ rnea, aba and crba timed alone on a model read from stdin
#include <pinocchio/multibody.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <algorithm>
#include <cstdio>
#include <ctime>
#include <iostream>
#include <string>
#include <vector>
using namespace pinocchio;
static double now() { timespec t; clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t); return t.tv_sec + 1e-9 * t.tv_nsec; }
static JointModel joint(int kind, const Eigen::Vector3d &ax) {
  switch (kind) {
    case 0: return JointModelRX(); case 1: return JointModelRY(); case 2: return JointModelRZ();
    case 3: return JointModelPX(); case 4: return JointModelPY(); case 5: return JointModelPZ();
    case 6: return JointModelFreeFlyer(); case 7: return JointModelRevoluteUnaligned(ax);
    case 8: return JointModelPrismaticUnaligned(ax); case 9: return JointModelRUBX();
    case 10: return JointModelRUBY(); case 11: return JointModelRUBZ();
    default: return JointModelRevoluteUnboundedUnaligned(ax);
  }
}
static Eigen::VectorXd read(int n) { Eigen::VectorXd x(n); for (int i = 0; i < n; i++) std::cin >> x[i]; return x; }
int main() {
  Model model;
  long calls; int rounds, njoints;
  std::cin >> calls >> rounds;
  Eigen::Vector3d g = read(3);
  model.gravity.linear(g);
  std::cin >> njoints;
  for (int j = 1; j <= njoints; j++) {
    int parent, kind; std::cin >> parent >> kind;
    Eigen::Vector3d ax = read(3);
    Eigen::VectorXd r = read(9), p = read(3), mc = read(4), in = read(9);
    Eigen::Matrix3d R = Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(r.data()),
                    I = Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(in.data());
    JointIndex id = model.addJoint(parent, joint(kind, ax), SE3(R, Eigen::Vector3d(p)), "j" + std::to_string(j));
    model.appendBodyToJoint(id, Inertia(mc[0], Eigen::Vector3d(mc.tail<3>()), I), SE3::Identity());
  }
  Data data(model);
  Eigen::VectorXd q = read(model.nq), v = read(model.nv), a = read(model.nv), tau = read(model.nv);
  const char *names[3] = {"rnea", "aba", "crba"};
  for (int alg = 0; alg < 3; alg++) {
    std::vector<double> t;
    for (int r = 0; r < rounds; r++) {
      double t0 = now();
      for (long i = 0; i < calls; i++) {
        if (alg == 0) rnea(model, data, q, v, a);
        else if (alg == 1) aba(model, data, q, v, tau, Convention::LOCAL);
        else crba(model, data, q, Convention::LOCAL);
      }
      t.push_back((now() - t0) / calls * 1e9);
    }
    std::sort(t.begin(), t.end());
    printf("TIME %s %.3f %.3f\n", names[alg], t[0], t[t.size() / 2]);
  }
  Eigen::VectorXd r = rnea(model, data, q, v, a), b = aba(model, data, q, v, tau);
  printf("RNEA"); for (int i = 0; i < r.size(); i++) printf(" %.17g", r[i]); printf("\n");
  printf("ABA"); for (int i = 0; i < b.size(); i++) printf(" %.17g", b[i]); printf("\n");
}
"""


def _model_text(pm, q, v, a, tau, calls: int, rounds: int) -> str:
    """The program's input: the model's joints (parent, kind, axis, placement, inertia) and the state."""
    nums = lambda x: " ".join(repr(float(e)) for e in np.ravel(x))  # noqa: E731
    lines = [f"{calls} {rounds}", nums(pm.gravity.linear), str(pm.njoints - 1)]
    for jid in range(1, pm.njoints):
        jm, M, Y = pm.joints[jid], pm.jointPlacements[jid], pm.inertias[jid]
        kind = jm.shortname()
        if kind not in JOINT_KINDS:
            raise NotImplementedError(f"pinocchio_cpp_ns: joint kind {kind}")
        axis = jm.extract().axis if "Unaligned" in kind else np.zeros(3)
        lines.append(f"{pm.parents[jid]} {JOINT_KINDS.index(kind)} {nums(axis)} {nums(M.rotation)} "
                     f"{nums(M.translation)} {float(Y.mass)!r} {nums(Y.lever)} {nums(Y.inertia)}")
    lines += [nums(q), nums(v), nums(a), nums(tau)]
    return "\n".join(lines) + "\n"


#: What Pinocchio's CMake targets define for their users (lib/cmake/pinocchio): Boost limits of
#: its joint variant, and the explicit instantiations of the library — the compiled algorithms its
#: Python bindings call.
PINOCCHIO_DEFINES = ("-DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS", "-DBOOST_MPL_LIMIT_LIST_SIZE=30",
                     "-DBOOST_MPL_LIMIT_VECTOR_SIZE=30", "-DBOOST_FUSION_INVOKE_MAX_ARITY=12",
                     "-DPINOCCHIO_ENABLE_TEMPLATE_INSTANTIATION")


def pinocchio_cpp_ns(pm, q, v, a, tau, calls: int = 20000, rounds: int = 9) -> dict:
    """``{"rnea"|"aba"|"crba": (min, median) CPU ns per call, "rnea_result", "aba_result"}``
    of Pinocchio's C++ algorithms on the model ``pm`` at ``(q, v, a, tau)`` (module docstring)."""
    import casadi

    import pinocchio

    prefix = Path(pinocchio.__file__).resolve().parents[4]          # cmeel.prefix
    eigen = Path(casadi.__file__).parent / "include" / "eigen3"
    exe = _built(PROGRAM, "", lambda s, o: ["c++", "-O3", "-DNDEBUG", "-std=c++17", *PINOCCHIO_DEFINES,
                                            f"-I{prefix / 'include'}", f"-I{eigen}", s, "-o", o,
                                            f"-L{prefix / 'lib'}", "-lpinocchio_default",
                                            f"-Wl,-rpath,{prefix / 'lib'}"])
    out = subprocess.run([str(exe)], input=_model_text(pm, q, v, a, tau, calls, rounds), check=True,
                         capture_output=True, text=True).stdout
    res = {}
    for line in out.splitlines():
        head, *rest = line.split()
        if head == "TIME":
            res[rest[0]] = (float(rest[1]), float(rest[2]))
        else:
            res[head.lower() + "_result"] = np.array([float(x) for x in rest])
    return res

