"""Step Jacobians from the element tables (``nc.step_function(model, h)``, kernels chosen
"tables": the implicit function theorem on the table stepper's own Newton systems, compiled
once per ncgen version; issues 34 and 37).

1. Calls: ``st.jacobians(x, u)`` (``A = ∂x⁺/∂x``, 2nq × 2nq in natural coordinates, and
   ``B = ∂x⁺/∂u``, from Python) against ``mujoco.mjd_transitionFD`` (forward and centred,
   eps 1e-6) on the twin with its Euler integrator at the same step: the 20-bar chain
   (``common.chain_mjcf``, ball joints) and the Panda (its URDF with ``<mimic>`` removed — the
   fingers then move independently, as in benchmarks/joint_simulation.py — visuals and
   collisions dropped for MuJoCo).  ``--flat`` adds the flat step function (the model's own
   generated package, compiled first).  Interleaved batches, CPU time (``time.process_time``),
   min and median per call.  ncgen's A is first checked against central differences of its own
   step (printed, relative to max |A|).  Not the same coordinates nor the same step: the same
   job (one step's linearisation).  ``--chain-only``: this part on the chain alone.
2. Time to the first Jacobian of a new robot, each in a fresh process: ``from_urdf`` →
   ``build`` → ``step_function`` → ``jacobians`` (CPU and wall seconds; the number of
   compiler runs, which must be 0 once the element library is cached): z1, Panda (mimic
   removed, and stock: its finger mimic), UR10, and with ``--talos`` Talos (floating base).
3. The table stepper's Newton iterations per step on the z1 and the UR10 (100 steps of
   1 ms with random torques).

    python benchmarks/table_step_jacobians.py [--calls 50] [--repeat 5] [--bars 20] [--flat] [--talos]
                                              [--chain-only] [--smoke]
"""
from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import batches, chain_mjcf, chain_system, machine, report_ratios  # noqa: E402

import ncgen as nc  # noqa: E402

H = 1e-3
ROBOTS = {"z1": "z1", "panda": "panda", "ur10": "ur10", "talos": "talos_reduced"}


def urdf_text(robot: str) -> str:
    """The robot's URDF (example-robot-data) with ``<dynamics>`` removed, and ``<mimic>`` too
    unless the name ends in ``_stock``."""
    stock = robot.endswith("_stock")
    text = Path(nc.robots.urdf_path(ROBOTS[robot.removesuffix("_stock")])).read_text()
    text = text if stock else re.sub(r"<mimic[^>]*/>", "", text)
    return re.sub(r"<dynamics[^>]*/>", "", text)


def compare(title: str, model, mj, nu_mj: int, calls: int, repeat: int, flat: bool) -> None:
    import mujoco
    st = nc.step_function(model, H)
    rng = np.random.default_rng(0)
    v = nc.project_velocity(model, model.q0, 0.3 * rng.normal(size=model.nq)) if model.dof else model.v0
    x = np.concatenate([model.q0, v])
    u = np.zeros(model.nu)
    for _ in range(20):
        x = st(x, u)
    d = mujoco.MjData(mj)
    mujoco.mj_step(mj, d, nstep=20)
    nxm = 2 * mj.nv + mj.na
    A, B = np.zeros((nxm, nxm)), np.zeros((nxm, nu_mj))
    _, Aj, _ = st.jacobians(x, u)
    eps = 1e-6
    D = np.column_stack([(st(x + e, u) - st(x - e, u)) / (2 * eps) for e in np.eye(x.size) * eps])
    print(f"\n{title}: ncgen's A against central differences of its step (eps {eps:g}): "
          f"{np.max(np.abs(Aj - D)) / np.max(np.abs(Aj)):.1e} relative to max |A|")
    fns = {"ncgen tables st.jacobians": lambda: st.jacobians(x, u)}
    if flat:
        fl = nc.step_function(model, H, kernels="flat")
        fns["ncgen flat st.jacobians"] = lambda: fl.jacobians(x, u)
    fns["mujoco mjd_transitionFD forward"] = lambda: mujoco.mjd_transitionFD(mj, d, 1e-6, False, A, B, None, None)
    fns["mujoco mjd_transitionFD centred"] = lambda: mujoco.mjd_transitionFD(mj, d, 1e-6, True, A, B, None, None)
    report_ratios(f"{title}: ncgen A {2 * model.nq}×{2 * model.nq}, B {2 * model.nq}×{model.nu} ({st.kernels}); "
                  f"MuJoCo A {nxm}×{nxm}; CPU time", batches(fns, calls, repeat, clock=time.process_time),
                  "ncgen tables st.jacobians", "target ≤ 0.5")


def panda_twin():
    import mujoco
    text = urdf_text("panda")
    spec = mujoco.MjSpec.from_string(re.sub(r"<(visual|collision)\b.*?</\1>", "", text, flags=re.S))
    m = spec.compile()
    m.opt.timestep = H
    m.opt.integrator = mujoco.mjtIntegrator.mjINT_EULER
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    return nc.System.from_urdf(text).build(), m


CHILD = r"""
import json, sys, time
import numpy as np
import ncgen as nc
import ncgen.codegen.compile_cache as cc
sys.path.insert(0, {bench!r})
from table_step_jacobians import urdf_text
runs = []
real = cc.compile_package
def counted(*a, **k):
    runs.append(1)
    return real(*a, **k)
cc.compile_package = counted
text = urdf_text({robot!r})
c0, w0 = time.process_time(), time.perf_counter()
model = nc.System.from_urdf(text, floating_base={floating!r}).build()
c1, w1 = time.process_time(), time.perf_counter()
st = nc.step_function(model, 1e-3)
rng = np.random.default_rng(1)
x = np.concatenate([model.q0, model.v0])
x1, A, B = st.jacobians(x, rng.normal(size=model.nu))
c2, w2 = time.process_time(), time.perf_counter()
print(json.dumps({{"kernels": st.kernels, "build_cpu": c1 - c0, "build_wall": w1 - w0, "jac_cpu": c2 - c1,
                  "jac_wall": w2 - w1, "compiles": len(runs), "nx": st.nx}}))
"""


def first_jacobian(robot: str) -> None:
    code = CHILD.format(bench=str(Path(__file__).resolve().parent), robot=robot, floating=robot.startswith("talos"))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=3600)
    if out.returncode:
        print(f"  {robot}: failed: {out.stderr.strip().splitlines()[-1] if out.stderr.strip() else '?'}")
        return
    r = json.loads(out.stdout.strip().splitlines()[-1])
    print(f"  {robot:11s} nx {r['nx']:4d}  kernels {r['kernels']:6s}  compiler runs {r['compiles']}  "
          f"from_urdf+build {r['build_cpu']:6.2f} s CPU ({r['build_wall']:6.2f} s wall)  "
          f"step_function + first jacobians {r['jac_cpu']:6.2f} s CPU ({r['jac_wall']:6.2f} s wall)")


def newton_iterations(robot: str, steps: int) -> None:
    model = nc.System.from_urdf(urdf_text(robot)).build()
    st = nc.step_function(model, H)
    rng = np.random.default_rng(2)
    x = np.concatenate([model.q0, nc.project_velocity(model, model.q0, 0.5 * rng.normal(size=model.nq))])
    its = []
    for _ in range(steps):
        status, x, res, it, _, _ = st._table(x, rng.normal(size=model.nu), 0.0, False)
        if status:
            print(f"  {robot}: step failed, status {status}")
            return
        its.append(it)
    print(f"  {robot:6s} Newton iterations per step: mean {np.mean(its):.2f}, max {max(its)} "
          f"(residual of the last step {res:.1e})")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--calls", type=int, default=50)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--bars", type=int, default=20)
    ap.add_argument("--flat", action="store_true", help="also the flat step function (compiled first)")
    ap.add_argument("--talos", action="store_true", help="also Talos's time to the first Jacobian")
    ap.add_argument("--chain-only", action="store_true", help="the chain's Jacobians alone (part 1)")
    ap.add_argument("--smoke", action="store_true", help="tiny sizes: check that the script runs")
    args = ap.parse_args(argv)
    if args.smoke:
        args.calls, args.repeat, args.bars = 3, 2, 3
    print(machine())
    import mujoco
    chain = mujoco.MjModel.from_xml_string(chain_mjcf(args.bars, integrator="Euler", timestep=H))
    compare(f"chain of N = {args.bars} bars, h = {H} s", chain_system(args.bars).build(), chain, chain.nu,
            args.calls, args.repeat, args.flat)
    if not (args.smoke or args.chain_only):
        model, m = panda_twin()
        compare(f"Panda (mimic removed), h = {H} s", model, m, m.nu, args.calls, args.repeat, args.flat)
        print("\n=== time to the first step Jacobians of a new robot (fresh process, element library cached)")
        for robot in ["z1", "panda", "panda_stock", "ur10"] + (["talos"] if args.talos else []):
            first_jacobian(robot)
        print("\n=== the table stepper's Newton iterations per step (h = 1 ms, random torques)")
        for robot in ("z1", "ur10"):
            newton_iterations(robot, 100)
    print(f"\nload average at end: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
