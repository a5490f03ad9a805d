"""Joint space from Python: ncgen's forward dynamics of a URDF arm vs ``pinocchio.aba``, and a
humanoid URDF from file to loaded compiled library.

Robot: the Panda of example-robot-data (7 arm joints + 2 fingers, the mimic tag dropped so that
both engines see the same 9-DOF model).  One state, the same in both engines.  Timed, in µs
per call, best of ``--repeat`` batches of ``--calls`` calls from Python:

* ``pinocchio.aba(model, data, q, v, tau)``: joint space in and out (Featherstone's ABA);
* ncgen's compiled forward dynamics called directly (``forward_dynamics_kernel``, ctypes,
  preallocated buffers): natural coordinates in, ``q̈`` and ``λ`` out; the kernel solves the
  constraint equations by the Schur complement of the constant mass matrix
  (``(A M⁻¹ Aᵀ) λ = A M⁻¹ F − γ``, sparse LDLᵀ) — "direct";
* the same kernel with the inputs already in its buffers (``DirectFunction.call``): the C
  kernel plus the bare ctypes call — "kernel";
* the same compiled kernel through ``casadi.external`` — "external";
* a trivial compiled function (``y = 2x``, 3 entries) directly and through
  ``casadi.external``: the call overheads themselves;
* ncgen joint space in and out in one compiled call (``forward_dynamics_kernel(model,
  joint_space=True)``: the tree map q_j → q, the same solve, a_j = J q̈ + J̇ q̇) — "joint kernel";
* ncgen joint space in and out from Python: ``from_joint_space`` + direct kernel +
  ``to_joint_space``.

Then the humanoid: Talos (``talos_reduced.urdf``, floating base) from file to a loaded
compiled library (``System.from_urdf`` → ``build`` → ``nc.generate(compile=True)`` →
``load_functions``), seconds per stage.

    python benchmarks/joint_space.py [--calls 2000] [--repeat 5] [--skip-humanoid] [--smoke]
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
from ncgen.runtime.joint_dynamics import forward_dynamics_kernel  # noqa: E402


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


def arm(calls, repeat):
    import pinocchio as pin

    text = re.sub(r"<mimic[^>]*/>", "", robot_file("panda_description/urdf/panda.urdf").read_text())
    model = nc.System.from_urdf(text).build()
    pm = pin.buildModelFromXML(text)
    pd = pm.createData()
    rng = np.random.default_rng(0)
    qp = pin.randomConfiguration(pm, -np.ones(pm.nq), np.ones(pm.nq))
    vp, tp = rng.normal(size=pm.nv), rng.normal(size=pm.nv)
    js = model.joint_space
    sq, sv = js.slices(), js.slices(rates=True)
    qj, vj, tau = np.zeros(js.nq), np.zeros(js.nv), np.zeros(model.nu)
    for jid in range(1, pm.njoints):
        jm, n = pm.joints[jid], pm.names[jid]
        qj[sq[n]], vj[sv[n]] = qp[jm.idx_q], vp[jm.idx_v]
        tau[model.joint_names.index(n)] = tp[jm.idx_v]
    q, v = model.from_joint_space(qj, vj)
    t0 = time.perf_counter()
    k = forward_dynamics_kernel(model)
    build = time.perf_counter() - t0
    a, lam = k(0.0, q, v, tau, model.p0)
    aj = model.to_joint_space(q, v, a)[2]
    a_pin = pin.aba(pm, pd, qp, vp, tp)
    err = max(abs(aj[model.joint_names.index(pm.names[j])] - a_pin[pm.joints[j].idx_v]) for j in range(1, pm.njoints))
    kj = forward_dynamics_kernel(model, joint_space=True)
    aj2 = kj(0.0, qj, vj, tau, model.p0)[0]
    err = max(err, max(abs(aj2[model.joint_names.index(pm.names[j])] - a_pin[pm.joints[j].idx_v])
                       for j in range(1, pm.njoints)))
    ext = ca.external(f"{model.name}_fd_{k.name}", str(k.library))
    p0 = model.p0

    def joint_space():
        q_, v_ = model.from_joint_space(qj, vj)
        return model.to_joint_space(q_, v_, k(0.0, q_, v_, tau, p0)[0])

    out = {
        "pinocchio.aba": per_call(lambda: pin.aba(pm, pd, qp, vp, tp), calls, repeat),
        "ncgen direct": per_call(lambda: k(0.0, q, v, tau, p0), calls, repeat),
        "ncgen kernel": per_call(k.call, calls, repeat),
        "ncgen external": per_call(lambda: ext(0.0, q, v, tau, p0), max(1, calls // 10), repeat),
        "ncgen joint kernel": per_call(lambda: kj(0.0, qj, vj, tau, p0), calls, repeat),
        "ncgen joint space": per_call(joint_space, max(1, calls // 100), repeat),
    }
    return model, out, err, build


def humanoid():
    """Stages in seconds, with an empty build cache (the compile is part of the figure)."""
    import os

    from ncgen.codegen.load import load_functions

    path = robot_file("talos_data/robots/talos_reduced.urdf")
    stages = {}
    old = os.environ.get("NCGEN_CACHE_DIR")
    with tempfile.TemporaryDirectory() as cache:
        os.environ["NCGEN_CACHE_DIR"] = cache
        try:
            return _humanoid_stages(path, stages, load_functions)
        finally:
            if old is None:
                os.environ.pop("NCGEN_CACHE_DIR")
            else:
                os.environ["NCGEN_CACHE_DIR"] = old


def _humanoid_stages(path, stages, load_functions):
    t0 = time.perf_counter()
    s = nc.System.from_urdf(path, floating_base=True)
    stages["from_urdf"] = time.perf_counter() - t0
    t1 = time.perf_counter()
    model = s.build()
    stages["build"] = time.perf_counter() - t1
    t2 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        pkg = nc.generate(model, Path(tmp) / "talos", compile=True)
        stages["generate + compile"] = time.perf_counter() - t2
        t3 = time.perf_counter()
        load_functions(pkg, backend="compiled")
        stages["load"] = time.perf_counter() - t3
    stages["total"] = time.perf_counter() - t0
    return model, stages


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--calls", type=int, default=2000)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--skip-humanoid", action="store_true")
    ap.add_argument("--smoke", action="store_true", help="few calls, no humanoid (CI)")
    args = ap.parse_args(argv)
    if args.smoke:
        args.calls, args.repeat, args.skip_humanoid = 20, 1, True
    print(machine())
    d, kcall, e = trivial(args.calls, args.repeat)
    print("=== call overhead: y = 2x (3 entries), compiled")
    print(f"  direct (copy in + call): {d:8.2f} µs   call only: {kcall:8.2f} µs   casadi.external: {e:8.2f} µs")
    print(f"RATIO casadi.external / direct: {e / d:.1f}")
    model, t, err, build = arm(args.calls, args.repeat)
    print(f"=== Panda (9 DOF; ncgen nq = {model.nq}, nc = {model.nc}): forward dynamics from Python, µs per call")
    print(f"  kernel built and loaded in {build:.1f} s; max |a_j(ncgen kernels) - a(pinocchio.aba)| = {err:.2e}")
    for name, value in t.items():
        print(f"  {name:<20s} {value:10.2f}")
    print(f"RATIO ncgen direct / pinocchio.aba: {t['ncgen direct'] / t['pinocchio.aba']:.1f}")
    print(f"RATIO ncgen kernel / pinocchio.aba: {t['ncgen kernel'] / t['pinocchio.aba']:.1f}")
    print(f"RATIO ncgen external / ncgen direct: {t['ncgen external'] / t['ncgen direct']:.1f}")
    print(f"RATIO ncgen joint kernel / pinocchio.aba: {t['ncgen joint kernel'] / t['pinocchio.aba']:.1f}")
    if not args.skip_humanoid:
        hm, stages = humanoid()
        print(f"=== Talos (floating base; {len(hm.member_names)} bodies, nq = {hm.nq}, nc = {hm.nc}): "
              "URDF file to loaded compiled library")
        for name, value in stages.items():
            print(f"  {name:<20s} {value:8.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
