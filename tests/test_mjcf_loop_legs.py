"""A Cassie-like biped written with ``<equality><connect>`` (``tests/data/loop_legs.xml``: a
pelvis on a free root, two legs of a hip roll and pitch, a knee and a four-bar of thigh, shin,
tarsus and a ball-jointed push rod closed by a connect; damping, ranges, heel and toe
springs, motors).  Checked: it imports without an unsupported-feature warning and builds
without dependent rows; at random states on its loops and random motor commands ncgen's
accelerations equal ``mj_forward``'s with the connects held exactly in the reference
(``qacc = a₀ − M⁻¹Jᵀ(JM⁻¹Jᵀ)⁺(J a₀ + J̇ qvel)``); with the pelvis fixed, 10 s of the legs
swinging under gravity with their joint damping keep every connect's anchors within 1e-10 m,
and the energy lost equals the damping work; beside it MuJoCo's soft connects on the same
file open to millimetres, and its hinge angles approach ncgen's as its connects are
stiffened (``solref``).  The free-falling biped: ``python benchmarks/mjcf_loop_closure.py
tests/data/loop_legs.xml``."""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc

mujoco = pytest.importorskip("mujoco")

from mjcf_reference import closure_run, loop_qacc, on_loops, to_mujoco  # noqa: E402
from test_mjcf import import_quietly, without_friction_and_limits  # noqa: E402

PATH = Path(__file__).parent / "data" / "loop_legs.xml"
#: Each connect: (body1, its anchor in body1's frame, body2).
CONNECTS = [("left_rod", (0.0, 0.0, -0.7), "left_tarsus"), ("right_rod", (0.0, 0.0, -0.7), "right_tarsus")]
#: MuJoCo beside ncgen over the hanging legs' 10 s: (the connects' ``solref`` time constant in
#: s, None for MuJoCo's default 0.02; RK4 timestep in s, at most half the time constant).
SOFTNESS = ((None, 5e-4), (0.002, 5e-4), (0.0005, 2.5e-4))


def built(text_or_path):
    system = import_quietly(text_or_path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")                 # no dependent rows: the four-bars are spatial RRSS loops
        return system, system.build()


def anchor_gap(model, qs) -> float:
    """Largest distance (m) between each connect's anchor on body1 and the point of body2
    that was there in the file's configuration, over the states ``qs``."""
    worst = 0.0
    for body1, anchor, body2 in CONNECTS:
        a1 = np.array(anchor)
        R1, p1 = model.frame_pose(body1, model.q0)
        R2, p2 = model.frame_pose(body2, model.q0)
        a2 = R2.T @ (p1 + R1 @ a1 - p2)
        for q in qs:
            R1, p1 = model.frame_pose(body1, q)
            R2, p2 = model.frame_pose(body2, q)
            worst = max(worst, float(np.linalg.norm(p1 + R1 @ a1 - p2 - R2 @ a2)))
    return worst


def test_imports_without_warning_and_closes_two_loops():
    system, model = built(PATH)
    assert system.mjcf_unsupported == []
    # free root 6, per leg: hip roll, hip pitch, knee (the four-bar), the rod's spin, toe
    assert model.dof == 16
    assert sorted(j.name for j in system.joints if j.kind == "Spherical") == [
        "left_heel", "left_rod_ball", "right_heel", "right_rod_ball"]


def test_accelerates_as_mujoco_with_its_loops_held():
    """Random states on the loops, random motor commands in ``ctrlrange``: ncgen's
    accelerations (natural coordinates, mapped to MuJoCo's dofs) equal MuJoCo's with the
    connects held exactly, to 1e-8 relative; joint damping off in MuJoCo (ncgen's
    natural-coordinate ``accel`` has none: it acts in simulation with ``joint_dynamics``),
    springs on."""
    system, model = built(PATH)
    mj = mujoco.MjModel.from_xml_path(str(PATH))
    D = mujoco.mjtDisableBit
    mj.opt.disableflags |= D.mjDSBL_CONTACT | D.mjDSBL_LIMIT | D.mjDSBL_EQUALITY
    mj.dof_damping[:] = 0.0
    assert not np.any(mj.dof_armature)
    d = mujoco.MjData(mj)
    rng = np.random.default_rng(11)
    worst = 0.0
    for _ in range(4):
        q, v = on_loops(model, rng, 0.2)
        ctrl = rng.uniform(-1.0, 1.0, mj.nu)
        tau = system.actuator_gear @ ctrl
        a, _ = model.accel(q, v, u=tau)
        qj, vj, aj = model.to_joint_space(q, v, np.asarray(a).ravel())
        qpos, qvel, qacc = to_mujoco(model, mj, qj, vj, aj)
        d.qpos[:], d.qvel[:], d.ctrl[:] = qpos, qvel, ctrl
        mujoco.mj_forward(mj, d)
        expected = loop_qacc(mj, d)
        assert np.max(np.abs(expected)) > 1.0
        worst = max(worst, np.max(np.abs(qacc - expected)) / max(1.0, np.max(np.abs(expected))))
    assert worst < 1e-8


def hanging_legs_in_mujoco(text: str, solref, dt: float, every: int):
    """MuJoCo's run of the hanging legs (contacts, limits and friction loss off, as in ncgen's
    run; joint damping and springs on), its connects with the ``solref`` time constant
    (None: the file's default): ``(model, largest connect gap (m), qpos every ``every``
    steps)``."""
    if solref is not None:
        text = text.replace("<connect ", f'<connect solref="{solref:g} 1" ')
    mj = mujoco.MjModel.from_xml_string(text)
    D = mujoco.mjtDisableBit
    mj.opt.disableflags |= D.mjDSBL_CONTACT | D.mjDSBL_LIMIT | D.mjDSBL_FRICTIONLOSS
    mj.opt.integrator, mj.opt.timestep = mujoco.mjtIntegrator.mjINT_RK4, dt
    return (mj, *closure_run(mj, 10.0, every))


@pytest.mark.slow
def test_hanging_legs_keep_their_loops_closed_for_10_s():
    """The pelvis fixed (the file without its free joint), the legs released from the file's
    configuration swing under gravity and the preloaded heel springs with their joint damping
    (IDAS, ``joint_dynamics=True``, rtol 1e-10): the anchors of both connects stay within
    1e-10 m for 10 s, and ``E(t) + W_damping(t) = E(0)`` (the damping work ``∫ Σ c θ̇² dt``
    by Simpson's rule on the 5 ms output grid) to 2e-4 of the work.

    MuJoCo beside it (RK4, the same file): with its default connects the anchors open to
    about 2 mm (measured, > 1e-4 m) and its hinge angles differ from ncgen's by about 1e-2
    rad; stiffening the connects (``solref`` 0.002 s, then 0.0005 s) closes the gap and
    brings every hinge angle of the 10 s run to ncgen's, the difference falling with the gap
    (below 5e-5 rad at 0.0005 s): ncgen's run is the limit of MuJoCo's as its loops harden."""
    text = PATH.read_text().replace('<freejoint name="root"/>', "")
    system = without_friction_and_limits(import_quietly(text))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        model = system.build()
    assert model.dof == 10
    dt = 5e-3
    traj = nc.simulate(model, 10.0, dt, rtol=1e-10, atol=1e-12, joint_dynamics=True)
    js = model.joint_space
    c = np.zeros(js.nv)
    for n, s in js.slices(rates=True).items():
        c[s] = js.joints[n].dynamics.get("damping", 0.0) if js.nv_joint[n] == 1 else 0.0
    assert np.count_nonzero(c) == 10
    power = np.array([c @ (model.to_joint_space(q, v)[1] ** 2) for q, v in zip(traj.q, traj.v)])
    from scipy.integrate import cumulative_simpson
    work = np.r_[0.0, cumulative_simpson(power, dx=dt)]
    knees = np.array([model.to_joint_space(q)[js.slices()["left_knee"]][0] for q in traj.q])
    assert np.ptp(knees) > 0.1 and work[-1] > 0.1
    imbalance = np.max(np.abs(traj.energy + work - traj.energy[0]))
    gap = anchor_gap(model, traj.q)
    assert imbalance < 2e-4 * work[-1]
    assert gap < 1e-10

    gaps, deviations = [], []
    for solref, step in SOFTNESS:
        mj, mj_gap, mj_qpos = hanging_legs_in_mujoco(text, solref, step, round(dt / step))
        hinges = [mj.jnt_qposadr[j] for j in range(mj.njnt) if mj.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]
        assert len(hinges) == 10 and len(mj_qpos) == len(traj.q)
        ours = np.array([to_mujoco(model, mj, *model.to_joint_space(q, v), np.zeros(js.nv))[0][hinges]
                         for q, v in zip(traj.q, traj.v)])
        gaps.append(mj_gap)
        deviations.append(float(np.max(np.abs(mj_qpos[:, hinges] - ours))))
    print(f"connect gap over 10 s: ncgen {gap:.2g} m; MuJoCo RK4, solref default / 0.002 / 0.0005 s: "
          + " / ".join(f"{g:.2g} m (hinge angles {e:.2g} rad from ncgen's)" for g, e in zip(gaps, deviations)))
    assert gaps[0] > 1e-4 and gaps[0] > gaps[1] > gaps[2]
    assert deviations[0] > 4 * deviations[1] > 16 * deviations[2] and deviations[2] < 5e-5
