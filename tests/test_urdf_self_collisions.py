"""Contacts between a URDF robot's links (``from_urdf(collisions={"self": True, ...})``): the
pairs made (adjacent and welded links excluded, the user's filter honoured, pairs without an
element warned about), and a 3-link arm (tests/data/folding_arm.urdf) whose last link folds
under gravity onto its first: it rests on its sphere without penetration, with the normal
force of the static torque balance about the wrist and no energy created."""
import warnings
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import ModelError
from ncgen.model.urdf import UrdfCollisionWarning

QUICK_COMPILE = True             # its time is gcc compiling the arm: -O0 (tests/conftest.py)
ARM = Path(__file__).parent / "data" / "folding_arm.urdf"
G = 9.81
SELF = {"self": True, "ground": False}
PAIRS = ["link1_collision0__link3_collision0", "link1_collision0__link3_tip_collision0"]


def arm(**collisions):
    return nc.System.from_urdf(str(ARM), collisions=collisions)


def test_pairs_exclude_adjacent_and_welded_links_and_follow_the_filter():
    # link2 is adjacent to link1 and link3; link3_tip is welded to link3 (one body), so the
    # only pairs are link1 against link3's box and against the tip's sphere
    assert [c.name for c in arm(**SELF).contacts] == PAIRS
    assert [type(c).__name__ for c in arm(**SELF).contacts] == ["BoxBox", "SphereBox"]
    ground = [f"{ln}_collision0" for ln in ("link1", "link2", "link3", "link3_tip")]
    assert [c.name for c in arm(self=True, mu=0.3).contacts] == ground + PAIRS
    assert all(c.mu == 0.3 for c in arm(self=True, mu=0.3).contacts)
    assert [c.name for c in nc.System.from_urdf(str(ARM), collisions=True).contacts] == ground   # self off
    # excluding a link excludes the body it is welded into
    assert arm(exclude=[("link3_tip", "link1")], **SELF).contacts == []
    assert [c.name for c in arm(exclude=[["link2", "link3"]], **SELF).contacts] == PAIRS


@pytest.mark.parametrize("collisions, message", [
    ({"self": "yes"}, r"collisions: self: expected True or False, got 'yes'"),
    ({"ground": 1}, r"collisions: ground: expected True or False, got 1"),
    ({"exclude": [("link1", "link3")]}, r"collisions: exclude: filters the pairs of links, which only self=True"),
    ({"self": True, "exclude": ("link1", "link3")}, r"collisions: exclude\[0\]: expected a pair of link names, "
                                                    r"got 'link1'"),
    ({"self": True, "exclude": [("link1", "hand")]}, r"collisions: exclude\[0\]: 'hand' is not a link of this "
                                                     r"robot \(links: base, link1"),
    ({"self": True, "exclude": "link1"}, r"collisions: exclude: expected a list of pairs of link names"),
    ({"selfs": True}, r"collisions: unknown key\(s\) 'selfs'; expected ground, self, exclude, mu"),
])
def test_bad_collision_options_are_refused_by_key(collisions, message):
    with pytest.raises(ModelError, match=message):
        nc.System.from_urdf(str(ARM), collisions=collisions)


def test_pairs_without_an_element_are_warned_about_and_listed():
    text = ARM.read_text().replace(
        '<collision><origin xyz="0.3 0 0"/><geometry><box size="0.6 0.06 0.06"/></geometry></collision>',
        '<collision><origin xyz="0.3 0 0"/><geometry><box size="0.6 0.06 0.06"/></geometry></collision>'
        '<collision><origin xyz="0.1 0 0.1"/><geometry><cylinder radius="0.02" length="0.1"/></geometry></collision>')
    with pytest.warns(UrdfCollisionWarning, match=r"1 pair\(s\) .*link1_collision1__link3_collision0 "
                                                  r"\(cylinder–box: no contact element for that pair\)"):
        s = nc.System.from_urdf(text, collisions=SELF)
    assert s.skipped_collisions == ["link1_collision1__link3_collision0"]
    assert [c.name for c in s.contacts] == PAIRS + ["link1_collision1__link3_tip_collision0"]   # CylinderSphere


@pytest.mark.slow      # the arm compiled with its self-collisions and run to rest; fast: the pairs' and the broad phase's
#                        tests of this file (test_broad_phase_bound_is_below_the_gap_with_shared_coordinates)
@pytest.mark.parametrize("share", [True, False])
def test_folded_arm_rests_on_its_sphere_with_the_torque_balance_force(share):
    """Links 1 and 2 turn about vertical axes, so the vertical forces leave them still;
    link3 (with the welded tip, mass m at distance c from the wrist) rests on the sphere at
    distance d: N d cos θ = m g c cos θ, so N = m g c / d whatever the resting angle θ.
    With shared coordinates (the default) the links are re-based on their joints, which the
    broad phase's bounds must follow (the sphere sank 18 mm into link1 when they did not)."""
    s = arm(**SELF)
    model = s.build(contacts="nonsmooth", share=share)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")               # the box corners near the face: redundant rows
        tr = nc.simulate(model, 1.0, 0.01, method="stepper", substeps=10)
    m3, m_tip, c3, d = 0.8, 0.2, 0.205, 0.4           # from the URDF: link3 and the tip link
    c = (m3 * c3 + m_tip * d) / (m3 + m_tip)
    k = model.contact_names.index(PAIRS[1])
    settled = tr.t > 0.5
    np.testing.assert_allclose(tr.contact_normal[settled, k], (m3 + m_tip) * G * c / d, rtol=1e-9)
    assert np.all(tr.contact_normal[settled][:, np.arange(tr.gap.shape[1]) != k] == 0)   # the box is clear
    assert tr.gap.min() > -1e-9 and tr.gap[settled, k].max() < 1e-6          # resting, no penetration
    # it did fall onto link1: the wrist turned by asin((H - b/2 - r) / d) with H = 0.2 m
    wrist = tr.joint("wrist")[0][-1]
    assert abs(abs(wrist) - np.arcsin((0.2 - 0.03 - 0.04) / d)) < 1e-5
    np.testing.assert_allclose(tr.joint("shoulder")[0][-1], 0, atol=1e-9)
    np.testing.assert_allclose(tr.joint("elbow")[0][-1], 0, atol=1e-9)
    E = tr.energy
    assert np.all(np.diff(E) < 1e-8 * E[0])                   # contact creates no energy
    assert E[-1] < E[0] - 0.1                                 # the landing's loss (e = 0)


def test_broad_phase_bound_is_below_the_gap_with_shared_coordinates():
    """Every element's lower bound is below each of its gaps, at folded and random poses of
    the re-based (shared) links."""
    from ncgen.assembly.pair_kernels import element_bounds, pair_kernels
    model = arm(**SELF).build(contacts="nonsmooth")
    assert model.sharing.eliminated                          # the links are re-based
    elements = pair_kernels(model).elements
    rng = np.random.default_rng(3)
    poses = [np.array([0.0, 0.0, w]) for w in (0.0, -0.2, -0.38)] + list(rng.uniform(-1.5, 1.5, (20, 3)))
    for pose in poses:
        q, _ = model.from_joint_space(pose, np.zeros(3))
        g = model.gap(q)
        for element in elements:
            assert element_bounds(element, q)[0] <= g[element.first:element.first + element.count].min() + 1e-12


def test_skipped_collisions_survive_pickling():
    """A stored system (the store of read files, spawn pools) keeps the list."""
    import pickle
    text = ARM.read_text().replace('<geometry><sphere radius="0.04"/></geometry>',
                                   '<geometry><mesh filename="tip.stl"/></geometry>')
    s = nc.System.from_urdf(text, collisions=SELF)
    assert s.skipped_collisions == ["link3_tip_collision0"]
    assert pickle.loads(pickle.dumps(s)).skipped_collisions == ["link3_tip_collision0"]
