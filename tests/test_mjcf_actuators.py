"""MJCF actuators (ncgen.model.mjcf_actuators) against MuJoCo: motor, position, velocity,
damper and general (affine gain and bias) on hinges, a slide and a fixed tendon, with
ctrlrange, forcerange and a joint's actuatorfrcrange clamps (tests/data/actuators.xml): the
actuator forces equal MuJoCo's ``actuator_force``/``qfrc_actuator``, the accelerations
``mj_forward``'s ``qacc``, and a run under the compiled controller MuJoCo's RK4."""
from __future__ import annotations

import pickle
import warnings
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import ModelError
from ncgen.model.mjcf import MjcfWarning

mujoco = pytest.importorskip("mujoco")

from mjcf_reference import JointMap, joint_ode, mujoco_free_dynamics, random_state  # noqa: E402
from test_mjcf import import_quietly, without_friction_and_limits  # noqa: E402

ACTUATORS = Path(__file__).parent / "data" / "actuators.xml"


@pytest.fixture(scope="module")
def imported():
    system = without_friction_and_limits(import_quietly(ACTUATORS))
    model = system.build()
    mj = mujoco_free_dynamics(ACTUATORS)
    return system, model, mj, JointMap(model, system, mj)


def states(mj, n: int, seed: int = 0):
    """Random states and controls (normal, σ = 2: most ctrl and force clamps act somewhere)."""
    rng = np.random.default_rng(seed)
    for _ in range(n):
        qpos, qvel = random_state(mj, rng)
        yield qpos, qvel, rng.normal(0.0, 2.0, mj.nu)


def test_every_kind_is_imported(imported):
    system = imported[0]
    assert [a["kind"] for a in system.actuators] == ["motor", "position", "velocity", "position", "damper",
                                                     "general", "position"]
    assert system.actuation.joint_ranges == {1: (-1.5, 2.0)}
    assert system.actuator_gear[:, 5].tolist() == [0, 0, 0, 1.5 * 0.7, 1.5 * -0.4]     # gear × tendon coef


def test_actuator_forces_equal_mujoco(imported):
    """f and τ (forces after the clamps, generalised forces) as MuJoCo's to 1e-12 relative;
    every clamp acts at one of the states at least."""
    system, model, mj, jmap = imported
    d = mujoco.MjData(mj)
    clamped = np.zeros(3, bool)           # ctrl, force, joint clamps seen
    for qpos, qvel, ctrl in states(mj, 8):
        d.qpos[:], d.qvel[:], d.ctrl[:] = qpos, qvel, ctrl
        mujoco.mj_forward(mj, d)
        qj, vj = jmap.to_ncgen(qpos, qvel)
        rows = system.actuation.rows(model)
        f, tau = system.actuation.forces(qj[[r for r, _ in rows]], vj[[r for _, r in rows]], ctrl)
        f, tau = (np.asarray(ca.evalf(x), float).ravel() for x in (f, tau))
        assert np.allclose(f, d.actuator_force, rtol=1e-12, atol=1e-12 * np.max(np.abs(d.actuator_force)))
        assert np.allclose(tau, [d.qfrc_actuator[mj.jnt_dofadr[mujoco.mj_name2id(mj, mujoco.mjtObj.mjOBJ_JOINT, n)]]
                                 for n in ("ha", "hb", "sc", "hd", "he")], rtol=1e-12, atol=1e-12)
        clamped |= [np.any(np.abs(ctrl[[0, 1, 4]]) > [0.8, 1, 2]), np.any(np.abs(f[[1, 5]]) == [6, 2.5]) or
                    np.any(f[[1, 5]] == [-6, -2]), tau[1] in (-1.5, 2.0)]
    assert clamped.all(), clamped


def test_accelerations_equal_mujoco(imported):
    """Joint-space ODE with the actuation's τ against ``mj_forward`` (ctrl clamped as MuJoCo
    does): 1e-8 relative (measured ~1e-14)."""
    system, model, mj, jmap = imported
    ode, d, worst = joint_ode(model), mujoco.MjData(mj), 0.0
    for qpos, qvel, ctrl in states(mj, 6, seed=1):
        d.qpos[:], d.qvel[:], d.ctrl[:] = qpos, qvel, ctrl
        mujoco.mj_forward(mj, d)
        qj, vj = jmap.to_ncgen(qpos, qvel)
        tau = system.actuation.tau(model, qj, vj, ctrl)
        xdot = np.asarray(ode(0.0, np.r_[qj, vj], tau, np.zeros(model.np))[0]).ravel()
        qacc = jmap.acceleration_to_mujoco(qpos, qvel, xdot[len(qj):])
        worst = max(worst, np.max(np.abs(qacc - d.qacc)) / max(1.0, np.max(np.abs(d.qacc))))
    assert worst < 1e-8


def test_compiled_controller_runs_as_mujoco_rk4(imported):
    """0.5 s under constant controls inside the clamps' ranges (the servos track, the damper
    brakes) with the actuators as a compiled controller, joint space (RK45, rtol 1e-11)
    against MuJoCo's RK4 at 1e-4 s: every joint coordinate within 1e-7."""
    system, model, mj, jmap = imported
    ctrl = np.array([0.3, 0.5, -0.2, 0.05, 1.0, 0.4, -0.3])
    mj.opt.integrator, mj.opt.timestep = mujoco.mjtIntegrator.mjINT_RK4, 1e-4
    d = mujoco.MjData(mj)
    d.qvel[:] = np.random.default_rng(4).normal(0, 1, mj.nv)
    d.ctrl[:] = ctrl
    qj0, vj0 = jmap.to_ncgen(d.qpos.copy(), d.qvel.copy())
    ref = [qj0]
    for _ in range(5):
        for _ in range(1000):
            mujoco.mj_step(mj, d)
        ref.append(jmap.to_ncgen(d.qpos.copy(), d.qvel.copy())[0])
    q0, v0 = model.from_joint_space(qj0, vj0)
    traj = nc.simulate(model, 0.5, 0.1, q0=q0, v0=v0, method="joint", u=system.actuation.controller(ctrl),
                       joint_dynamics=True, rtol=1e-11, atol=1e-12)
    ours = np.array([model.to_joint_space(traj.q[k]) for k in range(len(traj.t))])
    assert np.ptp(np.array(ref), axis=0).min() > 1e-3
    assert np.max(np.abs(ours - np.array(ref))) < 1e-7


def test_the_actuation_survives_the_store_and_pickles(tmp_path, monkeypatch, imported):
    """A file read from the store of read files, and a pickled system, keep the actuation,
    the gear matrix and the imported joints' ``ref``."""
    from ncgen.codegen import model_cache
    monkeypatch.setenv("NCGEN_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv(model_cache.ENV, raising=False)
    system, model, mj, jmap = imported
    qj, vj = jmap.to_ncgen(*random_state(mj, np.random.default_rng(2)))
    ctrl = np.linspace(-1, 1, mj.nu)
    expected = system.actuation.tau(model, qj, vj, ctrl)
    import_quietly(ACTUATORS)
    again = import_quietly(ACTUATORS)                    # from the store
    for other in (again, pickle.loads(pickle.dumps(again))):
        assert np.array_equal(other.actuator_gear, system.actuator_gear)
        assert other.actuators == system.actuators and other.tendons == system.tendons
        assert other.joints[0].mjcf_ref == pytest.approx(np.radians(10))
        assert np.array_equal(other.actuation.tau(model, qj, vj, ctrl), expected)


BODY = "<worldbody><body><joint name='h'/><geom size='0.1'/></body></worldbody>"


@pytest.mark.parametrize("actuator, said", [
    ("<position joint='h' kp='3' timeconst='0.1'/>", "timeconst (activation dynamics"),
    ("<intvelocity joint='h' kp='3'/>", "actuator intvelocity 'actuator0' (only motor, position"),
    ("<general joint='h' dyntype='filter'/>", "dyntype='filter'"),
    ("<general joint='h' gaintype='muscle'/>", "gaintype='muscle'"),
])
def test_unsupported_actuators_are_named(actuator, said):
    with pytest.warns(MjcfWarning, match=r"text:2 <\w+>: ") as caught:
        s = nc.System.from_mjcf(f"<mujoco>{BODY}\n<actuator>{actuator}</actuator></mujoco>")
    assert said in str(caught[0].message) and s.actuation.nu == 0


def test_bad_ranges_are_named():
    with pytest.raises(ModelError, match=r"text:2: <motor ctrlrange='1 -1'>: the lower bound is above the upper"):
        nc.System.from_mjcf(f"<mujoco>{BODY}\n<actuator><motor joint='h' ctrlrange='1 -1'/></actuator></mujoco>")
    with pytest.raises(ModelError, match="ctrl: expected 1 finite numbers"):
        with warnings.catch_warnings():
            warnings.simplefilter("error", MjcfWarning)
            nc.System.from_mjcf(f"<mujoco>{BODY}<actuator><motor joint='h'/></actuator></mujoco>") \
                .actuation.controller([1.0, 2.0])


def test_inheritrange_gives_mujocos_ctrlrange():
    """``inheritrange`` r: the ctrlrange is the joint's range (degrees here, ``ref`` ≠ 0)
    scaled by r about its centre, as MuJoCo compiles it (``actuator_ctrlrange``); on a joint
    without a range it is an error, as in MuJoCo."""
    text = """<mujoco><compiler angle="degree"/><worldbody><body><joint name='h' range='-30 90' ref='10'/>
      <geom size='0.1'/></body></worldbody><actuator><position joint='h' kp='5' inheritrange='0.8'/></actuator></mujoco>"""
    mj = mujoco.MjModel.from_xml_string(text)
    s = import_quietly(text)
    assert np.allclose(s.actuators[0]["ctrlrange"], mj.actuator_ctrlrange[0], rtol=0, atol=1e-15)
    with pytest.raises(ModelError, match=r"text:2: <position inheritrange=...> on joint 'h', which has no range"):
        nc.System.from_mjcf(text.replace(" range='-30 90'", ""))
