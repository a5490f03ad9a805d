"""MJCF import (ncgen.model.mjcf) against MuJoCo: the joint-space accelerations of the shipped
gymnasium and dm_control models at random states equal mj_forward's qacc (contacts, limits,
equality constraints and friction loss off in MuJoCo, the same passive forces), a passive
run equals MuJoCo's RK4 at a fine step, and malformed or unsupported MJCF is named with its
element and line."""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import ModelError
from ncgen.model.joint_dynamics import coordinate_laws
from ncgen.model.mjcf import MjcfWarning

mujoco = pytest.importorskip("mujoco")

from mjcf_reference import (JointMap, constrained_qacc, coupling_rows, joint_ode,  # noqa: E402
                            mujoco_free_dynamics, on_couplings, random_state, shipped_files)

FILES = shipped_files()
#: Shipped models that import without an unsupported-feature warning (checked by the test).
SUPPORTED = ["gymnasium/inverted_pendulum.xml", "gymnasium/hopper.xml", "dm_control/cheetah.xml",
             "dm_control/point_mass.xml", "dm_control/humanoid.xml",
             "gymnasium/inverted_double_pendulum.xml", "gymnasium/half_cheetah.xml", "gymnasium/walker2d.xml",
             "gymnasium/walker2d_v5.xml", "gymnasium/ant.xml", "gymnasium/humanoid.xml",
             "gymnasium/humanoidstandup.xml", "gymnasium/point.xml", "gymnasium/pusher.xml", "gymnasium/pusher_v5.xml",
             "gymnasium/reacher.xml", "dm_control/acrobot.xml", "dm_control/cartpole.xml", "dm_control/finger.xml",
             "dm_control/hopper.xml", "dm_control/humanoid_CMU.xml", "dm_control/manipulator.xml",
             "dm_control/pendulum.xml", "dm_control/reacher.xml", "dm_control/stacker.xml", "dm_control/walker.xml"]
#: Fast tier: planar roots and two slides (a point mass on a tendon-driven motor); the cheetah and the
#: humanoid (17 s) are slow: their joint sequences are covered fast by sequences.xml.
FAST = [k for k in SUPPORTED[:4] if k != "dm_control/cheetah.xml"]
SEQUENCES = Path(__file__).parent / "data" / "sequences.xml"


def import_quietly(source):
    """The system, failing on any MjcfWarning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", MjcfWarning)
        return nc.System.from_mjcf(source)


def without_friction_and_limits(system):
    """MuJoCo's frictionloss and limits are constraints (off in the reference); ncgen's are a
    regularised friction law and a penalty: compare without them."""
    for j in system.joints:
        for law in coordinate_laws(j):            # a joint sequence: one law per coordinate
            law.dynamics = {k: v for k, v in law.dynamics.items() if k != "friction"}
            law.limits = {}
    return system


def qacc_error(path, trials: int = 5, seed: int = 0, reference=None) -> float:
    """Largest |qacc_ncgen − qacc_mujoco| / max(1, |qacc_mujoco|) over random states and
    controls; MuJoCo runs the file ``reference`` (default: ``path``)."""
    system = without_friction_and_limits(import_quietly(path))
    model = system.build()
    mj = mujoco_free_dynamics(reference or path)
    jmap = JointMap(model, system, mj)
    ode = joint_ode(model)
    d = mujoco.MjData(mj)
    J = coupling_rows(mj)           # joint and tendon equalities: held exactly by ncgen (Mimic)
    rng = np.random.default_rng(seed)
    worst = 0.0
    for _ in range(trials):
        qpos, qvel = on_couplings(mj, J, *random_state(mj, rng))
        ctrl = rng.normal(size=mj.nu)
        d.qpos[:], d.qvel[:], d.ctrl[:] = qpos, qvel, ctrl
        mujoco.mj_forward(mj, d)
        expected = constrained_qacc(mj, d, J)
        assert np.max(np.abs(expected)) > 1e-3           # a state that moves
        qj, vj = jmap.to_ncgen(qpos, qvel)
        tau = system.actuation.tau(model, qj, vj, ctrl) if reference is None else ctrl   # exported: a motor a joint
        xdot = np.asarray(ode(0.0, np.r_[qj, vj], tau, np.zeros(model.np))[0]).ravel()
        qacc = jmap.acceleration_to_mujoco(qpos, qvel, xdot[len(qj):])
        worst = max(worst, np.max(np.abs(qacc - expected)) / max(1.0, np.max(np.abs(expected))))
    return worst


@pytest.mark.parametrize("key", [k if k in FAST else pytest.param(k, marks=pytest.mark.slow) for k in SUPPORTED])
def test_forward_dynamics_equals_mujoco(key):
    """Relative to 1e-8 (measured 1e-16 ... 1e-13; 6e-13 for manipulator and stacker, whose
    tendon equality ncgen holds exactly and the reference projects out of MuJoCo's
    unconstrained acceleration)."""
    if key not in FILES:
        pytest.skip(f"{key.split('/')[0]} is not installed (a test extra)")
    assert qacc_error(FILES[key], trials=5 if key not in FAST else 2) < 1e-8


@pytest.mark.slow      # imports all 33 files (~30 s); fast: the FAST files and sequences.xml
def test_every_shipped_file_without_warning_is_compared():
    """The list above is every shipped file that imports without a warning but lqr.xml (no
    moving body); with both packages installed they are at least 80 % of the files."""
    quiet = []
    for key, path in FILES.items():
        with warnings.catch_warnings():
            warnings.simplefilter("error", MjcfWarning)
            try:
                nc.System.from_mjcf(path)
            except (MjcfWarning, ModelError):
                continue
        quiet.append(key)
    assert sorted(set(quiet) - {"dm_control/lqr.xml"}) == sorted(k for k in SUPPORTED if k in FILES)
    if len(FILES) == 33:                    # gymnasium 1.x and dm_control 1.0.x both installed
        assert len(quiet) / len(FILES) >= 0.8


def test_joint_sequences_against_mujoco():
    """Several joints in one body, each form the import takes (three oblique slides, three
    perpendicular hinges at a point with springs, two oblique hinges through a point, two
    hinges on skew lines), under an oblique gravity with damping and motors: qacc as
    MuJoCo's to 1e-8 relative (measured 8e-13)."""
    system = import_quietly(SEQUENCES)
    assert [j.shape() for j in system.joints] == ["slides", "hinges3", "hinges2", "skew2"]
    assert system.build().joint_space.position_names[:3] == ["sx_sy_sz.sx", "sx_sy_sz.sy", "sx_sy_sz.sz"]
    assert qacc_error(SEQUENCES, trials=4) < 1e-8


def passive_runs(path, methods, t_end: float = 1.0, scale: float = 1.0):
    """``{method: worst |x_ncgen − x_MuJoCo|}`` over ``t_end`` s (every 0.1 s) of the file's
    passive motion from random joint rates (normal, ``scale`` rad/s or m/s; contacts, limits,
    friction loss off), ncgen
    at rtol 1e-11 against MuJoCo's RK4 at 1e-4 s; and the MuJoCo run's joint ranges."""
    system = without_friction_and_limits(import_quietly(path))
    model = system.build()
    mj = mujoco_free_dynamics(path)
    mj.opt.integrator, mj.opt.timestep = mujoco.mjtIntegrator.mjINT_RK4, 1e-4
    d = mujoco.MjData(mj)
    d.qvel[:] = np.random.default_rng(3).normal(0, scale, mj.nv)
    jmap = JointMap(model, system, mj)
    qj0, vj0 = jmap.to_ncgen(d.qpos.copy(), d.qvel.copy())
    q0, v0 = model.from_joint_space(qj0, vj0)
    ref = [qj0]
    for _ in range(int(round(t_end / 0.1))):
        for _ in range(1000):
            mujoco.mj_step(mj, d)
        ref.append(jmap.to_ncgen(d.qpos.copy(), d.qvel.copy())[0])
    ref = np.array(ref)
    out = {}
    for method in methods:
        traj = nc.simulate(model, t_end, 0.1, q0=q0, v0=v0, method=method, joint_dynamics=True, rtol=1e-11,
                           atol=1e-12)
        ours = np.array([model.to_joint_space(traj.q[k]) for k in range(len(traj.t))])
        out[method] = float(np.max(np.abs(ours - ref)))
    return out, np.ptp(ref, axis=0)


@pytest.mark.slow      # 1 s at rtol 1e-11 and 10 000 MuJoCo steps; fast: test_joint_sequences_against_mujoco (the
#                       same model's qacc), test_passive_run_equals_mujoco_rk4 (a run against MuJoCo's RK4)
def test_joint_sequences_run_as_mujoco_rk4_idas():
    """1 s of the sequences model in natural coordinates (IDAS: the sequences' equations,
    damping and springs as joint dynamics and forces) against MuJoCo's RK4: every joint
    coordinate within 1e-8 (measured 1.1e-10)."""
    errors, ranges = passive_runs(SEQUENCES, ["idas"])
    assert np.all(ranges > 0.1)
    assert errors["idas"] < 1e-8


@pytest.mark.slow
def test_humanoid_runs_as_mujoco_rk4():
    """1 s of dm_control's humanoid tumbling from random joint rates (free root, three-hinge
    hips, skew ankles, springs, armature, damping; contacts and limits off) in joint space
    against MuJoCo's RK4 at 1e-4 s: every coordinate within 1e-8 (measured 4.6e-13)."""
    key = "dm_control/humanoid.xml"
    if key not in FILES:
        pytest.skip("dm_control is not installed (a test extra)")
    errors, ranges = passive_runs(FILES[key], ["joint"])
    assert ranges.min() > 0.01
    assert errors["joint"] < 1e-8


@pytest.mark.slow
def test_joint_sequences_run_as_mujoco_rk4_joint_space():
    """The same run in joint space (compiled RK45 loop; measured 1.1e-10)."""
    errors, _ = passive_runs(SEQUENCES, ["joint"])
    assert errors["joint"] < 1e-8


CHAIN = """
<mujoco model="chain">
  <compiler angle="radian" eulerseq="zyx"/>
  <option gravity="0.3 -0.2 -9.81"/>
  <default>
    <joint damping="0.05" armature="0.01"/>
    <default class="soft"><joint stiffness="2" springref="0.3" damping="0.2"/></default>
    <geom density="500"/>
  </default>
  <worldbody>
    <body name="a" pos="0.1 0 1" euler="0.3 0.2 0.1" childclass="soft">
      <joint name="j1" type="hinge" axis="0 1 1" pos="0 0 0.05"/>
      <geom type="capsule" fromto="0 0 0 0.3 0.1 -0.2" size="0.04"/>
      <geom type="box" size="0.05 0.06 0.07" pos="0.1 0 0" axisangle="1 1 0 0.4"/>
      <body name="b" pos="0.3 0.1 -0.2" xyaxes="0 1 0 -1 0 0.2">
        <joint name="j2" type="slide" axis="1 0 0" stiffness="0" class="main"/>
        <geom type="cylinder" size="0.03 0.1" zaxis="1 0.2 0"/>
        <frame pos="0.01 0.02 0" euler="0.1 0 0.2">
          <geom type="ellipsoid" size="0.05 0.04 0.03" quat="0.9 0.1 0.3 0.2" mass="0.7"/>
        </frame>
        <body name="c" pos="0 0.2 0">
          <joint name="j3" axis="0.2 0.1 1"/>
          <inertial pos="0.02 0.1 0" mass="0.4" fullinertia="0.004 0.003 0.005 0.0002 -0.0001 0.0003"/>
          <geom type="sphere" size="0.05"/>
          <frame euler="0 0.3 0"><site name="tip" pos="0 0.2 0.1"/></frame>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator>
    <motor joint="j1" gear="3"/>
    <general joint="j3" gear="2" gainprm="1.5"/>
  </actuator>
</mujoco>
"""


def test_frames_geoms_defaults_against_mujoco(tmp_path):
    """Every orientation form, every solid geom, fromto, frames, fullinertia, defaults with childclass,
    stiffness with springref, armature and damping, motor and general actuators: qacc as
    MuJoCo's at random states, to 1e-8 relative."""
    path = tmp_path / "chain.xml"
    path.write_text(CHAIN)
    assert qacc_error(path, trials=4) < 1e-8


def test_include_and_tip_marker(tmp_path):
    """<include> pastes the included file's children; a site is a marker at MuJoCo's place."""
    (tmp_path / "parts.xml").write_text("<mujoco><default><joint damping='0.1'/></default></mujoco>")
    main = CHAIN.replace('<compiler angle="radian" eulerseq="zyx"/>',
                         '<compiler angle="radian" eulerseq="zyx"/><include file="parts.xml"/>')
    main = main.replace('<joint damping="0.05" armature="0.01"/>', '<joint armature="0.01"/>')
    path = tmp_path / "main.xml"
    path.write_text(main)
    system = import_quietly(path)
    assert {j.name: j.dynamics.get("damping") for j in system.joints} == {"j1": 0.2, "j2": 0.1, "j3": 0.2}
    mj = mujoco.MjModel.from_xml_path(str(path))
    d = mujoco.MjData(mj)
    mujoco.mj_forward(mj, d)
    c = system.member("c")
    np.testing.assert_allclose(c.p0 + c.R0 @ c.markers["tip"], d.site("tip").xpos, atol=1e-12)


def test_passive_run_equals_mujoco_rk4():
    """2 s of a passive hopper (planar root, armature, damping, gravity; ground contact and
    limits off) in ncgen's joint space against MuJoCo's RK4 at 1e-4 s: joints within 1e-6 (measured
    1.0e-13)."""
    key = "dm_control/hopper.xml"
    if key not in FILES:
        pytest.skip("dm_control is not installed (a test extra)")
    errors, ranges = passive_runs(FILES[key], ["joint"], t_end=2.0, scale=0.5)
    assert ranges[1] > 0.5                          # it falls
    assert errors["joint"] < 1e-6


@pytest.mark.parametrize("key", ["chain", "sequences"] + [pytest.param(k, marks=pytest.mark.slow) for k in (   # fast:
    "gymnasium/ant.xml", "dm_control/cheetah.xml", "dm_control/humanoid.xml")])          # chain, sequences
def test_round_trip_mjcf_ncgen_mjcf(key, tmp_path):
    """MJCF → ncgen → to_mjcf → MuJoCo: the exported file's qacc equals the imported model's
    (hence the original's, test above) to 1e-8 relative, free joint, planar root, joint
    sequences, springs, armature and damping included."""
    if key == "sequences":
        source = SEQUENCES
    elif key == "chain":
        source = tmp_path / "chain.xml"
        source.write_text(CHAIN)
    elif key in FILES:
        source = FILES[key]
    else:
        pytest.skip(f"{key.split('/')[0]} is not installed (a test extra)")
    exported = tmp_path / "exported.xml"
    import_quietly(source).build().to_mjcf(exported)
    assert qacc_error(source, trials=3, reference=exported) < 1e-8


def test_export_refuses_a_second_hinge_to_a_member():
    s = nc.System("loop")
    a = s.add_body("a", mass=1.0, inertia=np.eye(3) * 0.01, position=(0, 0, 0))
    s.add_joint(nc.Revolute(s.ground, a, at=(0, 0, 0), axis=(0, 1, 0)))
    s.add_joint(nc.Revolute(s.ground, a, at=(0, 0, 0), axis=(0, 1, 0), name="again"))
    with pytest.raises(ModelError, match="a Revolute joint is exported as a tree joint"):
        from ncgen.model.mjcf_export import mjcf_text
        mjcf_text(s)


def mujoco_loop_run(path, solref, t_end: float):
    """MuJoCo's RK4 at 1e-4 s on the loop (contacts off), its connect at ``solref``: the crank
    angle every 0.01 s and the largest closure gap (m)."""
    mj = mujoco.MjModel.from_xml_path(str(path))
    if solref is not None:
        mj.eq_solref[0] = solref
    mj.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    mj.opt.integrator, mj.opt.timestep = mujoco.mjtIntegrator.mjINT_RK4, 1e-4
    d = mujoco.MjData(mj)
    mujoco.mj_forward(mj, d)
    crank, gap = [d.qpos[0]], 0.0
    for _ in range(int(round(t_end / 0.01))):
        for _ in range(100):
            mujoco.mj_step(mj, d)
        gap = max(gap, np.linalg.norm(d.site("c_end").xpos - d.site("r_end").xpos))
        crank.append(d.qpos[0])
    return np.array(crank), gap


@pytest.mark.slow      # 2 s of IDAS and three 20 000-step MuJoCo runs; fast: test_loop_round_trip[rssr] imports and
#                       builds the same connect loop, test_weld_is_exact holds a closure exactly
def test_connect_closes_the_loop_exactly():
    """An RSSR loop closed by <equality><connect>: ncgen holds the closure to 1e-10 m over 2 s
    (shared point: measured 0); MuJoCo's soft connect opens by 2.6 mm at its default solref,
    and its crank angle converges to ncgen's as the constraint stiffens (1.4 rad apart at the
    default, 0.065 at solref 0.002, 0.0013 at 0.0005)."""
    path = Path(__file__).parent / "data" / "rssr.xml"
    model = import_quietly(path).build()
    assert model.dof == 2
    traj = nc.simulate(model, 2.0, 0.01, rtol=1e-10, atol=1e-12)
    gap = np.linalg.norm(traj.marker("coupler.c_end") - traj.marker("rocker.r_end"), axis=1)
    assert gap.max() < 1e-10
    crank = np.array([model.to_joint_space(q)[0] for q in traj.q])
    assert np.ptp(crank) > 1.0
    ref, mj_gap = mujoco_loop_run(path, None, 2.0)
    assert mj_gap > 1e-3
    differences = [np.max(np.abs(mujoco_loop_run(path, [tc, 1.0], 2.0)[0] - crank)) for tc in (0.002, 0.0005)]
    assert differences[1] < 5e-3 and differences[1] < differences[0] / 10


WELDED = """<mujoco><option gravity="0 0 -9.81"/><worldbody>
  <body name="a" pos="0 0 1"><joint name="h" axis="0 1 0.2"/><geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03"/>
    <body name="b" pos="0.3 0 0" euler="10 20 30">{joint}<geom type="box" size="0.05 0.1 0.02" pos="0.1 0 0"/></body>
  </body></worldbody>{equality}</mujoco>"""


def test_weld_is_exact():
    """<weld> between two bodies joined by a hinge: the pair is one rigid body, whose
    hinge acceleration MuJoCo gives exactly for the file with b merged into a (1e-10
    relative, random states)."""
    system = import_quietly(WELDED.format(joint='<joint name="k" axis="1 0 0"/>',
                                          equality='<equality><weld body1="a" body2="b"/></equality>'))
    with pytest.warns(UserWarning, match="dropping redundant constraints k.coincide"):   # the hinge k, welded
        model = system.build()
    assert model.dof == 1
    mj = mujoco.MjModel.from_xml_string(WELDED.format(joint="", equality=""))
    d = mujoco.MjData(mj)
    rng = np.random.default_rng(5)
    for _ in range(3):
        d.qpos[:], d.qvel[:] = rng.uniform(-2, 2, 1), rng.normal(size=1)
        mujoco.mj_forward(mj, d)
        q, v = model.from_joint_space({"h": d.qpos.copy()}, {"h": d.qvel.copy()})
        a, _ = nc.forward_dynamics(model, q, v, u=np.zeros(model.nu))
        aj = model.to_joint_space(q, v, a)[2]
        assert abs(aj[0] - d.qacc[0]) < 1e-10 * max(1.0, abs(d.qacc[0]))


COUPLED = """<mujoco><worldbody>
  <body name="p1" pos="0 0 1"><joint name="j1" axis="0 1 0"/><geom type="capsule" fromto="0 0 0 0.4 0 0" size="0.03"/></body>
  <body name="p2" pos="0 0.5 1"><joint name="j2" axis="0 1 0"/><geom type="capsule" fromto="0 0 0 0 0 -0.5" size="0.03"/>
  </body></worldbody><equality><joint joint1="j1" joint2="j2" polycoef="0 0.5 0 0 0"/></equality></mujoco>"""


@pytest.mark.slow      # three runs (IDAS at 1e-10, two 10 000-step MuJoCo runs); fast:
#                       test_armature_on_coupled_joints_equals_mujoco (the same coupling's qacc),
#                       test_loop_round_trip[rssr]
def test_joint_equality_is_exact():
    """<equality><joint polycoef="0 0.5 ...">: ncgen holds x1 = 0.5 x2 to round-off over 1 s;
    MuJoCo's soft coupling converges to ncgen's run as it stiffens (x2 apart by 2.3e-4 rad at
    the default solref, 4.9e-6 at 0.002, 3.1e-7 at 0.0005)."""
    model = import_quietly(COUPLED).build()
    assert model.dof == 1
    v0 = model.from_joint_space({"j2": np.zeros(1)}, {"j2": np.array([1.0])})[1]
    traj = nc.simulate(model, 1.0, 0.01, v0=v0, rtol=1e-10, atol=1e-12)
    qj = np.array([model.to_joint_space(q) for q in traj.q])
    names = model.joint_names
    x1, x2 = qj[:, names.index("j1")], qj[:, names.index("j2")]
    assert np.max(np.abs(x1 - 0.5 * x2)) < 1e-10 and np.ptp(x2) > 0.5
    diffs = []
    for tc in (0.002, 0.0005):
        mj = mujoco.MjModel.from_xml_string(COUPLED)
        mj.eq_solref[0] = [tc, 1.0]
        mj.opt.integrator, mj.opt.timestep = mujoco.mjtIntegrator.mjINT_RK4, 1e-4
        d = mujoco.MjData(mj)
        d.qvel[:] = [0.5, 1.0]
        ref = [d.qpos[1]]
        for _ in range(100):
            for _ in range(100):
                mujoco.mj_step(mj, d)
            ref.append(d.qpos[1])
        diffs.append(np.max(np.abs(np.array(ref) - x2)))
    assert diffs[1] < 1e-6 and diffs[1] < diffs[0] / 3


def test_armature_on_coupled_joints_equals_mujoco(tmp_path):
    """Armature (and damping) on hinges coupled by ``<equality><joint>`` (a ``Mimic`` in ncgen,
    as the Panda's fingers): the joint-space ODE, each armature reflected through the
    coupling's ratio, equals ``mj_forward``'s ``qacc`` with the coupling held exactly
    (``a₀ − M⁻¹Jᵀ(JM⁻¹Jᵀ)⁻¹J a₀``, MuJoCo's mass matrix with its armature) to 1e-8 relative."""
    path = tmp_path / "coupled_armature.xml"
    path.write_text(COUPLED.replace('name="j1" axis="0 1 0"/>', 'name="j1" axis="0 1 0" armature="0.3" damping="0.2"/>')
                    .replace('name="j2" axis="0 1 0"/>', 'name="j2" axis="0 1 0" armature="0.05"/>'))
    assert qacc_error(path, trials=4) < 1e-8


@pytest.mark.parametrize("source", ["rssr", pytest.param("coupled", marks=pytest.mark.slow)])   # fast: rssr
def test_loop_round_trip(source, tmp_path):
    """A loop model (connect; a joint coupling) exported back to MJCF (loops as <equality>)
    runs in MuJoCo as the original file does: 1 s of RK4 at 1e-4 s, joint angles within 1e-6
    rad."""
    if source == "rssr":
        original = Path(__file__).parent / "data" / "rssr.xml"
    else:
        original = tmp_path / "coupled.xml"
        original.write_text(COUPLED)
    exported = tmp_path / "exported.xml"
    import_quietly(original).build().to_mjcf(exported)
    runs = []
    for path in (original, exported):
        mj = mujoco.MjModel.from_xml_path(str(path))
        assert mj.neq == 1
        mj.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
        mj.opt.integrator, mj.opt.timestep = mujoco.mjtIntegrator.mjINT_RK4, 1e-4
        d = mujoco.MjData(mj)
        hinges = [mujoco.mj_name2id(mj, mujoco.mjtObj.mjOBJ_JOINT, n) for n in
                  (("crank", "rocker") if source == "rssr" else ("j1", "j2"))]
        adr = [mj.jnt_qposadr[k] for k in hinges]
        d.qvel[[mj.jnt_dofadr[k] for k in hinges[-1:]]] = 0.0 if source == "rssr" else 1.0
        if source == "coupled":
            d.qvel[mj.jnt_dofadr[hinges[0]]] = 0.5
        out = []
        for _ in range(100):
            for _ in range(100):
                mujoco.mj_step(mj, d)
            out.append(d.qpos[adr].copy())
        runs.append(np.array(out))
    assert np.ptp(runs[0]) > 0.1
    assert np.max(np.abs(runs[0] - runs[1])) < 1e-6


def test_unsupported_named_in_one_warning():
    text = """<mujoco><option viscosity="0.1"/><worldbody>
      <body name="a"><joint name="j" type="hinge"/><geom size="0.1"/>
        <body name="b" pos="0 0 -0.5"><joint name="k" type="hinge"/><geom size="0.1"/></body></body>
      </worldbody>
      <tendon><fixed name="t" stiffness="1"><joint joint="j" coef="1"/></fixed></tendon>
      <actuator><position joint="j" kp="10" timeconst="0.1"/></actuator>
      <equality><joint joint1="j" joint2="k" polycoef="0 1 0.5 0 0"/></equality></mujoco>"""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        system = nc.System.from_mjcf(text)
    ours = [w for w in caught if issubclass(w.category, MjcfWarning)]
    assert len(ours) == 1
    message = str(ours[0].message)
    for part in ("text:1 <option>: viscosity", "text:5 <fixed>: tendon fixed 't' (stiffness not modelled)",
                 "text:6 <position>: actuator 'actuator0': timeconst",
                 "text:7 <joint>: equality joint"):
        assert part in message, (part, message)
    assert len(system.mjcf_unsupported) == 4


@pytest.mark.parametrize("text, expected", [
    ("<mujoco><worldbody><bogus/></worldbody></mujoco>", "MJCF text:1: unknown element <bogus>"),
    ("<mujoco><worldbody><body><joint/>\n<geom size='0.1 x'/></body></worldbody></mujoco>",
     "MJCF text:2: <geom size='0.1 x'>: expected numbers"),
    ("<mujoco><worldbody><body pos='0 0'><joint/><geom size='1'/></body></worldbody></mujoco>",
     "MJCF text:1: <body pos='0 0'>: expected 3 number(s), found 2"),
    ("<mujoco><worldbody><body><joint/><geom size='1'/></body></worldbody>\n"
     "<actuator><motor joint='nope'/></actuator></mujoco>", "MJCF text:2: <motor joint='nope'>: no joint of that name"),
    ("<mujoco><worldbody><body><joint/></body></worldbody></mujoco>", "moves (joints) but has no mass"),
    ("<mujoco><worldbody><body><joint class='x'/><geom size='1'/></body></worldbody></mujoco>",
     "uses class 'x', which no <default> defines"),
    ("<mujoco><worldbody><body><joint/><geom size='1'/></worldbody></mujoco>", "not well-formed XML"),
    ("<mujoco><include file='missing.xml'/></mujoco>", "<include file='missing.xml'>: no file"),
    ("<robot/>", "expected a <mujoco> root element, found <robot>"),
    ("<mujoco><worldbody><body><frame><joint/></frame><geom size='1'/></body></worldbody></mujoco>",
     "MJCF text:1: <joint> inside a <frame>"),
    ("<mujoco><worldbody><body name='a'><joint/><geom size='1'/></body></worldbody>\n"
     "<equality><connect body1='a' body2='nope' anchor='0 0 0'/></equality></mujoco>",
     "MJCF text:2: <connect body2='nope'>: no body of that name"),
    ("<mujoco><worldbody><body><joint type='hinge'/><joint type='hinge'/><geom size='1'/></body></worldbody>"
     "</mujoco>", "MJCF text:1: body 'body1', joints hinge0, hinge1: joint 'hinge0_hinge1' "
     "(JointSequence ground–body1): two hinges about parallel axes"),
    ("<mujoco><worldbody><body><joint type='hinge'/><joint type='ball'/><geom size='1'/></body></worldbody>"
     "</mujoco>", "MJCF text:1: a ball joint in body 'body1' with other joints"),
    ("<mujoco><worldbody><body><joint/><inertial mass='1' diaginertia='1 1 3'/></body></worldbody></mujoco>",
     "the inertia tensor is not physical"),
    ("<mujoco><worldbody><body name='a'><joint/><geom size='1'/><body name='b'><geom size='1'/></body></body>"
     "</worldbody>\n<equality><connect body1='a' body2='b' anchor='0 0 0'/></equality></mujoco>",
     "MJCF text:2: <connect>: body1 and body2 move together (one rigid group)"),
])
def test_malformed_mjcf_is_named(text, expected):
    with pytest.raises(ModelError) as e:
        nc.System.from_mjcf(text)
    assert expected in str(e.value)


def test_an_include_loop_is_named(tmp_path):
    """Files that include each other: the error names the element, its line and the chain."""
    (tmp_path / "a.xml").write_text("<mujoco>\n<include file='b.xml'/></mujoco>")
    (tmp_path / "b.xml").write_text("<mujoco><include file='a.xml'/></mujoco>")
    with pytest.raises(ModelError, match=r"MJCF b\.xml:1: <include file='a\.xml'> includes itself "
                                         r"\(through a\.xml → b\.xml\)"):
        nc.System.from_mjcf(tmp_path / "a.xml")


def test_actuator_gear_rows_follow_tau():
    """Unnamed joints take tau components too; a motor's gear lands in its joint's row."""
    s = import_quietly("""<mujoco><worldbody><body><joint axis="0 1 0"/><geom size="0.1"/>
      <body pos="0 0 -0.5" name="b"><joint name="k" axis="1 0 0"/><geom size="0.1"/></body></body></worldbody>
      <actuator><motor joint="k" gear="7" ctrlrange="-1 1"/></actuator></mujoco>""")
    assert s.actuator_gear.tolist() == [[0.0], [7.0]]
    assert s.actuators == [{"name": "actuator0", "kind": "motor", "joint": "k", "gear": 7.0, "gain": (1.0, 0.0, 0.0),
                            "bias": (0.0, 0.0, 0.0), "ctrlrange": (-1.0, 1.0), "forcerange": None}]
    assert s.build().nu == 2


def test_cli_loads_mjcf(tmp_path):
    from ncgen.cli.common import load_system
    path = tmp_path / "chain.xml"
    path.write_text(CHAIN)
    system = load_system(str(path))
    assert [j.name for j in system.joints] == ["j1", "j2", "j3"]
    assert [f.name for f in system.forces] == ["j1_spring", "j3_spring"]      # j3 inherits the childclass
    with pytest.raises(ModelError, match="an MJCF model"):
        load_system(str(path), floating_base=True)


@pytest.mark.slow      # a compile from an empty cache; fast: test_cli_loads_mjcf, tests/test_cli_simulate.py (the
#                       store's second run)
def test_cli_simulates_an_mjcf_file_twice(tmp_path, monkeypatch):
    """``ncgen simulate model.xml``: the second run (model read from the store of built
    models) gives the first run's trajectory."""
    from ncgen.cli import main
    monkeypatch.setenv("NCGEN_CACHE_DIR", str(tmp_path / "cache"))
    path = tmp_path / "chain.xml"
    path.write_text(CHAIN)
    runs = []
    for k in range(2):
        out = tmp_path / f"run{k}.npz"
        assert main(["simulate", str(path), "--t-end", "0.05", "-o", str(out)]) in (0, None)
        runs.append(np.load(out))
    assert np.ptp(runs[0]["q"]) > 0
    for key in ("t", "q", "v"):
        assert np.array_equal(runs[0][key], runs[1][key]), key


@pytest.mark.slow      # a benchmark smoke; fast: test_connect_closes_the_loop_exactly
def test_loop_closure_script_runs():
    import subprocess
    import sys
    script = Path(__file__).resolve().parents[1] / "benchmarks" / "mjcf_loop_closure.py"
    out = subprocess.run([sys.executable, str(script), "--t-end", "0.2"], capture_output=True, text=True,
                         timeout=600, check=True).stdout
    gaps = [float(line.split("=")[-1].split()[0]) for line in out.splitlines() if "anchor distance" in line]
    assert len(gaps) == 3 and gaps[0] < 1e-10                   # ncgen's anchors shared
    assert all(g > 1e-5 for g in gaps[1:])                      # MuJoCo's soft connect opens


@pytest.mark.slow      # imports all 33 files again (~35 s); fast: the FAST files
def test_coverage_script_runs():
    import subprocess
    import sys
    script = Path(__file__).resolve().parents[1] / "benchmarks" / "mjcf_coverage.py"
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=600, check=True).stdout
    assert "import without an unsupported-feature warning" in out
