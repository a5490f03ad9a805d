"""Joint dynamics in TOML (``dynamics = {damping, armature, friction, lower, upper, ...}`` in a
joint table, one table per coordinate of a JointSequence), so that an imported MJCF model
written by ``to_toml`` is the same model: MJCF → System → TOML → System gives the joint-space
accelerations (damping, armature, friction, limit laws, springs) of the imported system to
1e-12, at states beyond the limits too.  Bad tables are named by key path."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import ModelError
from ncgen.model.joint_dynamics import coordinate_laws

from mjcf_reference import joint_ode  # noqa: E402
from test_mjcf import CHAIN, import_quietly  # noqa: E402

DATA = Path(__file__).parent / "data"


@pytest.mark.parametrize("source", ["chain", "sequences.xml", "actuators.xml", "tendons.xml"])
def test_toml_of_an_imported_model_keeps_its_dynamics(source):
    """Damping, armature, friction and ranges of every coordinate (hinges, slides, joint
    sequences) survive the TOML text, and qacc of the rebuilt model equals the imported one's
    (joint space, joint dynamics on) to 1e-12 relative at random states and inputs."""
    system = import_quietly(CHAIN if source == "chain" else DATA / source)
    laws = [(dict(law.dynamics), dict(law.limits)) for j in system.joints for law in coordinate_laws(j)]
    assert any(d for d, _ in laws) and (source != "actuators.xml" or all(lim for _, lim in laws[2:4]))
    again = nc.System.from_toml(system.to_toml())
    assert [(dict(law.dynamics), dict(law.limits)) for j in again.joints for law in coordinate_laws(j)] == laws
    models = [s.build() for s in (system, again)]
    odes = [joint_ode(m) for m in models]
    js = models[0].joint_space
    rng = np.random.default_rng(1)
    worst = 0.0
    for _ in range(4):
        q, v = models[0].from_joint_space(rng.normal(0, 0.6, js.nq) * _not_free(js),
                                          rng.normal(0, 1.0, js.nv) * _not_free(js, rates=True))
        qj, vj = models[0].to_joint_space(q, v)
        tau = rng.normal(size=models[0].nu)
        a, b = (np.asarray(ode(0.0, np.r_[qj, vj], tau, np.zeros(m.np))[0]).ravel() for ode, m in zip(odes, models))
        worst = max(worst, np.max(np.abs(a - b)) / max(1.0, np.max(np.abs(a))))
    assert worst <= 1e-12


def _not_free(js, rates: bool = False) -> np.ndarray:
    """1 on hinge and slide coordinates (the test models' joints), 0 elsewhere."""
    sizes = js.nv_joint if rates else js.nq_joint
    return np.concatenate([np.full(sizes[n], 1.0 if js.joints[n].kind in ("Revolute", "Prismatic",
                                                                             "JointSequence") else 0.0)
                           for n in js.joint_names])


BASE = """
[[members]]
name = "arm"
kind = "body"
mass = 1.0
inertia = [[0.1, 0, 0], [0, 0.1, 0], [0, 0, 0.1]]
position = [0.5, 0, 0]
"""


def test_a_revolute_joint_reads_its_dynamics():
    s = nc.System.from_toml(BASE + """
[[joints]]
type = "Revolute"
between = ["ground", "arm"]
at = [0, 0, 0]
axis = [0, 1, 0]
dynamics = {damping = 0.3, armature = 0.02, lower = -1.0, upper = 1.5}
""")
    assert s.joints[0].dynamics == {"damping": 0.3, "armature": 0.02}
    assert s.joints[0].limits == {"lower": -1.0, "upper": 1.5}


@pytest.mark.parametrize("table, said", [
    ('type = "Revolute"\nbetween = ["ground", "arm"]\nat = [0, 0, 0]\naxis = [0, 1, 0]\ndynamics = {dampin = 1}',
     "joints[0].dynamics.dampin: unknown key (did you mean 'damping'?)"),
    ('type = "Revolute"\nbetween = ["ground", "arm"]\nat = [0, 0, 0]\naxis = [0, 1, 0]\ndynamics = {damping = "x"}',
     "joints[0].dynamics.damping: expected a number, got a string ('x')"),
    ('type = "Revolute"\nbetween = ["ground", "arm"]\nat = [0, 0, 0]\naxis = [0, 1, 0]\ndynamics = {damping = -1}',
     "joints[0].dynamics: "),
    ('type = "Spherical"\nbetween = ["ground", "arm"]\nat = [0, 0, 0]\ndynamics = {damping = 1}',
     "joints[0].dynamics: joint dynamics apply to Revolute, Prismatic joints and joint sequences, not Spherical"),
    ('type = "JointSequence"\nbetween = ["ground", "arm"]\nsteps = [{kind = "slide", at = [0, 0, 0], axis = [0, 1, 0]},'
     ' {kind = "slide", at = [0, 0, 0], axis = [1, 0, 0]}]\ndynamics = [{damping = 1}]',
     "joints[0].dynamics: expected 2 tables (one per coordinate of"),
])
def test_bad_dynamics_are_named(table, said):
    with pytest.raises(ModelError) as e:
        nc.System.from_toml(BASE + "\n[[joints]]\n" + table + "\n")
    assert said in str(e.value)
