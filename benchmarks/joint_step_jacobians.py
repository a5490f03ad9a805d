"""The Panda's joint-space step Jacobians (``nc.JointStep(model, h).jacobians``) against
``mujoco.mjd_transitionFD`` on its MuJoCo twin (issue 37: ≤ 0.5×).

The 7-DOF Panda of example-robot-data (fingers locked: ``nc.robots.locked_urdf``; ``<dynamics>``
removed, so no joint damping or friction on either side, and no armature: URDF has none).  The twin
is the same URDF text compiled by MuJoCo (visuals and collisions dropped, contacts disabled), a
``motor`` actuator of gear 1 on each joint (no control limits, and the URDF's efforts not
taken as force limits: ncgen's step does not clip either), its Euler integrator at the same
step h = 1 ms.  Both are the same discrete map: semi-implicit Euler ``v⁺ = v + h a``,
``q⁺ = q + h v⁺`` on the rigid-body accelerations; the joint limits of the URDF are inactive at
the state used (checked: MuJoCo reports no constraint).  First the two ``(A, B)`` are compared
(largest difference relative to the largest entry; MuJoCo's are finite differences, so they agree
to about its ``eps``² for centred ones), then timed in interleaved batches (CPU time,
``time.process_time``), min and median per call:

- ``JointStep.jacobians`` (checked inputs), ``JointStep.unchecked_jacobians``, and the call it
  makes, ``ncgen.runtime.tree_algorithm_kernels.aba_derivatives`` (compiled ABA derivatives), which
  shows where the time goes: the rest is the assembly of x⁺, A and B (one C call of
  ``ncgen.control.joint_step.step_jacobians_function`` on the kernel's buffers);
- ``mujoco.mjd_transitionFD`` centred (eps 1e-6) and forward.

    python benchmarks/joint_step_jacobians.py [--calls 200] [--repeat 7] [--smoke]
"""
from __future__ import annotations

import argparse
import os
import re
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import batches, machine, report_ratios  # noqa: E402

import ncgen as nc  # noqa: E402
from ncgen.runtime.tree_algorithm_kernels import aba_derivatives  # noqa: E402

H = 1e-3
FINGERS = ["panda_finger_joint1", "panda_finger_joint2"]
Q0 = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785])


def panda_urdf() -> str:
    """The 7-DOF Panda's URDF text, fingers locked, ``<dynamics>`` tags removed."""
    return re.sub(r"<dynamics[^>]*/>", "", nc.robots.locked_urdf("panda", FINGERS))


def twin(text: str, joint_names, h: float = H):
    """MuJoCo model of the URDF ``text``: Euler at the step ``h``, contacts off, a motor (gear 1)
    per joint of ``joint_names`` (which must be MuJoCo's joints in its order)."""
    import mujoco
    spec = mujoco.MjSpec.from_string(re.sub(r"<(visual|collision)\b.*?</\1>", "", text, flags=re.S))
    for j in spec.joints:                   # MuJoCo reads URDF efforts as limits of the actuator force
        j.actfrclimited = mujoco.mjtLimited.mjLIMITED_FALSE
    for j in joint_names:
        spec.add_actuator(name=f"motor_{j}", target=j, trntype=mujoco.mjtTrn.mjTRN_JOINT,
                          gear=[1, 0, 0, 0, 0, 0], ctrllimited=0)
    m = spec.compile()
    m.opt.timestep = h
    m.opt.integrator = mujoco.mjtIntegrator.mjINT_EULER
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    names = [m.joint(i).name for i in range(m.njnt)]
    if names != list(joint_names) or m.nv != len(joint_names):
        raise SystemExit(f"the twin's joints {names} are not ncgen's {list(joint_names)}")
    if np.any(m.dof_damping) or np.any(m.dof_armature) or np.any(m.dof_frictionloss):
        raise SystemExit("the twin has damping, armature or friction loss: not the same dynamics")
    return m


def state(n: int):
    rng = np.random.default_rng(0)
    return np.concatenate([Q0 + 0.2 * rng.normal(size=n), 0.5 * rng.normal(size=n)]), 5.0 * rng.normal(size=n)


def agreement(step, m, x, tau, eps: float) -> tuple[float, float, float]:
    """``(|Δx⁺|, |ΔA|/|A|, |ΔB|/|B|)`` (max norms) of ncgen's exact and MuJoCo's centred Jacobians."""
    import mujoco
    n = step.n
    d = mujoco.MjData(m)
    d.qpos[:], d.qvel[:], d.ctrl[:] = x[:n], x[n:], tau
    A, B = np.zeros((2 * n, 2 * n)), np.zeros((2 * n, n))
    mujoco.mjd_transitionFD(m, d, eps, True, A, B, None, None)
    x1, A1, B1 = step.jacobians(x, tau)
    mujoco.mj_step(m, d)
    if d.nefc:
        raise SystemExit(f"MuJoCo has {d.nefc} active constraint rows (a joint limit?): not the same dynamics")
    dx = np.max(np.abs(x1 - np.concatenate([d.qpos, d.qvel])))
    return dx, np.max(np.abs(A1 - A)) / np.max(np.abs(A)), np.max(np.abs(B1 - B)) / np.max(np.abs(B))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--calls", type=int, default=200)
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--smoke", action="store_true", help="tiny sizes: check that the script runs")
    args = ap.parse_args(argv)
    if args.smoke:
        args.calls, args.repeat = 3, 2
    print(machine())
    import mujoco
    text = panda_urdf()
    model = nc.System.from_urdf(text).build()
    step = nc.JointStep(model, H)
    m = twin(text, model.joint_names)
    n = step.n
    x, tau = state(n)
    dx, dA, dB = agreement(step, m, x, tau, 1e-6)
    print(f"\n=== same discrete map: Panda 7-DOF, h = {H} s, MuJoCo Euler, centred FD eps 1e-6")
    print(f"  |x⁺ ncgen − x⁺ MuJoCo| = {dx:.1e};  |A − A_FD| / |A| = {dA:.1e};  |B − B_FD| / |B| = {dB:.1e}")
    tol = 1e-6
    if max(dx, dA, dB) > tol:
        raise SystemExit(f"ncgen and MuJoCo disagree by more than {tol:g}: the comparison would not be fair")
    print(f"  AGREE to {tol:g} (max norm, relative for A and B)")

    d = mujoco.MjData(m)
    d.qpos[:], d.qvel[:], d.ctrl[:] = x[:n], x[n:], tau
    A, B = np.zeros((2 * n, 2 * n)), np.zeros((2 * n, n))
    q, v = x[:n].copy(), x[n:].copy()
    fns = {
        "ncgen JointStep.jacobians": lambda: step.jacobians(x, tau),
        "ncgen unchecked_jacobians": lambda: step.unchecked_jacobians(x, tau),
        "ncgen aba_derivatives alone": lambda: aba_derivatives(model, q, v, tau),
        "mujoco mjd_transitionFD centred": lambda: mujoco.mjd_transitionFD(m, d, 1e-6, True, A, B, None, None),
        "mujoco mjd_transitionFD forward": lambda: mujoco.mjd_transitionFD(m, d, 1e-6, False, A, B, None, None),
    }
    t = batches(fns, args.calls, args.repeat, clock=time.process_time)
    report_ratios(f"Panda 7-DOF step Jacobians (A 14×14, B 14×7), CPU time, {args.repeat} interleaved batches "
                  f"of {args.calls} calls", t, "ncgen JointStep.jacobians", "target ≤ 0.5")
    for name in ("ncgen unchecked_jacobians", "ncgen aba_derivatives alone"):
        print(f"  RATIO {name} / mujoco mjd_transitionFD centred: min "
              f"{min(t[name]) / min(t['mujoco mjd_transitionFD centred']):.2f}, median "
              f"{np.median(t[name]) / np.median(t['mujoco mjd_transitionFD centred']):.2f}")
    share = np.median(t["ncgen aba_derivatives alone"]) / np.median(t["ncgen JointStep.jacobians"])
    print(f"  aba_derivatives is {100 * share:.0f} % of JointStep.jacobians (median): the rest is the "
          f"input checks and the NumPy assembly of A and B")
    print(f"\nload average at end: {', '.join(f'{v:.2f}' for v in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
