"""MJCF geoms as contact shapes (ncgen.model.mjcf_contacts, ``from_mjcf(..., contacts=True)``):
the pairs are MuJoCo's collision filtering (self, parent–child and welded bodies,
contype/conaffinity, ``<exclude>``) on a small scene, and a ball and a box dropped on the
floor from MJCF rest at the smooth law's closed-form depth."""
from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import ModelError
from ncgen.model.mjcf import MjcfWarning

SCENE = Path(__file__).parent / "data" / "contacts.xml"


def test_off_by_default():
    with warnings.catch_warnings():
        warnings.simplefilter("error", MjcfWarning)
        s = nc.System.from_mjcf(SCENE)
    assert s.contacts == [] and s.mjcf_ignored == ["contact"]


def test_pairs_are_mujocos():
    """With a 5 m margin on every geom MuJoCo's ``mj_collision`` reports every pair its filter
    lets through; ncgen's contacts plus the pairs it names as unsupported (a cylinder against
    a box) are the same set."""
    mujoco = pytest.importorskip("mujoco")
    text = SCENE.read_text().replace('<geom density="500"/>', '<geom density="500" margin="5"/>')
    mj = mujoco.MjModel.from_xml_string(text)
    d = mujoco.MjData(mj)
    mujoco.mj_forward(mj, d)
    theirs = {frozenset((mj.geom(c.geom1).name, mj.geom(c.geom2).name)) for c in d.contact[:d.ncon]}
    with pytest.warns(MjcfWarning) as caught:
        s = nc.System.from_mjcf(SCENE, contacts=True)
    ours = {frozenset(c.name.split("__")) for c in s.contacts}
    named = {frozenset(m) for m in re.findall(r"contact of geom '(\w+)' \(\w+\) with '(\w+)'", str(caught[0].message))}
    assert named == {frozenset(("step", "lower")), frozenset(("crate", "lower"))}
    assert len(ours) == len(s.contacts) == 15
    assert ours | named == theirs
    assert "contact" not in s.mjcf_ignored
    again = nc.System.from_toml(s.to_toml())                   # the contacts have a TOML form
    assert [(c.name, c.kind, c.mu) for c in again.contacts] == [(c.name, c.kind, c.mu) for c in s.contacts]


def drop(shape: str, size: str, z0: float):
    """A free ``shape`` body dropped on the floor plane, 2 s (IDAS): its final height."""
    text = f"""<mujoco><worldbody><geom type="plane" size="2 2 0.1"/>
      <body pos="0.1 -0.2 {z0}"><freejoint/><geom type="{shape}" size="{size}" density="600"/></body>
    </worldbody></mujoco>"""
    s = nc.System.from_mjcf(text, contacts={"stiffness": 2e4, "damping": 1e5, "mu": 0.5})
    model = s.build()
    traj = nc.simulate(model, 2.0, 0.05, rtol=1e-8, atol=1e-10)
    body = s.joints[0].B
    return s, model, traj, body


@pytest.mark.parametrize("shape, size", [("sphere", "0.1"), ("box", "0.1 0.15 0.05")])
def test_a_dropped_shape_rests_at_the_closed_form_depth(shape, size):
    """At rest the contact forces carry the weight: a sphere sinks δ with ``k δ^1.5 = m g``;
    a box lying flat on its 4 lower corners, ``k δ^1.5 = m g / 4`` each (Hunt–Crossley law,
    exponent 1.5).  Final height within 1e-6 m of ``half height − δ``."""
    half = float(size.split()[-1])
    s, model, traj, body = drop(shape, size, half + 0.05)
    n = 1 if shape == "sphere" else 4
    delta = (body.spec["mass"] * 9.81 / n / 2e4) ** (1 / 1.5)
    z = traj.q[-1][model.coordinate_names.index(f"{body.name}.r_i.z")]        # the centre of mass
    assert abs(z - (half - delta)) < 1e-6, (z, half - delta)
    assert np.max(np.abs(traj.v[-1])) < 1e-4


def test_bad_contacts_option_is_named():
    with pytest.raises(ModelError, match="contacts: unknown key\\(s\\) 'stifness'"):
        nc.System.from_mjcf(SCENE, contacts={"stifness": 1.0})


def test_a_pair_its_element_refuses_is_named():
    """A sphere fixed in the world against a moving sphere (SphereSphere needs both moving):
    named in the warning with the element's reason, not added."""
    text = """<mujoco><worldbody><geom name="post" type="sphere" size="0.1"/>
      <body pos="0 0 0.5"><freejoint/><geom name="bob" type="sphere" size="0.1"/></body></worldbody></mujoco>"""
    with pytest.warns(MjcfWarning, match=r"text:2 <geom>: contact of geom 'bob' \(sphere\) with 'post' \(sphere\) at "
                                         r"text:1 \(.*a sphere needs a moving member"):
        s = nc.System.from_mjcf(text, contacts=True)
    assert s.contacts == []


RSSR = Path(__file__).parent / "data" / "rssr.xml"


def test_capsules_meeting_at_a_loop_point_are_named():
    """The coupler's and the rocker's capsules share the end point where ``<connect>`` closes the
    loop: MuJoCo's ``mj_collision`` collides them there (0.04 m deep, both radii), so the import
    keeps the pair, and the build refuses it by name (its normal is undefined: the cores meet)
    instead of a non-finite initial state that names nothing.  Excluded, the loop builds."""
    mujoco = pytest.importorskip("mujoco")
    mj = mujoco.MjModel.from_xml_path(str(RSSR))
    d = mujoco.MjData(mj)
    mujoco.mj_forward(mj, d)
    theirs = {frozenset((mj.body(mj.geom_bodyid[c.geom1]).name, mj.body(mj.geom_bodyid[c.geom2]).name)): c.dist
              for c in d.contact[:d.ncon]}
    assert set(theirs) == {frozenset(("coupler", "rocker"))} and theirs[frozenset(("coupler", "rocker"))] == \
        pytest.approx(-0.04, abs=1e-12)
    s = nc.System.from_mjcf(RSSR, contacts=True)
    assert "coupler_geom0__rocker_geom0" in [c.name for c in s.contacts]
    with pytest.raises(ModelError, match=r"contact 'coupler_geom0__rocker_geom0\.b_end1' \(CapsuleCapsule\) between "
                                         r"'rocker' and 'coupler': its contact normal is undefined.*gap -0\.04 m"):
        s.build()
    text = RSSR.read_text().replace("</equality>", '</equality><contact><exclude body1="coupler" body2="rocker"/>'
                                                   "</contact>")
    s = nc.System.from_mjcf(text, contacts=True)
    assert [c.name for c in s.contacts] == ["crank_geom0__rocker_geom0"]
    model = s.build()
    assert np.all(np.array(model.functions["gap"](model.q0, model.p0)) > 0.1)


BALL = """<mujoco><worldbody><geom name="floor" type="plane" size="2 2 0.1"/>
  <body name="ball" pos="0 0 0.12"><freejoint/><geom name="ball" type="sphere" size="0.1" density="600"/></body>
</worldbody></mujoco>"""


def test_cli_mjcf_contacts_rest_the_ball_at_the_closed_form_depth(tmp_path, monkeypatch):
    """``ncgen simulate ball.xml --mjcf-contacts``: a ball dropped 2 cm onto the floor comes to
    rest where its contact carries its weight, ``k δ^e = m g`` (m = ρ 4/3 π r³; k, e the law's
    stiffness and exponent), within 5e-6 m after 20 s; without the flag it falls through."""
    from ncgen.cli import main
    monkeypatch.setenv("NCGEN_CACHE_DIR", str(tmp_path / "cache"))
    path = tmp_path / "ball.xml"
    path.write_text(BALL)
    law = nc.System.from_mjcf(path, contacts=True).contacts[0]
    mass = 600 * 4 / 3 * np.pi * 0.1 ** 3
    delta = (mass * 9.81 / law.stiffness) ** (1 / law.exponent)
    z = {}
    for flag in ([], ["--mjcf-contacts"]):
        out = tmp_path / f"run{len(flag)}.npz"
        assert main(["simulate", str(path), *flag, "--t-end", "20", "--dt", "0.5", "-o", str(out)]) in (0, None)
        run = np.load(out)
        z[bool(flag)] = run["q"][:, list(run["coordinate_names"]).index("ball.r_i.z")]
    assert z[False][-1] < -100                                   # free fall: 0.12 − g t²/2
    assert abs(z[True][-1] - (0.1 - delta)) < 5e-6, (z[True][-1], 0.1 - delta)
    assert z[True].min() > 0.1 - 10 * delta                      # never through the floor


def test_contact_points_share_their_nodes_without_changing_a_number():
    """Elements at one point share its expressions (``Context.local_point``, one pair per
    point: the Menagerie Panda's 400 box corners built in 5.5 s CPU instead of 7): the gaps,
    contact Jacobians and smooth forces of the scene's every shape pair at random states are
    bitwise those of each point contact written alone in a context of its own, as before."""
    import casadi as ca

    from ncgen.assembly.contact_kinematics import contact_terms, smooth_forces
    from ncgen.model.context import Context
    from ncgen.model.contacts import point_contacts
    with pytest.warns(MjcfWarning):
        s = nc.System.from_mjcf(SCENE, contacts=True)
    model = s.build()
    points = point_contacts(model.contact_elements)
    assert len(points) == model.nk > 50
    alone_functions = []                 # each point contact alone, in a context of its own
    for point in points:
        ctx = Context(s, model.layout)
        (alone,) = contact_terms(ctx, [point])
        fn_alone = smooth_forces(ctx, [alone])[0]
        alone_functions.append(ca.Function("one", [ctx.t, ctx.q, ctx.v, ctx.p],
                                           [alone.g, alone.WN, alone.WT, fn_alone]))
    rng = np.random.default_rng(5)
    f = model.functions
    for _ in range(3):
        q = model.q0 + 0.05 * rng.normal(size=model.nq)
        v = rng.normal(size=model.nq)
        g = np.array(f["gap"](q, model.p0)).ravel()
        WN, WT = (np.array(x) for x in f["contact_jacobian"](q, model.p0))
        fN = np.array(f["contact_force"](0.0, q, v, model.p0)[0]).ravel()
        per = WT.shape[0] // len(points)
        for k, (point, one) in enumerate(zip(points, alone_functions)):
            gk, WNk, WTk, fNk = (np.array(x) for x in one(0.0, q, v, model.p0))
            assert gk.item() == g[k] and fNk.item() == fN[k], point.name
            assert np.array_equal(WNk, WN[k:k + 1]) and np.array_equal(WTk, WT[k * per:(k + 1) * per]), point.name
