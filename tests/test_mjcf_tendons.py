"""Sites as markers and spatial tendons through sites as cables (ClusteredCable), against
MuJoCo on tests/data/tendons.xml: the markers' positions equal ``site_xpos``, the cable
lengths ``ten_length``, and the accelerations with the tendons' spring-dampers acting
``mj_forward``'s ``qacc`` at random states where both tendons are taut."""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import ModelError
from ncgen.model.mjcf import MjcfWarning
from ncgen.runtime.outputs import markers

mujoco = pytest.importorskip("mujoco")

from mjcf_reference import JointMap, joint_ode, mujoco_free_dynamics, random_state  # noqa: E402
from test_mjcf import import_quietly  # noqa: E402

TENDONS = Path(__file__).parent / "data" / "tendons.xml"


@pytest.fixture(scope="module")
def imported():
    system = import_quietly(TENDONS)
    model = system.build()
    mj = mujoco_free_dynamics(TENDONS)
    return system, model, mj, JointMap(model, system, mj)


def taut_states(mj, n: int):
    """Random states with every tendon longer than its spring length (MuJoCo's spring pushes
    below it, a cable goes slack)."""
    rng, d, out = np.random.default_rng(7), mujoco.MjData(mj), []
    while len(out) < n:
        d.qpos[:], d.qvel[:] = random_state(mj, rng)
        mujoco.mj_forward(mj, d)
        if np.all(d.ten_length > mj.tendon_lengthspring[:, 0] + 1e-3):
            out.append((d.qpos.copy(), d.qvel.copy()))
    return out


def test_sites_and_lengths_equal_mujocos(imported):
    """Marker positions (sites on moving bodies) as ``site_xpos`` and each cable's length
    ``Σ |s_{i+1} − s_i|`` (the world anchor a fixed point) as ``ten_length``, to 1e-12 m."""
    system, model, mj, jmap = imported
    d = mujoco.MjData(mj)
    anchor = mj.site("anchor").pos
    for qpos, qvel in taut_states(mj, 4):
        d.qpos[:], d.qvel[:] = qpos, qvel
        mujoco.mj_forward(mj, d)
        q, v = model.from_joint_space(*jmap.to_ncgen(qpos, qvel))
        pts = markers(model, q[None, :], v[None, :])[0]
        upper, fore = (pts[model.marker_names.index(n)] for n in ("upper.s_upper", "fore.s_fore"))
        assert np.allclose(upper, d.site("s_upper").xpos, atol=1e-12)
        assert np.allclose(fore, d.site("s_fore").xpos, atol=1e-12)
        lengths = [np.linalg.norm(upper - anchor) + np.linalg.norm(fore - upper), np.linalg.norm(fore - upper)]
        assert np.allclose(lengths, d.ten_length, atol=1e-12)


def test_taut_tendons_accelerate_as_in_mujoco(imported):
    """qacc with the cables' tension ``k (L − springlength) + c L̇`` as MuJoCo's tendon
    spring-damper: 1e-8 relative (measured ~1e-14)."""
    system, model, mj, jmap = imported
    assert [f.kind for f in system.forces] == ["ClusteredCable"] * 2
    ode, d, worst = joint_ode(model), mujoco.MjData(mj), 0.0
    for qpos, qvel in taut_states(mj, 5):
        d.qpos[:], d.qvel[:] = qpos, qvel
        mujoco.mj_forward(mj, d)
        assert np.max(np.abs(d.qfrc_passive)) > 1.0                     # the tendons pull
        qj, vj = jmap.to_ncgen(qpos, qvel)
        xdot = np.asarray(ode(0.0, np.r_[qj, vj], np.zeros(model.nu), np.zeros(model.np))[0]).ravel()
        qacc = jmap.acceleration_to_mujoco(qpos, qvel, xdot[len(qj):])
        worst = max(worst, np.max(np.abs(qacc - d.qacc)) / max(1.0, np.max(np.abs(d.qacc))))
    assert worst < 1e-8


@pytest.mark.parametrize("body, said", [
    ('<spatial name="t" stiffness="1"><site site="a"/><geom geom="g"/><site site="b"/></spatial>',
     "tendon spatial 't' (<geom> in its path (only sites are taken))"),
    ('<spatial name="t" stiffness="1" range="0 1"><site site="a"/><site site="b"/></spatial>',
     "tendon spatial 't' (range not modelled)"),
    ('<spatial name="t"><site site="a"/><site site="b"/></spatial>',
     "tendon spatial 't' (no stiffness or damping: nothing acts)"),
])
def test_other_spatial_tendons_are_named(body, said):
    text = f"""<mujoco><worldbody><site name="a" pos="0 0 2"/>
      <body pos="0 0 1"><joint/><geom name="g" size="0.1"/><site name="b"/></body></worldbody>
      <tendon>{body}</tendon></mujoco>"""
    with pytest.warns(MjcfWarning) as caught:
        s = nc.System.from_mjcf(text)
    assert said in str(caught[0].message) and s.forces == []


def test_a_tendon_through_a_missing_site_is_an_error():
    text = """<mujoco><worldbody><body><joint/><geom size="0.1"/><site name="b"/></body></worldbody>
      <tendon><spatial stiffness="1"><site site="b"/><site site="nope"/></spatial></tendon></mujoco>"""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(ModelError, match="no site of that name"):
            nc.System.from_mjcf(text)
