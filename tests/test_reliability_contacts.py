"""Contacts at t = 0: overlaps that no run can start from are refused when the model is
built (and by ``ncgen check``), naming the contact and the depth; shallow overlaps of the
compliant law build and are listed by ``ncgen check``."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import ncgen as nc
from ncgen.assembly.contact_kinematics import INITIAL_PENETRATION_TOL


def ball_on_floor(height, radius=0.1, plane_normal=(0, 0, 1)):
    s = nc.System("drop")
    b = s.add_body("ball", mass=1.0, inertia=0.004 * np.eye(3), position=(0.3, 0.0, height))
    s.add_contact(nc.SpherePlane(b, radius=radius, normal=plane_normal, mu=0.4, name="floor"))
    return s


@pytest.mark.parametrize("contacts", ["nonsmooth", "smooth"])
def test_a_sphere_deep_in_the_floor_is_refused_by_name(contacts):
    with pytest.raises(nc.ModelError, match=r"contact 'floor'.*penetrates by 0\.3 m \(gap -0\.3 m\)"):
        ball_on_floor(-0.2).build(contacts=contacts)


def test_nonsmooth_refuses_a_shallow_overlap_smooth_accepts_it():
    depth = 100 * INITIAL_PENETRATION_TOL
    s = ball_on_floor(0.1 - depth)
    with pytest.raises(nc.ModelError, match=r"contact 'floor'.*penetrates by 0\.0001 m.*nonsmooth"):
        s.build(contacts="nonsmooth")
    g = s.build(contacts="smooth").functions["gap"]
    assert float(g(s.build().q0, [])) == pytest.approx(-depth, abs=1e-12)
    ball_on_floor(0.1 - 0.5 * INITIAL_PENETRATION_TOL).build(contacts="nonsmooth")   # within the tolerance


def test_a_tilted_plane_measures_depth_along_its_normal():
    n = np.array([0.0, 0.6, 0.8])
    s = nc.System("tilt")
    b = s.add_body("ball", mass=1.0, inertia=0.004 * np.eye(3), position=0.05 * n)
    s.add_contact(nc.SpherePlane(b, radius=0.1, normal=n, name="slope"))
    with pytest.raises(nc.ModelError, match=r"contact 'slope'.*penetrates by 0\.05 m"):
        s.build(contacts="nonsmooth")


def test_coincident_sphere_centres_are_refused_by_name():
    s = nc.System("pair")
    a = s.add_body("a", mass=1.0, inertia=0.004 * np.eye(3), position=(0, 0, 1))
    b = s.add_body("b", mass=1.0, inertia=0.004 * np.eye(3), position=(0, 0, 1))
    s.add_contact(nc.SphereSphere(a, radius_a=0.1, b=b, radius_b=0.1, name="touch"))
    for contacts in ("smooth", "nonsmooth"):
        with pytest.raises(nc.ModelError, match=r"contact 'touch'.*centres of the spheres on 'a' and 'b' coincide"):
            s.build(contacts=contacts)


MODEL = """
[system]
name = "drop"
gravity = [0, 0, -9.81]
[[members]]
name = "ball"
kind = "body"
coords = "ruvw"
mass = 1.0
inertia = [[0.004, 0, 0], [0, 0.004, 0], [0, 0, 0.004]]
position = [0, 0, {height}]
[[contacts]]
type = "SpherePlane"
name = "floor"
sphere = "ball"
radius = 0.1
"""


def test_cli_check_names_the_penetration_and_lists_gaps(tmp_path):
    deep = tmp_path / "deep.toml"
    deep.write_text(MODEL.format(height=-0.4))
    r = subprocess.run([sys.executable, "-m", "ncgen.cli", "check", str(deep)], capture_output=True, text=True,
                       timeout=120)
    out = r.stdout + r.stderr
    assert r.returncode == 1 and "consistent: yes" not in out
    assert "contact 'floor'" in out and "penetrates by 0.5 m" in out
    ok = tmp_path / "ok.toml"
    ok.write_text(MODEL.format(height=0.35))
    r = subprocess.run([sys.executable, "-m", "ncgen.cli", "check", str(ok)], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    assert "initial gaps (m, < 0 penetrating): floor 0.25" in r.stdout
