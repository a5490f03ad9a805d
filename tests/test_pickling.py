"""Models and systems travel: pickled by description (TOML text, build options, content
hash), rebuilt once per process, compiled library found in the content-addressed cache."""
import json
import multiprocessing as mp
import pickle
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import ModelError
from ncgen.model import model as model_module

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def spring_damper():
    """Python-API model with a parameter, an input, dampers and a marker."""
    s = nc.System("spring_damper", gravity=(0.0, 0.0, -9.81))
    bar = s.add_bar("bar", "rr", mass=1.0, ends=[s.ground.point((0.0, 0.0, 0.0)), (1.0, 0.0, 0.0)])
    mass = s.add_point("mass", mass=0.5, position=(1.0, 0.0, -0.4))
    k = s.add_parameter("k", 40.0)
    push = s.add_input("push")
    s.add_force(nc.Spring(bar, (0.5, 0.0, 0.0), mass, (0.0, 0.0, 0.0), k=80.0, rest_length=0.4, damping=2.0))
    s.add_force(nc.Spring(s.ground, (1.0, 0.0, 0.5), mass, (0.0, 0.0, 0.0), k=k, rest_length=0.8, damping=1.5))
    s.add_force(nc.PointForce(mass, (0.0, 0.0, 0.0), force=ca.vertcat(0, push, 0)))
    return s


def forget_models():
    """As in a fresh worker: no model of this process known by its hash."""
    model_module._known.clear()
    model_module._rebuilt.clear()


@pytest.mark.parametrize("name", ["slider_crank", "cartpole", "heavy_top", "tensegrity"])
def test_model_rebuilt_from_its_pickle_computes_the_same(name):
    model = nc.System.from_toml(EXAMPLES / f"{name}.toml").build()
    data = pickle.dumps(model)
    forget_models()
    again = pickle.loads(data)
    assert again is not model and again.content_hash == model.content_hash
    assert again.coordinate_names == model.coordinate_names
    assert np.array_equal(again.q0, model.q0) and np.array_equal(again.v0, model.v0)
    q = model.q0 + 0.01
    assert np.array_equal(again.accel(q, model.v0)[0], model.accel(q, model.v0)[0])
    assert pickle.loads(data) is again           # rebuilt once per process


def test_python_api_model_pickles_with_parameters_inputs_and_dampers():
    model = spring_damper().build()
    data = pickle.dumps(model)
    forget_models()
    again = pickle.loads(data)
    assert again.content_hash == model.content_hash
    assert again.parameter_names == ["k"] and again.input_names == ["push"]
    u = lambda t: [np.sin(3 * t)]                # noqa: E731
    a = nc.simulate(model, 0.3, 0.01, u=u, p={"k": 55.0})
    b = nc.simulate(again, 0.3, 0.01, u=u, p={"k": 55.0})
    assert np.array_equal(a.q, b.q) and np.array_equal(a.lam, b.lam)


def test_system_pickles_by_its_toml_text():
    s = spring_damper()
    again = pickle.loads(pickle.dumps(s))
    assert again.to_toml() == s.to_toml()
    assert again.build().content_hash == s.build().content_hash


def test_unpickling_checks_the_content_hash():
    model = nc.System.from_toml(EXAMPLES / "slider_crank.toml").build()
    _, (description, options, _, version) = model.__reduce__()
    forget_models()
    with pytest.raises(ModelError, match="slider_crank.*differs from the pickled one"):
        nc.System.rebuilt_model(description, options, "0" * 64, version)


def test_content_hash_tells_models_apart():
    s = nc.System.from_toml(EXAMPLES / "slider_crank.toml")
    a = s.build()
    other = nc.System.from_toml((EXAMPLES / "slider_crank.toml").read_text().replace("k = 200.0", "k = 300.0"))
    assert other.build().content_hash != a.content_hash
    assert s.build(baumgarte=(1.0, 1.0)).content_hash != a.content_hash


def test_spawn_pool_runs_the_stepper_without_recompiling(tmp_path, monkeypatch):
    monkeypatch.setenv("NCGEN_CACHE_DIR", str(tmp_path / "cache"))
    model = nc.System.from_toml(EXAMPLES / "slider_crank.toml").build()
    local = nc.simulate(model, 0.3, 0.005, method="stepper", p={"omega": 4.0})
    entries = sorted((tmp_path / "cache").glob("slider_crank-*"))
    assert len(entries) == 1
    record = (entries[0] / "build.json").read_text()
    with mp.get_context("spawn").Pool(2) as pool:
        runs = [pool.apply_async(nc.simulate, (model, 0.3, 0.005), dict(method="stepper", p={"omega": 4.0}))
                for _ in range(3)]
        remote = [r.get(timeout=300) for r in runs]
    for traj in remote:
        assert np.array_equal(traj.q, local.q) and np.array_equal(traj.v, local.v)
        assert traj.model.content_hash == model.content_hash
    assert sorted((tmp_path / "cache").glob("slider_crank-*")) == entries      # no second build
    assert (entries[0] / "build.json").read_text() == record
    assert json.loads(record)["content_hash"]


def test_urdf_model_keeps_its_frames_and_joint_limits():
    from test_urdf import ARM
    model = nc.System.from_urdf(ARM).build()
    data = pickle.dumps(model)
    forget_models()
    again = pickle.loads(data)
    assert again.joint_limits == model.joint_limits == {"j1": {"velocity": 3.0, "effort": 10.0}}
    q, _ = model.from_joint_space([0.7])
    for name in model.frames:
        R, p = model.frame_pose(name, q)
        R2, p2 = again.frame_pose(name, q)
        assert np.array_equal(R, R2) and np.array_equal(p, p2)


def test_urdf_system_with_mimic_joints_pickles_and_round_trips_through_toml():
    """The Panda's second finger mimics the first (a Mimic joint names its leader and
    follower): its system pickles (by its TOML text) and rebuilds the same model, whose
    mimic equation holds the fingers together."""
    pytest.importorskip("yourdfpy")
    system = nc.System.from_urdf(nc.robots.urdf_path("panda"))
    text = system.to_toml()
    assert 'type = "Mimic"' in text
    again = pickle.loads(pickle.dumps(system))
    a, b = system.build(), again.build()
    assert a.constraint_names == b.constraint_names and "panda_finger_joint2_mimic.mimic" in a.constraint_names
    assert np.array_equal(a.M, b.M) and np.array_equal(a.q0, b.q0)
    qj = np.linspace(-0.5, 0.5, a.joint_space.nq)
    qj[-2:] = 0.02, 0.02
    q, _ = b.from_joint_space(qj)
    assert np.max(np.abs(b.phi(q))) < 1e-10
    qj[-1] = 0.0                                           # the follower is held to the leader
    # the mimic equation and the two given fingers share the least-squares residual equally
    # (0.02 / 3 each): all three are named, whichever rounds largest on this CPU
    with pytest.raises(ModelError, match=r"mimic\.mimic by 0\.00667, panda_finger_joint1 by 0\.00667, "
                                         r"panda_finger_joint2 by 0\.00667"):
        b.from_joint_space(qj)
