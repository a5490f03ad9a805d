"""Joint space from Python: ncgen's forward dynamics of a URDF arm vs ``pinocchio.aba``, and a
humanoid URDF from file to loaded compiled library.

Robot: the Panda of example-robot-data (7 arm joints + 2 fingers, the mimic tag dropped so that
both engines see the same 9-DOF model).  One state, the same in both engines.  Timed, in µs
per call, best of ``--repeat`` batches of ``--calls`` calls from Python:

* ``pinocchio.aba(model, data, q, v, tau)``: joint space in and out (Featherstone's ABA);
* ncgen's joint-space kernel (``k = nc.joint_forward_dynamics_kernel(model)``; ``k(qj, vj,
  u)``): joint space in and out in one compiled C function called through ctypes with
  preallocated buffers (the recursive world-frame form: composite inertias and a written-out
  Cholesky of the 9 × 9 joint-space mass matrix) — "joint kernel", the figure of the target
  (≤ 2× ``pinocchio.aba``);
* the same with the inputs already in its buffers (``k.direct.call``) — "joint kernel, call
  only" — and the same C function in a C loop (a small harness compiled here, timed with
  ``clock_gettime``) — "joint kernel, C loop": the kernel itself (default flags, -O2; and
  compiled with ``cflags="-O3 -march=native"``, for a local cache only: such a library is
  not portable);
* the same through ``casadi.external``, and ``nc.joint_forward_dynamics`` (validated inputs,
  the same kernel);
* the previous compiled paths: natural coordinates in and out
  (``forward_dynamics_kernel``: Schur complement of the constant mass matrix, sparse LDLᵀ)
  and its joint-space wrapper (``forward_dynamics_kernel(joint_space=True)``: tree map, the
  same solve, ``a_j = J q̈ + J̇ q̇``);
* a trivial compiled function (``y = 2x``, 3 entries) directly and through
  ``casadi.external``: the call overheads themselves.

Then the humanoid: Talos (``talos_reduced.urdf``, floating base, 33 bodies), with an empty
build cache, seconds per stage: (1) URDF file to the loaded compiled joint-space forward
dynamics (``System.from_urdf`` → ``build`` → ``joint_forward_dynamics_kernel``) — the figure
of the target (< 30 s), its accelerations checked against ``pinocchio.aba``; (2) the whole
simulation package (``nc.generate(compile=True)`` → ``load_functions``), for comparison
(``--skip-package`` leaves it out).

    python benchmarks/joint_space.py [--calls 2000] [--repeat 5] [--skip-humanoid] [--skip-package] [--smoke]
"""
from __future__ import annotations

import argparse
import importlib.metadata as md
import re
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import casadi as ca  # noqa: E402

import ncgen as nc  # noqa: E402
from common import best_time, machine  # noqa: E402
from ncgen.runtime.dynamics_at_state import forward_dynamics_kernel  # noqa: E402


def robot_file(rel: str) -> Path:
    for f in md.files("example-robot-data") or []:
        if str(f).endswith(rel):
            return Path(f.locate())
    raise SystemExit(f"example-robot-data has no {rel}; pip install example-robot-data")


def per_call(fn, calls: int, repeat: int) -> float:
    def batch():
        for _ in range(calls):
            fn()
    t, _ = best_time(batch, repeat)
    return t / calls * 1e6


def trivial(calls, repeat):
    from ncgen.codegen.compile_cache import compile_package
    from ncgen.codegen.direct import DirectFunction
    from ncgen.codegen.package import write_package

    x = ca.SX.sym("x", 3)
    f = ca.Function("twice", [x], [2 * x])
    with tempfile.TemporaryDirectory() as tmp:
        pkg = write_package("bench_trivial", [f], Path(tmp) / "pkg")
        built = compile_package(pkg)
        c_name = pkg.manifest["functions"][0]["c_name"]
    d = DirectFunction(built.path, c_name, f)
    ext = ca.external(c_name, str(built.path))
    y = np.ones(3)
    return per_call(lambda: d(y), calls, repeat), per_call(d.call, calls, repeat), \
        per_call(lambda: ext(y), max(1, calls // 10), repeat)


C_LOOP = r"""
#include <time.h>
typedef int (*kernel_t)(const double**, double**, long long*, double*, int);
double ncgen_c_loop(kernel_t f, const double** arg, double** res, long long* iw, double* w, int mem, long n) {
  struct timespec a, b;
  clock_gettime(CLOCK_MONOTONIC, &a);
  for (long i = 0; i < n; ++i) f(arg, res, iw, w, mem);
  clock_gettime(CLOCK_MONOTONIC, &b);
  return ((double)(b.tv_sec - a.tv_sec) + 1e-9 * (double)(b.tv_nsec - a.tv_nsec)) / (double)n;
}
"""


def c_loop(direct, calls: int, repeat: int) -> float:
    """µs per call of ``direct``'s C function called ``calls`` times in a C loop (best of ``repeat``)."""
    import ctypes
    import subprocess

    from ncgen.codegen.compiler import find_compiler

    with tempfile.TemporaryDirectory() as tmp:
        src, lib = Path(tmp) / "loop.c", Path(tmp) / "libloop.so"
        src.write_text(C_LOOP)
        subprocess.run([*find_compiler().argv, "-O2", "-fPIC", "-shared", str(src), "-o", str(lib)], check=True)
        h = ctypes.CDLL(str(lib))
    h.ncgen_c_loop.restype = ctypes.c_double
    h.ncgen_c_loop.argtypes = [ctypes.c_void_p] * 5 + [ctypes.c_int, ctypes.c_long]
    fn = ctypes.cast(direct._fn, ctypes.c_void_p)
    return min(h.ncgen_c_loop(fn, *direct._args, calls) for _ in range(repeat)) * 1e6


def panda_pair():
    import pinocchio as pin

    text = re.sub(r"<mimic[^>]*/>", "", robot_file("panda_description/urdf/panda.urdf").read_text())
    return nc.System.from_urdf(text).build(), pin.buildModelFromXML(text)


def pin_state(model, pm, seed=0):
    """A random state in both conventions: ``(qp, vp, taup)`` and ``(qj, vj, u)``."""
    import pinocchio as pin

    rng = np.random.default_rng(seed)
    qp = pin.randomConfiguration(pm, -np.ones(pm.nq), np.ones(pm.nq))
    vp, tp = rng.normal(size=pm.nv), rng.normal(size=pm.nv)
    js = model.joint_space
    sq, sv = js.slices(), js.slices(rates=True)
    qj, vj, u = np.zeros(js.nq), np.zeros(js.nv), np.zeros(model.nu)
    for jid in range(1, pm.njoints):
        jm, n = pm.joints[jid], re.sub(r"\W", "_", pm.names[jid])
        n = "root" if jm.shortname() == "JointModelFreeFlyer" else n
        qj[sq[n]], vj[sv[n]] = qp[jm.idx_q:jm.idx_q + jm.nq], vp[jm.idx_v:jm.idx_v + jm.nv]
        if n != "root":
            u[model.actuated_joints.index(n)] = tp[jm.idx_v]
        else:
            tp[jm.idx_v:jm.idx_v + jm.nv] = 0.0
    return (qp, vp, tp), (qj, vj, u)


def to_pin(model, pm, aj):
    sv = model.joint_space.slices(rates=True)
    out = np.zeros(pm.nv)
    for jid in range(1, pm.njoints):
        jm, n = pm.joints[jid], re.sub(r"\W", "_", pm.names[jid])
        n = "root" if jm.shortname() == "JointModelFreeFlyer" else n
        out[jm.idx_v:jm.idx_v + jm.nv] = aj[sv[n]]
    return out


def arm(calls, repeat):
    import pinocchio as pin

    model, pm = panda_pair()
    pd = pm.createData()
    (qp, vp, tp), (qj, vj, tau) = pin_state(model, pm)
    a_pin = pin.aba(pm, pd, qp, vp, tp)
    t0 = time.perf_counter()
    kj = nc.joint_forward_dynamics_kernel(model)
    build = time.perf_counter() - t0
    err = np.max(np.abs(to_pin(model, pm, kj(qj, vj, tau)) - a_pin)) / max(1.0, np.max(np.abs(a_pin)))
    q, v = model.from_joint_space(qj, vj)
    k = forward_dynamics_kernel(model)
    kkt = forward_dynamics_kernel(model, joint_space=True)
    err_kkt = np.max(np.abs(to_pin(model, pm, kkt(0.0, qj, vj, tau, model.p0)[0]) - a_pin)) / max(1.0, np.max(np.abs(a_pin)))
    ext = ca.external(f"{model.name}_jfd_tree_{kj.direct.name}", str(kj.direct.library))
    p0, t_ = model.p0, model.t0
    out = {
        "pinocchio.aba": per_call(lambda: pin.aba(pm, pd, qp, vp, tp), calls, repeat),
        "ncgen joint kernel": per_call(lambda: kj(qj, vj, tau), calls, repeat),
        "ncgen joint kernel, call only": per_call(kj.direct.call, calls, repeat),
        "ncgen joint kernel, C loop": c_loop(kj.direct, 20 * calls, repeat),
        "ncgen joint kernel, C loop, -O3 -march=native": c_loop(
            nc.joint_forward_dynamics_kernel(model, cflags="-O3 -march=native").direct, 20 * calls, repeat),
        "ncgen joint kernel, casadi.external": per_call(lambda: ext(t_, qj, vj, tau, p0), max(1, calls // 10), repeat),
        "nc.joint_forward_dynamics": per_call(lambda: nc.joint_forward_dynamics(model, qj, vj, tau),
                                              max(1, calls // 10), repeat),
        "ncgen natural-coordinate kernel (KKT)": per_call(lambda: k(0.0, q, v, tau, p0), calls, repeat),
        "ncgen joint space via the KKT kernel": per_call(lambda: kkt(0.0, qj, vj, tau, p0), calls, repeat),
    }
    return model, out, (err, err_kkt), build, kj


def humanoid(package: bool):
    """Stages in seconds, with an empty build cache (the compile is part of the figure)."""
    import os

    path = robot_file("talos_data/robots/talos_reduced.urdf")
    old = os.environ.get("NCGEN_CACHE_DIR")
    with tempfile.TemporaryDirectory() as cache:
        os.environ["NCGEN_CACHE_DIR"] = cache
        try:
            return _humanoid_stages(path, package)
        finally:
            if old is None:
                os.environ.pop("NCGEN_CACHE_DIR")
            else:
                os.environ["NCGEN_CACHE_DIR"] = old


def _humanoid_stages(path, package: bool):
    import pinocchio as pin

    from ncgen.codegen.load import load_functions

    kernel, full = {}, {}
    t0 = time.perf_counter()
    s = nc.System.from_urdf(path, floating_base=True)
    kernel["from_urdf"] = time.perf_counter() - t0
    t1 = time.perf_counter()
    model = s.build()
    kernel["build"] = time.perf_counter() - t1
    t2 = time.perf_counter()
    k = nc.joint_forward_dynamics_kernel(model)
    kernel["joint kernel: SX, C, compile, load"] = time.perf_counter() - t2
    kernel["total"] = time.perf_counter() - t0
    pm = pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer())
    (qp, vp, tp), (qj, vj, u) = pin_state(model, pm, seed=1)
    a_pin = pin.aba(pm, pm.createData(), qp, vp, tp)
    err = np.max(np.abs(to_pin(model, pm, k(qj, vj, u)) - a_pin)) / max(1.0, np.max(np.abs(a_pin)))
    pd = pm.createData()
    calls = {"joint kernel call, µs": per_call(lambda: k(qj, vj, u), 500, 3),
             "pinocchio.aba call, µs": per_call(lambda: pin.aba(pm, pd, qp, vp, tp), 500, 3)}
    if package:
        t3 = time.perf_counter()
        with tempfile.TemporaryDirectory() as tmp:
            pkg = nc.generate(model, Path(tmp) / "talos", compile=True)
            full["generate + compile"] = time.perf_counter() - t3
            t4 = time.perf_counter()
            load_functions(pkg, backend="compiled")
            full["load"] = time.perf_counter() - t4
        full["total (with from_urdf, build)"] = kernel["from_urdf"] + kernel["build"] + time.perf_counter() - t3
    return model, k, kernel, full, err, calls


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--calls", type=int, default=2000)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--skip-humanoid", action="store_true")
    ap.add_argument("--skip-package", action="store_true", help="Talos: only the joint kernel, not the full package")
    ap.add_argument("--smoke", action="store_true", help="few calls, no humanoid (CI)")
    args = ap.parse_args(argv)
    if args.smoke:
        args.calls, args.repeat, args.skip_humanoid = 20, 1, True
    print(machine())
    d, kcall, e = trivial(args.calls, args.repeat)
    print("=== call overhead: y = 2x (3 entries), compiled")
    print(f"  direct (copy in + call): {d:8.2f} µs   call only: {kcall:8.2f} µs   casadi.external: {e:8.2f} µs")
    print(f"RATIO casadi.external / direct: {e / d:.1f}")
    model, t, (err, err_kkt), build, kj = arm(args.calls, args.repeat)
    print(f"=== Panda (9 DOF; ncgen nq = {model.nq}, nc = {model.nc}): forward dynamics from Python, µs per call")
    print(f"  joint kernel ({kj.method} form, {kj.direct.name}) built and loaded in {build:.1f} s")
    print(f"  max |a_j - a(pinocchio.aba)| / max(1, |a|): joint kernel {err:.1e}, KKT kernel {err_kkt:.1e}")
    for name, value in t.items():
        print(f"  {name:<46s} {value:10.2f}")
    print(f"RATIO ncgen joint kernel / pinocchio.aba: {t['ncgen joint kernel'] / t['pinocchio.aba']:.2f}   (target <= 2)")
    print(f"RATIO ncgen joint kernel C loop / pinocchio.aba: {t['ncgen joint kernel, C loop'] / t['pinocchio.aba']:.2f}")
    print(f"RATIO ncgen joint space via the KKT kernel / pinocchio.aba: "
          f"{t['ncgen joint space via the KKT kernel'] / t['pinocchio.aba']:.1f}")
    if not args.skip_humanoid:
        hm, hk, kernel, full, herr, calls = humanoid(not args.skip_package)
        print(f"=== Talos (floating base; {len(hm.member_names)} bodies, {hm.joint_space.nv} joint rates, "
              f"nq = {hm.nq}, nc = {hm.nc}): URDF file to loaded compiled library, empty cache")
        print(f"  joint kernel ({hk.method} form): max |a_j - a(pinocchio.aba)| / max(1, |a|) = {herr:.1e}")
        for name, value in kernel.items():
            print(f"  {name:<40s} {value:8.1f} s")
        print(f"TALOS URDF file to loaded joint-space dynamics library: {kernel['total']:.1f} s   (target < 30 s)")
        print("  " + ", ".join(f"{name} {value:.1f}" for name, value in calls.items()))
        if full:
            print("  the whole simulation package (nc.generate + compile + load_functions), same model:")
            for name, value in full.items():
                print(f"  {name:<40s} {value:8.1f} s")
            print(f"TALOS URDF file to loaded simulation package: {full['total (with from_urdf, build)']:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
