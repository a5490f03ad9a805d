"""TOML model files: round trips through to_toml/from_toml give identical functions, and
every kind of bad input gives one clear message with the key path."""
from __future__ import annotations

import re
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

import ncgen as nc

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
FUNCTIONS = ("phi", "A", "phi_t", "gamma", "F", "ode", "alg", "energy", "markers", "poses", "accel")


def _everything_3d():
    """Every member type, shared points of every sort, every joint and force, drives,
    inputs, parameters; values as numbers, text, SX and callables."""
    s = nc.System("everything", gravity=(0.1, -0.2, -9.81))
    k = s.add_parameter("k", 40.0)
    gains = s.add_parameter("gains", [0.5, 2.0])
    push = s.add_input("push", 3)
    s.add_input("tau", 1)
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    base = s.add_body("base", coords="ruvw", mass=3.0, inertia=np.diag([0.3, 0.4, 0.5]), position=(0, 0, 1))
    arm = s.add_body("arm", coords="rrvw", mass=1.0, inertia=np.diag([0.05, 0.2, 0.2]), position=(0.5, 0, 1),
                     rotation=R, basis=[(-0.5, 0, 0), (0.5, 0, 0), (0, 1, 0), (0, 0, 1)])
    plate = s.add_body("plate", coords="rrrw", mass=0.5, inertia=np.diag([0.1, 0.1, 0.15]), position=(2, 0, 0),
                       basis=[(0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)])
    s.add_body("hub", coords="rrrr", mass=0.5, inertia=np.diag([0.1, 0.1, 0.15]), position=(7, 0, 0),
               share={"r_i": s.ground.point((7.0, 0.0, 0.0)), "r_k": plate.node("r_k")},
               basis=[(0, 0, 0), (-4, 1, 0), (-5, 1, 0), (0, 0, 1)])
    block = s.add_body("block", coords="rrrr", mass=0.7, inertia=np.diag([0.02, 0.03, 0.04]), position=(0, 2, 0))
    rod = s.add_bar("rod", coords="rr", mass=0.4, ends=[arm.node("r_j"), (0.5, 1.0, 1.5)])
    link = s.add_bar("link", coords="ru", mass=0.3, ends=[rod.end(1), (0.5, 1.5, 1.5)], com=0.2, inertia=0.01)
    bead = s.add_point("bead", mass=0.1, position=(3, 0, 0), velocity=(0, 0.5, 0))
    s.add_point("knob", mass=0.05, position=rod.end(1))
    rod.add_marker("mid", (0.1, 0, 0))
    base.add_marker("corner", (0.2, 0.1, -0.1))
    hinge = s.add_joint(nc.Revolute(s.ground, base, at=(0, 0, 1), axis=(0, 0, 1), name="hinge",
                                    drive=lambda t: 0.2 * t + 0.1 * ca.sin(gains[1] * t)))
    s.add_joint(nc.Revolute(base, arm, at=(0, 0, 1), axis=(0, 1, 0)))
    s.add_joint(nc.Prismatic(s.ground, block, at=(0, 2, 0), axis=(0, 1, 0), drive="0.1*t**2"))
    s.add_joint(nc.Cylindrical(block, link, at=(0.5, 1.5, 1.5), axis=(0, 1, 0)))
    s.add_joint(nc.Universal(s.ground, plate, at=(2, 0, 0), axis_a=(0, 0, 1), axis_b=(1, 0, 0)))
    s.add_joint(nc.PointOnPlane(s.ground, bead, at=(3, 0, 0), normal=(0, 0, 1)))
    s.add_joint(nc.Planar(s.ground, s.add_body("puck", mass=1, inertia=np.eye(3) * 0.1, position=(4, 4, 0)),
                          at=(4, 4, 0), normal=(0, 0, 1)))
    s.add_joint(nc.PointOnLine(plate, s.add_point("dot", mass=0.1, position=(3, 1, 0)), at=(3, 1, 0),
                               axis=(1, 0, 0)))
    s.add_joint(nc.Distance(block, rod, at=((0, 2, 0), (0.5, 1.0, 1.5)), drive=k / 40 * 1.8708286933869707))
    pole = s.add_bar("pole", mass=1, ends=[(6, 0, 0), (6, 0, 1)], velocity=(0, -0.15, 0),
                     angular_velocity=(0.3, 0, 0))
    s.add_joint(nc.CoordinateDriver(pole, "r_j", "x", "6 + 0.1*sin(t)"))
    s.add_joint(nc.Fixed(s.ground, s.add_body("lid", mass=1, inertia=np.eye(3) * 0.1, position=(5, 5, 5)),
                         at=(5, 5, 5)))
    s.add_joint(nc.Spherical(s.ground, pole, at=(6, 0, 0)))
    s.add_force(nc.Spring(base, (0.2, 0, 0), s.ground, (1, 1, 1), k=k, rest_length="0.5", damping=0.3))
    s.add_force(nc.Spring(rod, (0.2, 0, 0), bead, (0, 0, 0), k=lambda t: k * (1 + 0.5 * ca.cos(t)), cable=True))
    s.add_force(nc.PointForce(arm, (0.1, 0, 0), force=push))
    s.add_force(nc.PointForce(plate, (0.5, 0.5, 0), force=[0, "gains[0]*sin(t)", lambda t: 2 * t]))
    s.add_force(nc.Torque(arm, ca.vertcat(0, s.inputs["tau"][0], 0)))
    s.add_force(nc.TorsionalSpring(hinge, k="k/10", damping=gains[0], rest_angle=0.3))
    s.add_force(nc.GeneralizedForce(lambda t, q, v, u, p: -0.01 * v * p[1]))
    return s


def _everything_planar():
    s = nc.System("planar_everything", gravity=(0, -9.81))
    w = s.add_parameter("w", 3.0)
    s.add_input("f", 2)
    crank = s.add_bar("crank", mass=0.5, ends=[(0, 0), (0, 1)], angular_velocity=0.0)
    slider = s.add_body("slider", coords="rrv", mass=1.0, inertia=0.02, position=(2, 0.5), rotation=0.2,
                        basis=[(0.1, 0), (0.3, 0), (0, 1)])
    s.add_bar("coupler", coords="ru", mass=0.7, ends=[crank.end(1), (1, 1)])
    p = s.add_point("p", mass=0.2, position=(3, 3))
    blob = s.add_body("blob", coords="rrr", mass=1.0, inertia=0.1, position=(5, 5))
    hinge = s.add_joint(nc.Revolute(s.ground, crank, at=(0, 0), drive=lambda t: w * t))
    s.add_joint(nc.Prismatic(s.ground, slider, at=(2, 0.5), axis=(1, 0), drive="sin(t)**2"))
    s.add_joint(nc.Fixed(slider, p, at=(3, 3)))
    s.add_joint(nc.Distance(p, blob, at=((3, 3), (5, 5))))
    s.add_joint(nc.PointOnLine(s.ground, blob, at=(5, 5), axis=(1, 0)))
    s.add_force(nc.TorsionalSpring(hinge, k=2.0, rest_angle="0.1*t"))
    s.add_force(nc.Torque(blob, "f[1]*w"))
    s.add_force(nc.PointForce(blob, (0.1, 0.2), force="f"))
    s.add_force(nc.GeneralizedForce(["0"] * 7 + ["-v[7]"] + ["0"] * 8 + ["q[0]"] * 4))
    return s


def _compare(m1, m2, seed=0):
    assert (m1.nq, m1.nc, m1.nu, m1.np) == (m2.nq, m2.nc, m2.nu, m2.np)
    assert m1.coordinate_names == m2.coordinate_names and m1.constraint_names == m2.constraint_names
    assert m1.marker_names == m2.marker_names
    assert np.array_equal(m1.q0, m2.q0) and np.array_equal(m1.v0, m2.v0) and np.array_equal(m1.p0, m2.p0)
    rng = np.random.default_rng(seed)
    for _ in range(3):
        args = {"t": rng.uniform(0, 2), "q": m1.q0 + 0.1 * rng.normal(size=m1.nq), "v": rng.normal(size=m1.nq),
                "u": rng.normal(size=m1.nu), "p": m1.p0 * rng.uniform(0.5, 2, size=m1.np),
                "lam": rng.normal(size=m1.nc)}
        for name in FUNCTIONS:
            f1, f2 = m1.functions[name], m2.functions[name]
            r1 = f1.call({k: args[k] for k in f1.name_in()})
            r2 = f2.call({k: args[k] for k in f2.name_in()})
            for key in r1:
                a, b = np.array(r1[key]), np.array(r2[key])
                assert np.allclose(a, b, rtol=1e-12, atol=1e-12), (name, key)


@pytest.mark.parametrize("make", [_everything_3d, _everything_planar])
def test_round_trip_gives_identical_functions(make):
    s = make()
    text = s.to_toml()
    s2 = nc.System.from_toml(text)
    assert s2.to_toml() == text
    _compare(s.build(redundant="error"), s2.build(redundant="error"))


@pytest.mark.parametrize("name", ["fourbar_planar", "fourbar_3d"])
def test_examples_round_trip(name, tmp_path):
    s = nc.System.from_toml(EXAMPLES / f"{name}.toml")
    out = tmp_path / f"{name}.toml"
    out.write_text(s.to_toml(), encoding="utf-8")
    _compare(s.build(), nc.System.from_toml(out).build())


BASE = '''
[system]
name = "t"
gravity = [0.0, 0.0, -9.81]
[parameters]
omega = 2.0
[inputs]
push = 1
[[members]]
name = "crank"
kind = "body"
mass = 1.0
inertia = [[0.1, 0, 0], [0, 0.1, 0], [0, 0, 0.1]]
[[members]]
name = "pt"
kind = "point"
mass = 1.0
position = [0, 0, 1]
'''


@pytest.mark.parametrize("extra, message", [
    ('[[joints]]\ntype = "Revolute"\nbetween = ["ground", "crank"]\nat = [0, 0, 0]\naxis = [0, 1]\n'
     '[[joints]]\ntype = "Revolute"\nbetween = ["ground", "crank"]\nat = [0, 0, 0]\naxis = [0, 1, 0]\n'
     '[[joints]]\ntype = "Revolute"\nbetween = ["ground", "crank"]\nat = [0, 0, 0]\naxis = [0, 1]\n',
     "joints[0].axis: expected 3 numbers, got 2"),
    ('[[joints]]\ntype = "Revolute"\nbetween = ["ground", "crank"]\nat = [0, 0, 0]\naxes = [0, 1, 0]\n',
     "joints[0].axes: unknown key (did you mean 'axis'?); expected one of: type, dynamics, name, between, at, axis, drive"),
    ('[[joints]]\ntype = "Revolut"\nbetween = ["ground", "crank"]\n',
     "joints[0].type: unknown joint type 'Revolut' (did you mean 'Revolute'?)"),
    ('[[joints]]\ntype = "Spherical"\nbetween = ["ground", "crnk"]\nat = [0, 0, 0]\n',
     "joints[0].between[1]: no member named 'crnk' (did you mean 'crank'?)"),
    ('[[joints]]\ntype = "Revolute"\nbetween = ["ground", "crank"]\nat = [0, 0, 0]\naxis = [0, 0, 1]\n'
     'drive = "omga*t"\n', "joints[0].drive: unknown name 'omga' (did you mean 'omega'?)"),
    ('[[joints]]\ntype = "Revolute"\nbetween = ["ground", "crank"]\nat = [0, 0, 0]\naxis = [0, 0, 1]\n'
     'drive = "push*t"\n', "joints[0].drive: unknown name 'push'"),
    ('[[joints]]\ntype = "Revolute"\nbetween = ["ground", "pt"]\nat = [0, 0, 1]\naxis = [0, 0, 1]\n',
     "joints[0]: joint 'revolute_0' (Revolute ground–pt): pt is a point member and has no orientation"),
    ('[[joints]]\ntype = "Revolute"\nbetween = ["ground", "crank"]\nat = [0, 0, 0]\n',
     "joints[0]: joint 'revolute_0' (Revolute ground–crank): axis: expected a direction, got nothing"),
    ('[[joints]]\ntype = "Spherical"\nbetween = "crank"\nat = [0, 0, 0]\n',
     "joints[0].between: expected two member names (\"ground\" for the ground), got a string ('crank')"),
    ('[[forces]]\ntype = "PointForce"\nmember = "crank"\nat = [0, 0, 0]\nforce = [0, 0]\n',
     "forces[0].force: expected 3 numbers or expression strings, got 2"),
    ('[[forces]]\ntype = "PointForce"\nmember = "crank"\nat = [0, 0, 0]\nforce = "push"\n',
     "forces[0].force: expected 3 components, 'push' has 1"),
    ('[[forces]]\ntype = "Spring"\nbetween = ["crank", "pt"]\nat_a = [0, 0, 0]\nat_b = [0, 0, 0]\n'
     'k = true\n', "forces[0].k: expected a number or an expression string, got a boolean (true)"),
    ('[[forces]]\ntype = "TorsionalSpring"\njoint = "hing"\nk = 1.0\n', "forces[0].joint: no joint named 'hing'"),
    ('[[forces]]\ntype = "Torque"\nmember = "crank"\ntorque = [0, 0, "__import__(1)"]\n',
     "forces[0].torque[2]: unknown function '__import__'"),
    ("[systm]\nname = 'x'\n", "systm: unknown top-level key (did you mean 'system'?)"),
])
def test_bad_files_name_the_key(extra, message):
    with pytest.raises(nc.ModelError) as err:
        nc.System.from_toml(BASE + extra)
    assert message in str(err.value)


@pytest.mark.parametrize("text, message", [
    ('[[members]]\nname = "a"\nkind = "bar"\nmas = 1.0\nends = [[0, 0, 0], [1, 0, 0]]\n',
     "members[0].mas: unknown key (did you mean 'mass'?)"),
    ('[[members]]\nname = "a"\nkind = "bar"\nmass = "heavy"\nends = [[0, 0, 0], [1, 0, 0]]\n',
     "members[0].mass: expected a number, got a string ('heavy')"),
    ('[[members]]\nname = "a"\nkind = "bar"\nmass = 1.0\n', "members[0].ends: missing (required)"),
    ('[[members]]\nname = "a"\nkind = "rod"\nmass = 1.0\n',
     "members[0].kind: expected one of body, bar, point, got 'rod'"),
    ('[[members]]\nname = "a"\nkind = "bar"\nmass = 1.0\nends = ["b.r_j", [1, 0, 0]]\n',
     "members[0].ends[0]: no member named 'b'"),
    ('[[members]]\nname = "a"\nkind = "bar"\nmass = 1.0\nends = [{grnd = [0, 0, 0]}, [1, 0, 0]]\n',
     "members[0].ends[0].grnd: unknown key (did you mean 'ground'?)"),
    ('[[members]]\nname = "a"\nkind = "body"\nmass = 1.0\ninertia = [1, 2, 3]\n',
     "members[0].inertia[0]: expected 3 numbers, got a number (1)"),
    ('[[members]]\nname = "a"\nkind = "body"\nmass = 1.0\ninertia = 0.1\n',
     "members[0].inertia: expected a 3×3 matrix (3 rows of 3 numbers), got a number (0.1)"),
    ('[[members]]\nname = "a"\nkind = "bar"\nmass = 1.0\nends = [[0, 0, 0], [1, 0, 0]]\n'
     '[[members]]\nname = "a"\nkind = "point"\nmass = 1.0\nposition = [0, 0, 0]\n',
     "members[1]: point 'a': the name is already used in system"),
    ('[parameters]\nt = 1.0\n[[members]]\nname = "a"\nkind = "point"\nmass = 1.0\nposition = [0, 0, 0]\n',
     "parameters.t: parameter 't': the name is reserved in expressions"),
    ('[inputs]\nu1 = 0\n', "inputs.u1: expected the input's size (a positive integer), got a number (0)"),
    ("[system]\ngravity = [0, 1, 2, 3]\n", "system.gravity: expected 2 (planar) or 3 numbers, got 4"),
    ("[system\n", "<toml text>: invalid TOML"),
    ('[system]\nname = "x"\n', "members: missing (required)"),
])
def test_bad_members_and_headers(text, message):
    with pytest.raises(nc.ModelError) as err:
        nc.System.from_toml(text)
    assert message in str(err.value)


def test_missing_file():
    with pytest.raises(nc.ModelError, match="cannot read model file 'no/such/model.toml'"):
        nc.System.from_toml("no/such/model.toml")


def test_unprintable_values_are_reported():
    s = nc.System("mx")
    b = s.add_body("b", mass=1, inertia=np.eye(3) * 0.1)
    s.add_force(nc.Torque(b, ca.vertcat(0, 0, ca.SX.sym("stranger"))))
    with pytest.raises(nc.ModelError, match=r"torque\[2\]: symbol 'stranger' is not one of the system's names"):
        s.to_toml()


def test_the_documented_example_builds():
    doc = (Path(__file__).resolve().parent.parent / "docs" / "model-format.md").read_text(encoding="utf-8")
    example = re.findall(r"```toml\n(.*?)```", doc, re.S)[-1]
    model = nc.System.from_toml(example).build()
    report = nc.dof_report(model)
    assert (model.nq, model.nc, report.rank, report.dof, model.nu, model.np) == (10, 8, 8, 2, 1, 3)
