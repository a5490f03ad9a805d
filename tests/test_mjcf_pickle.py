"""Imported MJCF models travel: a JointSequence (several joints in one MJCF body) has a TOML
form that reads back to the same dynamics, a pickled imported model keeps each coordinate's
joint dynamics and limits (they are not TOML), and spawned workers (a process pool, a sweep)
run it to the same trajectory as this process."""
from __future__ import annotations

import multiprocessing as mp
import pickle
import warnings
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import ModelError
from ncgen.model import model as model_module
from ncgen.model.joint_dynamics import coordinate_laws

SEQUENCES = Path(__file__).parent / "data" / "sequences.xml"


def imported():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return nc.System.from_mjcf(SEQUENCES)


def forget_models():
    """As in a fresh worker: no model of this process known by its hash."""
    model_module._known.clear()
    model_module._rebuilt.clear()


def laws(system_or_model):
    return {j.name: [(dict(law.limits), dict(law.dynamics)) for law in coordinate_laws(j)]
            for j in system_or_model.joints}


@pytest.fixture(scope="module")
def original():
    system = imported()
    return system, system.build()


def test_joint_sequences_round_trip_through_toml(original):
    """TOML → System → build: the same equations and accelerations at random states and
    efforts (every sequence form of the file: three slides, three hinges at a point, two
    skew hinges, two hinges at a point; springs on single hinges of sequences)."""
    system, model = original
    text = system.to_toml()
    assert text.count('type = "JointSequence"') == 4 and "coordinate = 2" in text
    again = nc.System.from_toml(text)
    assert again.to_toml() == text
    built = again.build()
    assert built.joint_names == model.joint_names and built.constraint_names == model.constraint_names
    assert np.array_equal(built.M, model.M) and np.array_equal(built.q0, model.q0)
    rng = np.random.default_rng(4)
    for _ in range(3):
        qj = rng.uniform(-0.4, 0.4, model.joint_space.nq)
        vj = rng.normal(size=model.joint_space.nv)
        q, v = model.from_joint_space(qj, vj)
        u = rng.normal(size=model.nu)
        a, lam = model.accel(q, v, u=u)
        b, mu = built.accel(q, v, u=u)
        assert np.max(np.abs(np.asarray(a) - np.asarray(b))) <= 1e-12 * max(1.0, np.max(np.abs(a)))
        assert np.max(np.abs(np.asarray(lam) - np.asarray(mu))) <= 1e-12 * max(1.0, np.max(np.abs(lam)))


@pytest.mark.parametrize("change, message", [
    (('kind = "hinge"', 'kind = "ball"', 1), r'joints\[\d+\]\.steps\[0\]\.kind: expected "hinge" or "slide", got \'ball\''),
    (("names = [", "nam = [", 1), r"joints\[\d+\]\.nam: unknown key"),
    (('effort = ["tau[3]", "tau[4]", "tau[5]"]', 'effort = ["tau[3]", "tau[4]"]', 1),
     r"joints\[\d+\]\.effort: expected 3 numbers or expression strings"),
    ((", axis = [", ", axes = [", 1), r"joints\[\d+\]\.steps\[0\]\.axes: unknown key"),
    (("steps = [", "steps = 3 #", 1), r"joints\[\d+\]\.steps: expected a list of tables"),
])
def test_bad_joint_sequence_tables_are_named(original, change, message):
    text = original[0].to_toml().replace(*change)
    with pytest.raises(ModelError, match=message):
        nc.System.from_toml(text)


def test_pickled_imported_model_keeps_joint_dynamics_and_rebuilds_the_same(original):
    system, model = original
    assert any(law.dynamics for law in coordinate_laws(model.joints[0]))
    data = pickle.dumps(model)
    forget_models()
    again = pickle.loads(data)
    assert again is not model and again.content_hash == model.content_hash
    assert laws(again) == laws(model)
    sys_again = pickle.loads(pickle.dumps(system))
    assert laws(sys_again) == laws(system) and sys_again.to_toml() == system.to_toml()


def test_a_joint_sequence_with_limits_pickles_its_limits():
    """Ranges of the coordinates of a sequence (MJCF ``range``) travel with the pickle."""
    text = SEQUENCES.read_text().replace('<joint name="o1" axis="0 1 0.3"/>',
                                         '<joint name="o1" axis="0 1 0.3" range="-0.5 0.7"/>')
    system = nc.System.from_mjcf(text)
    again = pickle.loads(pickle.dumps(system))
    (law,) = [law for j in again.joints for law in coordinate_laws(j) if law.name == "o1"]
    assert law.limits == {"lower": -0.5, "upper": 0.7} and law.dynamics == {"damping": 0.02}


@pytest.mark.slow
def test_spawned_workers_run_the_imported_model_as_this_process(original):
    """A spawn pool and a process sweep (IDAS) rebuild the model from its pickle and run it,
    joint damping included, to the same trajectory as this process."""
    _, model = original
    local = nc.simulate(model, 0.2, 0.01, method="joint", joint_dynamics=True)
    undamped = nc.simulate(model, 0.2, 0.01, method="joint")
    assert np.max(np.abs(local.q - undamped.q)) > 1e-6          # the damping acts
    with mp.get_context("spawn").Pool(2) as pool:
        runs = [pool.apply_async(nc.simulate, (model, 0.2, 0.01), dict(method="joint", joint_dynamics=True))
                for _ in range(2)]
        remote = [r.get(timeout=600) for r in runs]
    for traj in remote:
        assert np.array_equal(traj.q, local.q) and traj.model.content_hash == model.content_hash
    here = nc.simulate(model, 0.2, 0.01, method="idas", joint_dynamics=True)
    swept = nc.sweep(model, None, t_end=0.2, dt=0.01, method="idas", q0=np.tile(model.q0, (2, 1)), workers=2,
                     joint_dynamics=True)
    assert list(swept.summary["status"]) == [0, 0]
    for k in range(2):
        assert np.max(np.abs(swept.arrays["q"][k] - here.q)) < 1e-9
