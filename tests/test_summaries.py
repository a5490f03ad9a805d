"""Summaries and files say what happened: energy balance of dissipative runs (never "drift"),
conservative runs called conservative, no nan lines, continuous joint angles, CSV columns
with units.  Balances are checked against the closed form where there is one."""
import csv
import os

import numpy as np
import pytest

import ncgen as nc


def ball(contacts="smooth"):
    s = nc.System("ball", gravity=(0, 0, -9.81))
    b = s.add_point("ball", mass=1.0, position=(0, 0, 0.3))
    b.add_marker("centre", (0, 0, 0))
    s.add_contact(nc.SpherePlane(b, radius=0.1, restitution=0.5, mu=0.3, name="floor"))
    return s.build(contacts=contacts)


def test_contact_run_is_a_balance_with_the_contacts_work():
    traj = nc.simulate(ball(), 1.0, 1e-3, backend="vm")
    text = traj.summary()
    assert "energy balance" in text and "contacts" in text and "drift:" not in text.split("constraint")[0]
    assert "nan" not in text
    e = traj.info["energy"]
    assert e["conservative"] is False
    # the balance closes: the loss is the contacts' work, integrated by IDAS as quadratures
    change = traj.energy[-1] - traj.energy[0]
    assert change < -1.0 and e["parts"]["contacts"] + e["parts"]["friction"] == pytest.approx(change, rel=1e-6)


def test_nonsmooth_run_has_no_nan_line():
    traj = nc.simulate(ball("nonsmooth"), 0.5, 1e-3, method="stepper")
    text = traj.summary()
    assert "nan" not in text and "not estimated (nonsmooth contacts" in text
    assert "contacts (normal)" in text and "accumulated step by step" in text
    assert traj.info["energy"]["relative"] < 1e-6


def test_input_work_matches_the_closed_form():
    """A point pushed by a constant force F along x from rest: W = F² t² / (2 m)."""
    s = nc.System("pushed", gravity=(0, 0, 0))
    p = s.add_point("p", mass=2.0, position=(0, 0, 0))
    f = s.add_input("f")
    s.add_force(nc.PointForce(p, (0, 0, 0), force=[f, 0, 0]))
    model = s.build()
    traj = nc.simulate(model, 1.0, 0.01, u=lambda t: [3.0])
    assert traj.info["energy"]["parts"]["inputs"] == pytest.approx(9.0 / 4.0, rel=1e-6)
    assert "inputs 2.25 J" in traj.summary()
    idle = nc.simulate(model, 1.0, 0.01)          # zero inputs do no work: conservative
    assert "energy (conservative" in idle.summary()


def test_joint_angles_are_continuous(tmp_path):
    s = nc.System("spinner", gravity=(0, -9.81))
    bar = s.add_bar("bar", mass=1.0, ends=[(0, 0), (1, 0)], velocity=(0, 6.0), angular_velocity=12.0)
    s.add_joint(nc.Revolute(s.ground, bar, at=(0, 0)))
    model = s.build(share=False)
    traj = nc.simulate(model, 2.0, 0.01)
    angle, rate = traj.joint(model.joint_names[0])
    assert angle[-1] - angle[0] > 4 * np.pi                  # several turns, counted
    assert np.max(np.abs(np.diff(angle))) < 0.5
    path = traj.save(tmp_path / "spin.csv")
    with open(path) as fh:
        rows = list(csv.reader(fh))
    col = rows[0].index(f"qj.{model.joint_names[0]} [rad]")
    np.testing.assert_allclose(np.array([r[col] for r in rows[1:]], float), angle)


def test_csv_carries_rates_markers_and_contacts(tmp_path):
    traj = nc.simulate(ball(), 0.3, 0.01, backend="vm")
    with open(traj.save(tmp_path / "ball.csv")) as fh:
        rows = list(csv.reader(fh))
    header = rows[0]
    for name in ("t [s]", "ball.r_i.z [m]", "v.ball.r_i.z [m/s]", "ball.centre.z [m]", "gap.floor [m]",
                 "contact_normal.floor [N]", "contact_tangent.floor.2 [N]"):
        assert name in header, name
    table = np.array(rows[1:], float)
    np.testing.assert_allclose(table[:, header.index("v.ball.r_i.z [m/s]")], traj.v[:, 2])
    np.testing.assert_allclose(table[:, header.index("gap.floor [m]")], traj.gap[:, 0])


def test_run_time_is_labelled_wall_and_cpu():
    """The integrator's line gives its wall time and its CPU time, labelled (a wall time read as
    CPU time on a loaded machine looked like a 5× slowdown of box_stack): the CPU time is
    positive and at most the wall time times the machine's cores."""
    traj = nc.simulate(ball(), 0.2, 1e-2, backend="vm")
    info = traj.info
    assert 0 < info["cpu_time"] <= info["wall_time"] * os.cpu_count() + 0.05
    assert f"{info['wall_time']:.3g} s wall ({info['cpu_time']:.3g} s CPU)" in traj.summary()
