"""'ncgen check MODEL.toml': the report and its exit code."""
from __future__ import annotations

from pathlib import Path

import pytest

import ncgen as nc
from ncgen.cli import main

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def test_consistent_example(capsys):
    assert main(["check", str(EXAMPLES / "fourbar_3d.toml")]) == 0
    out = capsys.readouterr().out
    for text in ("members (3):", "coupler          bar   rr   mass 0.8 kg; shares r_i = crank.r_j, r_j = rocker.r_j",
                 "coordinates (nq = 12):", "constraints (nc = 11):", "rank A = 11, DOF = 1",
                 "coordinate sharing: nq 24 -> 12, nc 23 -> 11",
                 "joints eliminated (2): crank_hinge (shared point and axis), rocker_hinge (shared point and axis)",
                 "redundant constraints: none", "max |Φ| = ", "consistent: yes"):
        assert text in out


def test_redundant_constraints_are_named(tmp_path, capsys):
    s = nc.System("triangle", gravity=(0, -9.81))
    crank = s.add_body("crank", coords="rrv", mass=1, inertia=0.05, position=(0.5, 0))
    rocker = s.add_body("rocker", coords="rrv", mass=1, inertia=0.05, position=(1.5, 0.5))
    s.add_joint(nc.Revolute(s.ground, crank, at=(0, 0), name="O"))
    s.add_joint(nc.Revolute(crank, rocker, at=(1, 0), name="B"))
    s.add_joint(nc.Revolute(rocker, s.ground, at=(2, 1), name="C"))
    s.add_joint(nc.Distance(crank, rocker, at=((0.5, 0), (1.5, 0.5)), name="extra"))
    path = tmp_path / "m.toml"
    path.write_text(s.to_toml(), encoding="utf-8")
    assert main(["check", str(path)]) == 0
    out = capsys.readouterr().out
    assert "rank A = 6, DOF = 0" in out and "joints eliminated (3): O (shared point)" in out and "redundant constraints: extra.distance (dropped when building)" in out


def test_inconsistent_initial_state_exits_1(tmp_path, capsys):
    s = nc.System("moving")
    s.add_bar("bar", mass=1.0, ends=[s.ground.point((0, 0, 0)), (1, 0, 0)], velocity=(0.5, 0, 0))
    path = tmp_path / "moving.toml"
    path.write_text(s.to_toml(), encoding="utf-8")
    assert main(["check", str(path)]) == 1
    out = capsys.readouterr().out
    assert "max |A v + Φ_t| = 1 m²/s" in out
    assert "consistent: no: inconsistent initial velocities: making them satisfy the constraints changes " \
           "bar.r_j.x by 0.5 m/s" in out
    assert main(["check", str(path), "--tolerance", "1"]) == 0


@pytest.mark.parametrize("text, message", [
    ('[[members]]\nname = "a"\nkind = "point"\nmass = 1.0\nposition = [0, 0]\n',
     "members[0].position: expected 3 numbers, got 2"),
    ('[[members]]\nname = "a"\nkind = "point"\nmass = 1.0\nposition = [0, 0, 0]\n'
     '[[joints]]\ntype = "Revolute"\nbetween = ["ground", "a"]\nat = [0, 0, 0]\naxis = [0, 0, 1]\n',
     "a is a point member and has no orientation"),
])
def test_invalid_models_exit_1_with_the_key_path(tmp_path, capsys, text, message):
    path = tmp_path / "bad.toml"
    path.write_text(text, encoding="utf-8")
    assert main(["check", str(path)]) == 1
    assert message in capsys.readouterr().err


def test_help_has_examples(capsys):
    assert main(["check", "--help"]) == 0
    assert "ncgen check examples/fourbar_planar.toml" in capsys.readouterr().out
