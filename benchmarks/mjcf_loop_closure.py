"""Closure error of MJCF loops (``<equality><connect>``): ncgen, which imports each connect as
a point the two bodies share, against MuJoCo, which holds it by a soft constraint.

For an MJCF file (default ``tests/data/rssr.xml``): a run of ``--t-end`` seconds from the
file's configuration at rest, ncgen by IDAS (rtol 1e-10) and MuJoCo by RK4 at ``--dt``
(contacts off), both on the file as written and MuJoCo also on ncgen's export of it
(``model.to_mjcf``); printed: the largest distance between the two anchors of every connect
(m) over the run (ncgen's measured from its bodies' frames, as MuJoCo's), and ncgen's
largest constraint residual.  MuJoCo loads the file with its mesh geoms taken out (a
Menagerie model whose meshes are not here, e.g. Agility's Cassie,
``$NCGEN_MENAGERIE/agility_cassie/cassie.xml``: its inertials are explicit).
``python benchmarks/mjcf_loop_closure.py [FILE] [--t-end 10] [--dt 1e-4]``."""
from __future__ import annotations

import argparse
import platform
import sys
import tempfile
from pathlib import Path

import numpy as np

import ncgen as nc

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from mjcf_reference import closure_run  # noqa: E402

DEFAULT = Path(__file__).resolve().parents[1] / "tests" / "data" / "rssr.xml"


def mujoco_model(path):
    """MuJoCo's model of the file without its mesh geoms, meshes and textures."""
    import mujoco
    spec = mujoco.MjSpec.from_file(str(path))
    for g in list(spec.geoms):
        if g.type == mujoco.mjtGeom.mjGEOM_MESH:
            spec.delete(g)
    for item in list(spec.meshes) + list(spec.textures):
        spec.delete(item)
    for mat in spec.materials:
        mat.textures = [""] * len(mat.textures)
    return spec.compile()


def ncgen_gap(path, model, traj) -> float:
    """The largest anchor distance (m) of the file's connects over ncgen's run: body1's
    anchor and body2's point there in the file's configuration, from the bodies' frames."""
    import xml.etree.ElementTree as ET

    from ncgen.model.urdf import identifier
    worst = 0.0
    for el in ET.parse(path).getroot().iter("connect"):
        b1, b2 = identifier(el.get("body1")), identifier(el.get("body2", "world"))
        a1 = np.array([float(x) for x in el.get("anchor", "0 0 0").split()])

        def pose(body, q):
            return (np.eye(3), np.zeros(3)) if body == "world" else model.frame_pose(body, q)
        (R1, p1), (R2, p2) = pose(b1, model.q0), pose(b2, model.q0)
        a2 = R2.T @ (p1 + R1 @ a1 - p2)
        for q in traj.q:
            (R1, p1), (R2, p2) = pose(b1, q), pose(b2, q)
            worst = max(worst, float(np.linalg.norm(p1 + R1 @ a1 - p2 - R2 @ a2)))
    return worst


def mujoco_gap(path, t_end: float, dt: float) -> float:
    """The largest anchor distance (m) of the file's connect constraints in a MuJoCo run."""
    import mujoco
    mj = mujoco_model(path)
    mj.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    mj.opt.integrator, mj.opt.timestep = mujoco.mjtIntegrator.mjINT_RK4, dt
    return closure_run(mj, t_end)[0]


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
    print(f"ncgen (IDAS, rtol 1e-10): max |Phi| = {np.max(np.abs(traj.constraint_residual)):.3g}, "
          f"max anchor distance = {ncgen_gap(args.file, model, traj):.3g} m")
    print(f"MuJoCo RK4 {args.dt:g} s, the file:        max anchor distance = {mujoco_gap(args.file, args.t_end, args.dt):.3g} m")
    with tempfile.TemporaryDirectory() as tmp:
        exported = Path(tmp) / "exported.xml"
        model.to_mjcf(exported)
        print(f"MuJoCo RK4 {args.dt:g} s, ncgen's export: max anchor distance = "
              f"{mujoco_gap(exported, args.t_end, args.dt):.3g} m")


if __name__ == "__main__":
    main()
