"""MJCF joint ``range`` and ``frictionloss`` against MuJoCo, where the two laws must agree.

MuJoCo makes both soft constraints (``solref``/``solimp``); ncgen imports them as its own
joint laws (``ncgen.model.joint_dynamics``): the limit a one-sided spring-damper of stiffness
``LIMIT_STIFFNESS`` (rest penetration ``τ / k``), friction loss ``f·tanh(w / w_f)`` (a joint
loaded below ``f`` creeps at ``w_f·atanh(τ / f)``).  What agrees, checked here against MuJoCo
and against the closed form of statics and of sliding: the rest angle against a limit (within
the larger of the two laws' penetrations) and the limit's reaction moment ``m g L sin q``;
a joint held by its friction (both creep slower than ``w_f``, both friction moments equal the
load) and a joint sliding under a larger torque (acceleration ``(τ − f) / I``)."""
from __future__ import annotations

import numpy as np
import pytest

import ncgen as nc
from ncgen.model.joint_dynamics import FRICTION_VELOCITY, LIMIT_STIFFNESS

mujoco = pytest.importorskip("mujoco")

L, M, R = 0.5, 1.0, 0.05               # arm length (m), bob mass (kg) and radius (m)
INERTIA = M * L ** 2 + 0.4 * M * R ** 2                     # about the hinge, kg·m²
G = 9.81


def mujoco_run(text: str, t_end: float, qpos0: float = 0.0, ctrl: float | None = None, every: float = 0.5):
    """MuJoCo's (default Euler, 2 ms) run of ``text`` from rest at ``qpos0``: its data at the
    end and the joint rate every ``every`` s."""
    mj = mujoco.MjModel.from_xml_string(text)
    d = mujoco.MjData(mj)
    d.qpos[0] = qpos0
    if ctrl is not None:
        d.ctrl[0] = ctrl
    rates = [0.0]
    for _ in range(int(round(t_end / every))):
        for _ in range(int(round(every / mj.opt.timestep))):
            mujoco.mj_step(mj, d)
        rates.append(float(d.qvel[0]))
    mujoco.mj_forward(mj, d)
    return d, np.array(rates)


PENDULUM = f"""<mujoco><compiler angle="degree"/><option gravity="0 0 -{G}"/><worldbody>
  <body name="arm"><joint name="hinge" axis="0 1 0" range="-90 -30" limited="true" damping="2"/>
    <geom type="sphere" pos="0 0 -{L}" size="{R}" mass="{M}"/></body></worldbody></mujoco>"""


def test_a_pendulum_rests_against_its_limit_as_in_mujoco():
    """A pendulum released at −40° inside its range [−90°, −30°] swings up against the upper
    limit and rests there (5 s, joint damping).  Statics: the limit's moment carries gravity's,
    ``m g L sin(−q)`` at the rest angle — ncgen's ``k (q − upper)`` to 1e-8 N·m, MuJoCo's
    ``qfrc_constraint`` and ``efc_force`` to 1e-6 N·m.  ncgen's penetration is ``τ / k``
    (2.45e-4 rad), MuJoCo's 3.66e-4 rad (its default solref): the rest angles differ by less
    than the larger penetration (measured 1.2e-4 rad), the moments by 2.1e-4 relative."""
    upper = np.radians(-30)
    system = nc.System.from_mjcf(PENDULUM)
    assert system.joints[0].limits == pytest.approx({"lower": np.radians(-90), "upper": upper})
    model = system.build()
    q0, v0 = model.from_joint_space(np.array([np.radians(-40)]), np.zeros(1))
    traj = nc.simulate(model, 5.0, 0.5, q0=q0, v0=v0, method="joint", joint_dynamics=True, rtol=1e-10, atol=1e-12)
    ours, rate = float(traj.qj[-1, 0]), float(traj.vj[-1, 0])
    d, rates = mujoco_run(PENDULUM, 5.0, qpos0=np.radians(-40))
    theirs = float(d.qpos[0])
    assert abs(rate) < 1e-8 and abs(rates[-1]) < 1e-8                        # both at rest

    moment_ours = -LIMIT_STIFFNESS * (ours - upper)                          # the law's effort at rest
    assert moment_ours == pytest.approx(-M * G * L * np.sin(-ours), abs=1e-8)
    assert d.nefc == 1
    assert float(d.qfrc_constraint[0]) == pytest.approx(-M * G * L * np.sin(-theirs), abs=1e-6)
    assert float(d.efc_force[0]) == pytest.approx(-float(d.qfrc_constraint[0]), abs=1e-6)

    penetration_ours, penetration_theirs = ours - upper, theirs - upper
    assert penetration_ours == pytest.approx(M * G * L * np.sin(-ours) / LIMIT_STIFFNESS, rel=1e-6)
    assert 0 < penetration_ours < 3e-4 and 0 < penetration_theirs < 5e-4
    assert abs(ours - theirs) < max(penetration_ours, penetration_theirs)
    assert moment_ours == pytest.approx(float(d.qfrc_constraint[0]), rel=5e-4)


FRICTION = 1.0
WHEEL = f"""<mujoco><option gravity="0 0 -{G}"/><worldbody>
  <body name="arm"><joint name="hinge" axis="0 0 1" frictionloss="{FRICTION}"/>
    <geom type="sphere" pos="{L} 0 0" size="{R}" mass="{M}"/></body></worldbody>
  <actuator><motor joint="hinge" gear="1"/></actuator></mujoco>"""


def wheel_runs(tau: float):
    """The horizontal arm (vertical hinge: gravity has no moment) from rest under a constant
    torque ``tau`` for 1 s: ncgen's and MuJoCo's joint rates every 0.5 s, and MuJoCo's data."""
    system = nc.System.from_mjcf(WHEEL)
    assert system.joints[0].dynamics == {"friction": FRICTION}
    model = system.build()
    traj = nc.simulate(model, 1.0, 0.5, u=np.array([tau]), method="joint", joint_dynamics=True,
                       rtol=1e-10, atol=1e-12)
    d, theirs = mujoco_run(WHEEL, 1.0, ctrl=tau)
    return traj.vj[:, 0], theirs, d


def test_friction_loss_holds_a_joint_below_it_as_in_mujoco():
    """Torque τ = f / 2: both hold the joint.  ncgen creeps at ``w_f·atanh(τ / f)`` (its
    regularised law's closed form, 5.5e-3 rad/s), MuJoCo at 2.1e-3 rad/s (its soft friction
    constraint), both below ``w_f``; both friction moments equal −τ."""
    tau = 0.5 * FRICTION
    ours, theirs, d = wheel_runs(tau)
    assert ours[-1] == pytest.approx(FRICTION_VELOCITY * np.arctanh(tau / FRICTION), rel=1e-6)
    assert 0 < theirs[-1] < FRICTION_VELOCITY and abs(theirs[-1] - theirs[-2]) < 1e-9
    assert -FRICTION * np.tanh(ours[-1] / FRICTION_VELOCITY) == pytest.approx(-tau, abs=1e-8)
    assert d.nefc == 1 and float(d.efc_force[0]) == pytest.approx(-tau, abs=1e-8)


def test_friction_loss_slides_a_joint_above_it_as_in_mujoco():
    """Torque τ = 2 f: both slide with the acceleration ``(τ − f) / I`` (3.984 rad/s², rate
    change over the last 0.5 s, both within 1e-6 relative); MuJoCo's friction moment is −f
    and its rate at 1 s is ideal Coulomb's ``(τ − f) t / I`` (1e-6 relative).  ncgen's leads it
    by the impulse the regularised law lets through at small rates, ``w_f ∫₀^∞ f (1 − tanh x)
    / (τ − f tanh x) dx`` (4.62e-3 rad/s; to 1e-6 rad/s)."""
    from scipy.integrate import quad
    tau = 2.0 * FRICTION
    ours, theirs, d = wheel_runs(tau)
    closed = (tau - FRICTION) / INERTIA
    assert (ours[-1] - ours[-2]) / 0.5 == pytest.approx(closed, rel=1e-6)
    assert (theirs[-1] - theirs[-2]) / 0.5 == pytest.approx(closed, rel=1e-6)
    assert float(d.efc_force[0]) == pytest.approx(-FRICTION, abs=1e-8)
    assert theirs[-1] == pytest.approx(closed * 1.0, rel=1e-6)
    lead = FRICTION_VELOCITY * quad(lambda x: FRICTION * (1 - np.tanh(x)) / (tau - FRICTION * np.tanh(x)), 0, 40)[0]
    assert ours[-1] - closed * 1.0 == pytest.approx(lead, abs=1e-6)
