"""MuJoCo Menagerie models: an arm (Universal Robots UR5e), a quadruped (Unitree Go1) and
Agility's Cassie, whose leg loops are written with ``<equality><connect>``.

The Menagerie is not committed here (see tests/data/README.md): these tests read a checkout
of github.com/google-deepmind/mujoco_menagerie (or a folder with its layout) named by
``$NCGEN_MENAGERIE`` and are skipped without it.  MuJoCo, the reference, loads each file with
its mesh geoms taken out (their mesh files need not be present; the models' inertials are
explicit).  Checked: the import names what it leaves out in its one warning (element and
line); ``mj_forward``'s ``qacc`` (contacts, limits, friction loss off; the same passive
forces) equals ncgen's to 1e-8 relative at random states, Cassie's with its connects held
exactly in the reference (``J qacc + J̇ qvel = 0``, MuJoCo's mass matrix); ncgen holds
Cassie's loops to 1e-10 m over a run (MuJoCo's soft constraint beside it:
``benchmarks/mjcf_loop_closure.py``)."""
from __future__ import annotations

import os
import re
import warnings
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.model.mjcf import MjcfWarning

mujoco = pytest.importorskip("mujoco")

from mjcf_reference import (JointMap, constrained_qacc, coupling_rows, joint_ode, loop_qacc,  # noqa: E402
                            mujoco_without_meshes, on_couplings, on_loops, random_state, to_mujoco)
from test_mjcf import without_friction_and_limits  # noqa: E402

ROOT = Path(os.environ.get("NCGEN_MENAGERIE", "")) if os.environ.get("NCGEN_MENAGERIE") else None
ARM, QUADRUPED, CASSIE = "universal_robots_ur5e/ur5e.xml", "unitree_go1/go1.xml", "agility_cassie/cassie.xml"
#: Further arms, checked when the checkout has them: Franka's Panda (general servos, a finger
#: tendon and a joint equality) and Kinova's Gen3 (position servos with kv).
PANDA, GEN3 = "franka_emika_panda/panda.xml", "kinova_gen3/gen3.xml"
#: What each import leaves out, as its warning names it: (line, element, what); the arm's and
#: the quadruped's position servos are imported (ncgen.model.mjcf_actuators).
LEFT_OUT = {
    ARM: [],
    QUADRUPED: [],
    CASSIE: [(82, "joint", "damping on a ball joint"), (149, "joint", "damping on a ball joint")],
    PANDA: [],
    GEN3: [],
}

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(ROOT is None or not ROOT.is_dir(),
                                 reason="$NCGEN_MENAGERIE (a mujoco_menagerie checkout) is not set")]


def imported(name):
    if not (ROOT / name).is_file():
        pytest.skip(f"{name} is not in $NCGEN_MENAGERIE")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        system = nc.System.from_mjcf(ROOT / name)
    return system, [str(w.message) for w in caught if issubclass(w.category, MjcfWarning)]


@pytest.mark.parametrize("name", [ARM, QUADRUPED, CASSIE, PANDA, GEN3])
def test_import_names_what_it_leaves_out(name):
    system, said = imported(name)
    assert len(said) == (1 if LEFT_OUT[name] else 0)
    if not said:
        assert system.mjcf_unsupported == []
        return
    items = said[0].split(": ", 2)[2].split("; ")
    assert len(items) == len(LEFT_OUT[name]) == len(system.mjcf_unsupported)
    for item, (line, tag, what) in zip(items, LEFT_OUT[name]):
        assert re.match(rf"{re.escape(Path(name).name)}:{line} <{tag}>: {re.escape(what)}", item), item


@pytest.mark.parametrize("name", [ARM, QUADRUPED, PANDA, GEN3])
def test_tree_models_accelerate_as_in_mujoco(name):
    """Joint-space ODE (damping, armature) against ``mj_forward`` at random states and
    controls, the actuators (position servos, general servos, force-clamped; the Panda's
    on a fixed tendon) as MuJoCo computes them; a joint equality (the Panda's fingers, a
    ``Mimic`` in ncgen) held exactly in the reference (``a₀ − M⁻¹Jᵀ(JM⁻¹Jᵀ)⁻¹J a₀``, the
    states on the coupling)."""
    system = without_friction_and_limits(imported(name)[0])
    model = system.build()
    mj = mujoco_without_meshes(ROOT / name)
    jmap, ode, d = JointMap(model, system, mj), joint_ode(model), mujoco.MjData(mj)
    J = coupling_rows(mj)
    assert len(J) == (1 if name == PANDA else 0)
    rng = np.random.default_rng(3)
    worst = 0.0
    for _ in range(5):
        d.qpos[:], d.qvel[:] = on_couplings(mj, J, *random_state(mj, rng))
        d.ctrl[:] = rng.normal(size=mj.nu)
        mujoco.mj_forward(mj, d)
        expected = constrained_qacc(mj, d, J)
        qj, vj = jmap.to_ncgen(d.qpos, d.qvel)
        tau = system.actuation.tau(model, qj, vj, d.ctrl)
        xdot = np.asarray(ode(0.0, np.r_[qj, vj], tau, np.zeros(model.np))[0]).ravel()
        qacc = jmap.acceleration_to_mujoco(d.qpos, d.qvel, xdot[len(qj):])
        assert np.max(np.abs(expected)) > 1e-3
        worst = max(worst, np.max(np.abs(qacc - expected)) / max(1.0, np.max(np.abs(expected))))
    assert worst < 1e-8


@pytest.fixture(scope="module")
def cassie():
    system, _ = imported(CASSIE)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")              # the foot loops' dependent rows, named at build
        return system, system.build()


def test_cassie_accelerates_as_mujoco_with_its_loops_held(cassie):
    """Random states on the loops, random motor commands:
    ncgen's accelerations (natural coordinates, mapped to MuJoCo's dofs) equal MuJoCo's with
    the connects held exactly; joint damping and armature off in MuJoCo (ncgen's accel has
    neither: they act in joint-space simulation), springs on."""
    system, model = cassie
    mj = mujoco_without_meshes(ROOT / CASSIE)
    mj.dof_damping[:] = 0.0
    mj.dof_armature[:] = 0.0
    d = mujoco.MjData(mj)
    rng = np.random.default_rng(5)
    worst = 0.0
    for _ in range(4):
        q, v = on_loops(model, rng, 0.1)
        ctrl = rng.uniform(-1.0, 1.0, mj.nu)
        assert all(a["kind"] == "motor" and a["forcerange"] is None and (a["ctrlrange"] is None or (
            a["ctrlrange"][0] <= -1 and a["ctrlrange"][1] >= 1)) for a in system.actuators)
        tau = system.actuator_gear @ ctrl          # motors (gain 1, no bias) inside their ctrlrange
        a, _ = model.accel(q, v, u=tau)
        qj, vj, aj = model.to_joint_space(q, v, np.asarray(a).ravel())
        qpos, qvel, qacc = to_mujoco(model, mj, qj, vj, aj)
        d.qpos[:], d.qvel[:], d.ctrl[:] = qpos, qvel, ctrl
        mujoco.mj_forward(mj, d)
        expected = loop_qacc(mj, d)
        assert np.max(np.abs(expected)) > 1e-2
        worst = max(worst, np.max(np.abs(qacc - expected)) / max(1.0, np.max(np.abs(expected))))
    assert worst < 1e-8


def test_cassie_loops_stay_closed(cassie):
    """Each connect's two anchors (body1's anchor, and the point of body2 there initially)
    stay within 1e-10 m over 0.3 s of falling and flailing from random joint rates (IDAS,
    rtol 1e-10; longer runs beside MuJoCo's: benchmarks/mjcf_loop_closure.py)."""
    system, model = cassie
    _, v0 = on_loops(model, np.random.default_rng(8), 0.0)
    traj = nc.simulate(model, 0.3, 0.01, v0=v0, rtol=1e-10, atol=1e-12)
    pairs = [("left_plantar_rod", "left_foot", 0.35012), ("left_achilles_rod", "left_heel_spring", 0.5012),
             ("right_plantar_rod", "right_foot", 0.35012), ("right_achilles_rod", "right_heel_spring", 0.5012)]
    gap = 0.0
    for body1, body2, x in pairs:
        R1, p1 = model.frame_pose(body1, model.q0)
        R2, p2 = model.frame_pose(body2, model.q0)
        a1 = np.array([x, 0.0, 0.0])
        a2 = R2.T @ (p1 + R1 @ a1 - p2)                  # body2's point at the anchor, initially
        for q in traj.q:
            R1, p1 = model.frame_pose(body1, q)
            R2, p2 = model.frame_pose(body2, q)
            gap = max(gap, float(np.linalg.norm(p1 + R1 @ a1 - p2 - R2 @ a2)))
    assert np.ptp(traj.q, axis=0).max() > 0.1 and gap < 1e-10
