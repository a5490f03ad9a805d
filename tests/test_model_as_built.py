"""The model keeps the system as built (``model.members``, ``model.contact_elements``: after
coordinate sharing re-based the bodies), and what reads members' coordinates reads those: a
double pendulum whose two bodies share the elbow's point and axis, with a sphere on the
forearm against a sphere and a box on the upper arm.  The broad phase's bounds
(:mod:`ncgen.assembly.pair_kernels`) are checked against the gaps of the closed-form
kinematics (rotations about y), and the built elements against a store round trip and a
pickle."""
from __future__ import annotations

import pickle
from collections import OrderedDict

import numpy as np
import pytest

import ncgen as nc
from ncgen.assembly.pair_kernels import element_bounds, pair_kernels

L = 0.6                            # link length (m); each body's centre of mass at its middle
SPHERE_A, R_A = np.array([-0.15, 0.0, 0.05]), 0.05     # on the upper arm, in its frame (m)
SPHERE_B, R_B = np.array([0.25, 0.0, 0.0]), 0.04       # at the forearm's tip, in its frame
BOX_AT, BOX = np.array([0.1, 0.0, 0.0]), np.array([0.2, 0.08, 0.06])   # on the upper arm


def R_y(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def arm() -> nc.System:
    s = nc.System("shared_arm", gravity=(0, 0, -9.81))
    inertia = np.diag([0.001, 0.03, 0.03])
    a = s.add_body("upper", mass=1.0, inertia=inertia, position=(L / 2, 0, 0))
    b = s.add_body("fore", mass=0.5, inertia=inertia / 2, position=(1.5 * L, 0, 0))
    s.add_joint(nc.Revolute(s.ground, a, at=(0, 0, 0), axis=(0, 1, 0), name="shoulder"))
    s.add_joint(nc.Revolute(a, b, at=(L, 0, 0), axis=(0, 1, 0), name="elbow"))
    s.add_contact(nc.SphereSphere(a, tuple(SPHERE_A), R_A, b, tuple(SPHERE_B), R_B, name="balls"))
    s.add_contact(nc.SphereBox(b, tuple(SPHERE_B), R_B, box=a, size=tuple(BOX), box_at=tuple(BOX_AT),
                               name="ball_box"))
    return s


def closed_form_gaps(shoulder: float, elbow: float) -> np.ndarray:
    """Both gaps from the arm's kinematics: the upper arm turned by the shoulder angle about
    y at the origin, the forearm by both angles about y at the elbow ``(L, 0, 0)``."""
    Ra, Rb = R_y(shoulder), R_y(shoulder + elbow)
    pa = Ra @ np.array([L / 2, 0, 0])
    pb = Ra @ np.array([L, 0, 0]) + Rb @ np.array([L / 2, 0, 0])
    xa, xb = pa + Ra @ SPHERE_A, pb + Rb @ SPHERE_B
    balls = np.linalg.norm(xa - xb) - R_A - R_B
    local = Ra.T @ (xb - pa) - BOX_AT                         # the ball's centre in the box's frame
    outside = np.maximum(np.abs(local) - BOX / 2, 0.0)
    inside = np.min(BOX / 2 - np.abs(local))
    box = (np.linalg.norm(outside) if outside.any() else -inside) - R_B
    return np.array([balls, box])


@pytest.fixture(scope="module")
def model():
    return arm().build(contacts="nonsmooth")


def test_the_bodies_are_re_based_and_the_model_keeps_them(model):
    assert set(model.sharing.rebased) == {"upper", "fore"}        # the case where written ≠ built
    written = model.recipe[0].members
    for element in model.contact_elements:
        for m in element.members():
            assert m is model.members[m.name]
            assert m.ctype.nq == len(model.layout.member_indices(m.name))
            assert m.ctype.name != written[m.name].ctype.name


def test_broad_phase_bounds_are_below_the_closed_form_gaps(model):
    """Every element's lower bound is at most its gap, the gap of the model equals the
    closed form, and the bounds are not vacuous, at folded and random elbow angles."""
    elements = pair_kernels(model).elements
    assert [e.name for e in elements] == ["balls", "ball_box"]
    rng = np.random.default_rng(11)
    folded = [(0.0, 0.0), (0.3, -2.9), (-0.5, 2.95), (1.0, np.pi)]
    angles = folded + [tuple(x) for x in rng.uniform(-np.pi, np.pi, (40, 2))]
    tight = 0
    for shoulder, elbow in angles:
        qj = np.zeros(len(model.joint_names))
        qj[model.joint_names.index("shoulder")], qj[model.joint_names.index("elbow")] = shoulder, elbow
        q, _ = model.from_joint_space(qj, np.zeros_like(qj))
        g = closed_form_gaps(shoulder, elbow)
        np.testing.assert_allclose(model.gap(q), g, rtol=0, atol=1e-12)
        for e in elements:
            bound = element_bounds(e, q)[0]
            assert bound <= g[e.first] + 1e-12, (e.name, shoulder, elbow, bound, g[e.first])
            tight += bound > 0.5 * g[e.first] > 0
    assert tight > 40


def test_the_built_elements_survive_the_store_and_pickling(tmp_path, monkeypatch):
    """A model read back (from the store of built models, or a pickle rebuilding it) keeps
    its contact elements on its own members, with the same broad-phase tables."""
    from ncgen.codegen import model_cache
    from ncgen.model import model as model_module

    monkeypatch.setenv("NCGEN_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv(model_cache.ENV, raising=False)
    model = arm().build(contacts="nonsmooth")
    stored, _ = model_cache.load(model.data.store_key)          # the entry on disk
    text = pickle.dumps(model)
    monkeypatch.setattr(model_module, "_known", {})              # as in another process: built again
    monkeypatch.setattr(model_module, "_rebuilt", OrderedDict())
    monkeypatch.setenv(model_cache.ENV, "0")
    rebuilt = pickle.loads(text)
    expected = pair_kernels(model).elements
    for other in (stored, rebuilt):
        assert other is not model
        for element in other.contact_elements:
            assert all(m is other.members[m.name] for m in element.members())
        for e, f in zip(pair_kernels(other).elements, expected, strict=True):
            assert (e.name, e.idx_a, e.idx_b) == (f.name, f.idx_a, f.idx_b)
            for s, t in zip(e.sides, f.sides, strict=True):
                assert s.kind == t.kind and np.array_equal(s.centre, t.centre) and np.array_equal(s.axes, t.axes)
