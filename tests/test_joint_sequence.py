"""nc.JointSequence (several hinges or slides between two members, applied in order, as
MuJoCo composes the joints of one body): each form's coordinates invert the product of
exponentials (joint space → natural coordinates → joint space), its rates equal central
differences of its coordinates along a motion, its equations hold there, the element tables
equal the flat functions, and what it does not take is refused by name.  Its dynamics
against MuJoCo: tests/test_mjcf.py (tests/data/sequences.xml, the humanoids)."""
from __future__ import annotations

import shutil

import numpy as np
import pytest

import ncgen as nc
from ncgen.codegen.compiler import CANDIDATES
from ncgen.errors import ModelError
from ncgen.runtime.table_library import load_element_library, table_functions

C = np.array([0.1, 0.2, 0.9])
A = np.array([1.0, 1.0, 0.0]) / np.sqrt(2)
B = np.array([-1.0, 1.0, 0.0]) / np.sqrt(2)
N = np.array([0.0, 0.0, 1.0])
FORMS = {
    "slides": [("slide", C, A), ("slide", C, (0.3, 0.2, 1.0)), ("slide", C, (0.1, 0.2, 1.0))],
    "planar": [("slide", C, A), ("slide", C + N, B), ("hinge", C + 0.1 * A, N)],
    "hinges2": [("hinge", C, A), ("hinge", C + 0.3 * np.array([0.3, 1.0, 0.5]), (0.3, 1.0, 0.5))],   # meet at C
    "skew2": [("hinge", C, A), ("hinge", C + 0.05 * N, B)],
    "hinges3": [("hinge", C, A), ("hinge", C, -N), ("hinge", C, B)],
}


def system(steps, second_body: bool = False):
    s = nc.System("seq")
    a = s.ground
    if second_body:                                   # the sequence between two moving bodies
        a = s.add_body("a", mass=2.0, inertia=np.diag([0.03, 0.02, 0.04]), position=(0.0, 0.1, 0.8))
        s.add_joint(nc.Spherical(s.ground, a, at=(0.0, 0.0, 0.8)))
    b = s.add_body("b", mass=1.0, inertia=np.diag([0.01, 0.02, 0.03]), position=(0.3, 0.1, 1.0))
    s.add_joint(nc.JointSequence(a, b, steps=steps, name="seq", effort=s.add_input("tau", len(steps))))
    return s


@pytest.mark.parametrize("form", FORMS)
def test_coordinates_invert_the_product_of_exponentials(form):
    model = system(FORMS[form], second_body=form in ("skew2", "hinges3")).build()
    assert model.joint_space.joints["seq"].shape() == form
    js = model.joint_space
    n = len(FORMS[form])
    assert model.dof == n + (3 if form in ("skew2", "hinges3") else 0)
    rng = np.random.default_rng(len(form))
    for _ in range(3):
        qj, vj = rng.uniform(-1.2, 1.2, js.nq), rng.normal(size=js.nv)
        if js.nq == n + 4:                            # the ball joint's quaternion first
            qj[:4] /= np.linalg.norm(qj[:4])
        q, v = model.from_joint_space(qj, vj)
        assert np.abs(model.phi(q)).max() < 1e-12
        back_q, back_v = model.to_joint_space(q, v)
        np.testing.assert_allclose(back_q[-n:], qj[-n:], atol=1e-12)
        np.testing.assert_allclose(back_v, vj, atol=1e-12)


@pytest.mark.parametrize("form", FORMS)
def test_rates_are_the_derivatives_of_the_coordinates(form):
    """v_j(q, q̇) against central differences of q_j along q(t) = q(q_j0 + t v_j)."""
    model = system(FORMS[form]).build()
    js = model.joint_space
    rng = np.random.default_rng(7)
    qj, vj = rng.uniform(-1.0, 1.0, js.nq), rng.normal(size=js.nv)
    q, v = model.from_joint_space(qj, vj)
    h = 1e-6
    qp, _ = model.from_joint_space(qj + h * vj)
    qm, _ = model.from_joint_space(qj - h * vj)
    fd = (np.array(js.positions(qp)).ravel() - np.array(js.positions(qm)).ravel()) / (2 * h)
    np.testing.assert_allclose(np.array(js.rates(q, v)).ravel(), fd, atol=1e-8)


@pytest.mark.skipif(not any(shutil.which(c) for c in CANDIDATES), reason="no C compiler for the element library")
def test_element_tables_equal_the_flat_functions():
    model = nc.System.from_mjcf("tests/data/sequences.xml").build()
    tf = table_functions(model, load_element_library())
    rng = np.random.default_rng(2)
    f = model.functions
    for q, v in ((model.q0, model.v0), (model.q0 + 0.3 * rng.standard_normal(model.nq), rng.standard_normal(model.nq))):
        np.testing.assert_allclose(tf.phi(q), np.array(f["phi"](0.0, q, model.p0)).ravel(), atol=1e-12)
        np.testing.assert_allclose(tf.tables.dense_A(tf.A(q)), np.array(f["A"](0.0, q, model.p0)), atol=1e-12)
        np.testing.assert_allclose(tf.gamma(q, v), np.array(f["gamma"](0.0, q, v, model.p0)).ravel(), atol=1e-12)


@pytest.mark.parametrize("steps, expected", [
    ([("hinge", C, A)], "expected at least two (kind, at, axis) steps"),
    ([("hinge", C, A), ("hinge", C + B, A)], "two hinges about parallel axes"),
    ([("hinge", C, A), ("slide", C, B)], "a sequence of hinge, slide: only hinges, only slides, or slide, slide"),
    ([("slide", C, A), ("slide", C, 2 * A)], "slides along dependent axes"),
    ([("hinge", C, A), ("hinge", C, B), ("hinge", C, (0, 0.3, 1))], "three hinges are taken through one point"),
    ([("hinge", C, A), ("hinge", C, B), ("hinge", C + N, N)], "three hinges are taken through one point"),
    ([("slide", C, A), ("slide", C, B), ("hinge", C, A)], "the hinge along their normal"),
    ([("ball", C, A), ("hinge", C, B)], "steps[0]: expected (\"hinge\" or \"slide\", at, axis)"),
    ([("hinge", C, (0, 0, 0)), ("hinge", C, B)], "steps[0] axis: expected a non-zero direction"),
])
def test_refused_by_name(steps, expected):
    with pytest.raises(ModelError) as e:
        system(steps)
    assert "joint 'seq' (JointSequence ground–b)" in str(e.value) and expected in str(e.value)


@pytest.mark.parametrize("form", FORMS)
def test_every_form_reads_back_from_its_toml(form):
    """The TOML form (``steps = [{kind, at, axis}]``, names, effort) gives the same sequence;
    its dynamics after the round trip: tests/test_mjcf_pickle.py."""
    s = system(FORMS[form], second_body=form in ("skew2", "hinges3"))
    text = s.to_toml()
    again = nc.System.from_toml(text)
    (joint,) = [j for j in again.joints if j.kind == "JointSequence"]
    assert joint.shape() == form and again.to_toml() == text
    assert [law.name for law in joint.laws] == [f"x{k + 1}" for k in range(len(FORMS[form]))]
    for (kind, at, axis), (kind2, at2, axis2) in zip(s.joints[-1].steps(), joint.steps()):
        assert kind == kind2 and np.array_equal(at, at2) and np.array_equal(axis, axis2)
