"""Closure error of MJCF loops (``<equality><connect>``): ncgen, which imports each connect as
a point the two bodies share, against MuJoCo, which holds it by a soft constraint.

For an MJCF file (default ``tests/data/rssr.xml``): a run of ``--t-end`` seconds from the
file's configuration at rest, ncgen by IDAS (rtol 1e-10) and MuJoCo by RK4 at ``--dt``
(contacts off), both on the file as written and MuJoCo also on ncgen's export of it
(``model.to_mjcf``); printed: the largest distance between the two anchors of every connect
(m) over the run, and ncgen's largest constraint residual.
``python benchmarks/mjcf_loop_closure.py [FILE] [--t-end 10] [--dt 1e-4]``."""
from __future__ import annotations

import argparse
import platform
import tempfile
from pathlib import Path

import numpy as np

import ncgen as nc

DEFAULT = Path(__file__).resolve().parents[1] / "tests" / "data" / "rssr.xml"


def mujoco_gap(path, t_end: float, dt: float) -> float:
    """The largest anchor distance (m) of the file's connect constraints in a MuJoCo run."""
    import mujoco
    mj = mujoco.MjModel.from_xml_path(str(path))
    mj.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    mj.opt.integrator, mj.opt.timestep = mujoco.mjtIntegrator.mjINT_RK4, dt
    d = mujoco.MjData(mj)
    mujoco.mj_forward(mj, d)
    connects = [k for k in range(mj.neq) if mj.eq_type[k] == mujoco.mjtEq.mjEQ_CONNECT]
    worst = 0.0
    for _ in range(int(round(t_end / dt))):
        mujoco.mj_step(mj, d)
        for k in connects:
            b1, b2 = mj.eq_obj1id[k], mj.eq_obj2id[k]
            x1 = d.xpos[b1] + d.xmat[b1].reshape(3, 3) @ mj.eq_data[k, 0:3]
            x2 = d.xpos[b2] + d.xmat[b2].reshape(3, 3) @ mj.eq_data[k, 3:6]
            worst = max(worst, float(np.linalg.norm(x1 - x2)))
    return worst


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("file", nargs="?", default=str(DEFAULT))
    p.add_argument("--t-end", type=float, default=10.0)
    p.add_argument("--dt", type=float, default=1e-4)
    args = p.parse_args()
    import mujoco
    print(f"python {platform.python_version()}, mujoco {mujoco.__version__}, {platform.machine()}; {args.file}, "
          f"{args.t_end:g} s")
    model = nc.System.from_mjcf(args.file).build()
    traj = nc.simulate(model, args.t_end, 0.01, rtol=1e-10, atol=1e-12)
    print(f"ncgen (IDAS, rtol 1e-10): max |Phi| = {np.max(np.abs(traj.constraint_residual)):.3g} "
          "(connect anchors shared: distance 0 m by construction)")
    print(f"MuJoCo RK4 {args.dt:g} s, the file:        max anchor distance = {mujoco_gap(args.file, args.t_end, args.dt):.3g} m")
    with tempfile.TemporaryDirectory() as tmp:
        exported = Path(tmp) / "exported.xml"
        model.to_mjcf(exported)
        print(f"MuJoCo RK4 {args.dt:g} s, ncgen's export: max anchor distance = "
              f"{mujoco_gap(exported, args.t_end, args.dt):.3g} m")


if __name__ == "__main__":
    main()
