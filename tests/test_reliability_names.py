"""Coordinates as written keep resolving after coordinate sharing re-bases their member:
``model.coordinate`` and ``traj.coordinate`` give the value of the unshared coordinate
(checked against a ``share=False`` run of the same system and against the body's geometry);
``nc.assemble(values=...)``, optimal-control bounds and targets and the TOML ``initial``
tables take them and give what ``share=False`` gives; unknown names say what exists."""
from __future__ import annotations

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import OptimizationError, ShapeError


def arm():
    s = nc.System("arm")
    up = s.add_body("upper", mass=1.0, inertia=np.diag([0.01, 0.02, 0.02]), position=(0.5, 0, 0))
    lo = s.add_body("lower", mass=1.0, inertia=np.diag([0.01, 0.02, 0.02]), position=(1.5, 0, 0))
    s.add_joint(nc.Revolute(s.ground, up, at=(0, 0, 0), axis=(0, 1, 0), name="shoulder"))
    s.add_joint(nc.Spherical(up, lo, at=(1, 0, 0), name="elbow"))
    return s


def test_names_as_written_resolve_after_sharing():
    shared, written = arm().build(), arm().build(share=False)
    assert "upper.r_i.x" not in shared.coordinate_names and "upper.r_i.x" in written.coordinate_names
    b = nc.simulate(written, 0.6, 0.05, rtol=1e-10, atol=1e-10)
    a = nc.simulate(shared, 0.6, 0.05, rtol=1e-10, atol=1e-10)
    for name in ("upper.r_i.x", "upper.r_i.z", "upper.u.z", "upper.w.x", "lower.r_i.y", "lower.v.z"):
        x, xd = a.coordinate(name)
        i = written.coordinate_names.index(name)
        np.testing.assert_allclose(x, b.q[:, i], atol=1e-6)
        np.testing.assert_allclose(xd, b.v[:, i], atol=1e-5)
    # the body's centre of mass is its r_i as written (position=...): check against the pose
    R, p = shared.poses(a.q[-1])
    s, c = shared.coordinate("upper.r_i.x")
    assert s @ a.q[-1] + c == pytest.approx(p[shared.member_names.index("upper")][0], abs=1e-12)
    # names of the shared model resolve as themselves
    s, c = shared.coordinate(shared.coordinate_names[3])
    assert s[3] == 1.0 and s.sum() == 1.0 and c == 0.0


def test_unknown_names_are_explained():
    shared = arm().build()
    with pytest.raises(nc.ModelError, match=r"no coordinate named 'upper\.r_k\.x'.*coordinates as written"):
        shared.coordinate("upper.r_k.x")
    ocp = nc.OptimalControl(shared, N=4, t_final=0.5)
    with pytest.raises(OptimizationError, match=r"no coordinate named 'upper\.r_k\.x'; coordinates: upper\.r_j\.x.*"
                                                r"as written .* resolve too"):
        ocp.bound_coordinate("upper.r_k.x", -1, 1)
    with pytest.raises(OptimizationError, match=r"no coordinate named 'lower\.r_i\.w'"):
        ocp.final(q={"lower.r_i.w": 0.1})
    with pytest.raises(nc.ModelError, match=r"no coordinate named 'upper\.r_z\.x'"):
        nc.assemble(shared, values={"upper.r_z.x": 0.1})
    with pytest.raises(ShapeError, match=r"values 'upper\.r_i\.z': expected a finite number, got nan"):
        nc.assemble(shared, values={"upper.r_i.z": float("nan")})


def test_assemble_sets_rebased_coordinates():
    """Values on re-based names are met exactly; fixing all of the arm's 4 degrees of freedom
    gives the configuration ``share=False`` gives (the map onto it is checked)."""
    shared, written = arm().build(), arm().build(share=False)
    values = {"upper.r_i.z": -0.3, "lower.r_i.y": 0.1, "lower.r_i.z": -0.5, "lower.v.z": 0.2}
    q_s = nc.assemble(shared, values=values)
    q_u = nc.assemble(written, values=values)
    for name, x in values.items():
        s, c = shared.coordinate(name)
        assert s @ q_s + c == pytest.approx(x, abs=1e-12)
    S, c = shared.unshared.coordinate_map(shared)
    np.testing.assert_allclose(S @ q_s + c, q_u, atol=1e-9)
    assert np.max(np.abs(written.phi(S @ q_s + c))) < 1e-12
    v_s = nc.project_velocity(shared, q_s, np.zeros(shared.nq), values={"upper.r_i.x": 0.2})
    s, _ = shared.coordinate("upper.r_i.x")
    assert s @ v_s == pytest.approx(0.2, abs=1e-12)
    assert np.max(np.abs(shared.A(q_s) @ v_s)) < 1e-12


def pendulum():
    s = nc.System("pend", gravity=(0, -9.81))
    b = s.add_body("link", mass=1.0, inertia=0.02, position=(0.5, 0.0), coords="ruv")
    s.add_joint(nc.Revolute(s.ground, b, at=(0, 0), name="hinge"))
    u = s.add_input("tau")
    s.add_force(nc.Torque(b, u[0], name="motor"))
    return s


def swing(model, bounds: bool):
    ocp = nc.OptimalControl(model, N=16, t_final=1.0)
    ocp.bound_input("tau", -15, 15)
    if bounds:
        ocp.bound_coordinate("link.r_i.y", -0.6, 0.26)          # the free swing overshoots to 0.273
        ocp.bound_velocity("link.r_i.x", -0.15, 0.15)           # the free swing reaches 0.216 m/s
    ocp.final(q={"link.r_i.y": 0.25}, v=0)
    ocp.minimize_effort()
    return ocp.solve()


def test_ocp_bounds_and_targets_on_rebased_names_reach_the_share_false_optimum():
    shared, written = pendulum().build(), pendulum().build(share=False)
    assert "link.r_i.y" not in shared.coordinate_names and "link" in shared.sharing.rebased
    a, b = swing(shared, True), swing(written, True)
    free = swing(shared, False)
    assert a.stats.objective == pytest.approx(b.stats.objective, rel=1e-7)
    assert a.stats.objective > free.stats.objective * (1 + 1e-3)             # the bounds bind
    for name in ("link.r_i.x", "link.r_i.y", "link.u.x"):
        x, xd = a.coordinate(name)
        i = written.coordinate_names.index(name)
        np.testing.assert_allclose(x, b.q[:, i], atol=1e-6)
        np.testing.assert_allclose(xd, b.v[:, i], atol=1e-5)
    y, _ = a.coordinate("link.r_i.y")
    _, xd = a.coordinate("link.r_i.x")
    assert y[-1] == pytest.approx(0.25, abs=1e-8) and y.max() <= 0.26 + 1e-8
    assert np.max(np.abs(xd)) == pytest.approx(0.15, abs=1e-6)
    np.testing.assert_allclose(a.u, b.u, atol=1e-5)


PENDULUM_TOML = """initial = {{"link.r_i.y" = {y}}}
initial_rates = {{"link.r_i.x" = {xd}}}

[system]
name = "pend"
gravity = [0.0, -9.81]

[[members]]
name = "link"
kind = "body"
coords = "ruv"
mass = 1.0
inertia = 0.02
position = [0.5, 0.0]

[[joints]]
type = "Revolute"
name = "hinge"
between = ["ground", "link"]
at = [0.0, 0.0]
"""


def test_toml_initial_on_rebased_names_gives_the_share_false_state():
    text = PENDULUM_TOML.format(y=-0.3, xd=0.2)
    shared = nc.System.from_toml(text).build()
    written = nc.System.from_toml(text).build(share=False)
    assert "link.r_i.y" not in shared.coordinate_names
    S, c = shared.unshared.coordinate_map(shared)
    np.testing.assert_allclose(S @ shared.q0 + c, written.q0, atol=1e-12)
    np.testing.assert_allclose(S @ shared.v0, written.v0, atol=1e-12)
    # closed form: the centre of mass 0.5 m from the hinge at sin θ = -0.6, ẋ = -0.5 sin θ θ̇
    theta = np.arcsin(-0.6)
    rate = 0.2 / (-0.5 * np.sin(theta))
    x, xd = shared.coordinate("link.r_i.x"), shared.coordinate("link.r_i.y")
    assert x[0] @ shared.q0 + x[1] == pytest.approx(0.5 * np.cos(theta), abs=1e-12)
    assert xd[0] @ shared.v0 == pytest.approx(0.5 * np.cos(theta) * rate, abs=1e-12)
    # a result read by the names as written: the equilibrium hangs straight down
    eq_s, eq_u = nc.equilibrium(shared), nc.equilibrium(written)
    for name in ("link.r_i.x", "link.r_i.y", "link.u.y"):
        assert eq_s.coordinate(name) == pytest.approx(eq_u.q[written.coordinate_names.index(name)], abs=1e-9)
    assert eq_s.coordinate("link.r_i.y") == pytest.approx(-0.5, abs=1e-9)
    again = nc.System.from_toml(nc.System.from_toml(text).to_toml()).build()
    np.testing.assert_allclose(again.q0, shared.q0, atol=1e-14)


@pytest.mark.parametrize("table, message", [
    ('{"link.r_z.x" = 0.1}', r"initial\.link\.r_z\.x: expected a coordinate link\.SLOT\.AXIS with SLOT one of r_i, u, v"),
    ('{"arm.r_i.x" = 0.1}', r"initial\.arm\.r_i\.x: no member named 'arm'"),
    ('{"link.r_i.y" = "high"}', r"initial\.link\.r_i\.y"),
    ('{"link.r_i.y" = 0.7}', r"initial coordinates link\.r_i\.y = 0\.7, link\.r_i\.x = 0: assembly failed"),
])
def test_toml_initial_coordinates_are_checked(table, message):
    text = PENDULUM_TOML.format(y=0, xd=0).replace('initial = {"link.r_i.y" = 0}', "initial = " + table)
    with pytest.raises(nc.ModelError, match=message):
        nc.System.from_toml(text).build()


def welded():
    s = nc.System("weld")
    a = s.add_body("a", mass=1.0, inertia=np.diag([0.01, 0.02, 0.02]), position=(0.5, 0, 0))
    b = s.add_body("b", mass=0.5, inertia=np.diag([0.01, 0.02, 0.02]), position=(1.2, 0, 0.1))
    b.add_marker("tip", (0.2, 0, 0))
    s.add_joint(nc.Revolute(s.ground, a, at=(0, 0, 0), axis=(0, 1, 0), name="hinge"))
    s.add_joint(nc.Fixed(a, b, at=(1.0, 0, 0), name="weld"))
    return s


def test_members_markers_and_coordinates_of_merged_bodies_keep_their_names():
    """A weld merges two bodies into one set of coordinates (24 -> 6): both members, their
    markers and their coordinates as written still read as in the share=False run."""
    shared, written = welded().build(), welded().build(share=False)
    assert shared.sharing.eliminated["weld"] == "merged" and (shared.nq, written.nq) == (6, 24)
    assert shared.member_names == written.member_names and shared.marker_names == ["b.tip"]
    a = nc.simulate(shared, 0.5, 0.1, method="idas", rtol=1e-10, atol=1e-12)
    b = nc.simulate(written, 0.5, 0.1, method="idas", rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(a.marker("b.tip"), b.marker("b.tip"), atol=1e-8)
    np.testing.assert_allclose(a.point("b", (0.1, 0, 0)), b.point("b", (0.1, 0, 0)), atol=1e-8)
    for name in ("b.r_i.x", "b.u.z", "a.w.y", "a.r_i.z"):
        x, xd = a.coordinate(name)
        i = written.coordinate_names.index(name)
        np.testing.assert_allclose(x, b.q[:, i], atol=1e-8)
        np.testing.assert_allclose(xd, b.v[:, i], atol=1e-7)
    # the tip swings on a circle about the hinge axis (y) through the origin
    tip = a.marker("b.tip")
    radius = np.hypot(tip[:, 0], tip[:, 2])
    np.testing.assert_allclose(radius, radius[0], atol=1e-8)


def test_problem_files_take_rebased_names_and_mpc_says_what_it_cannot_take():
    from ncgen.control.mpc_problem import mpc_problem
    from ncgen.optim.problem_file import problem_from_data
    model = pendulum().build()
    data = {"horizon": {"N": 4, "t_final": 1.0},
            "bounds": {"coordinates": {"link.r_i.y": [-0.6, 0.26]}, "velocities": {"link.r_i.x": [-1, 1]}},
            "final": {"q": {"link.r_i.y": 0.25}}}
    ocp, _ = problem_from_data(data, model, "p.toml")
    kinds = [(kind, name) for kind, name, *_ in ocp.row_bounds]
    assert kinds == [("coordinate", "link.r_i.y"), ("velocity of", "link.r_i.x")]
    s, c = model.coordinate("link.r_i.y")
    assert np.allclose(ocp.row_bounds[0][2], s) and ocp.row_bounds[0][3:] == (c, -0.6, 0.26)
    with pytest.raises(OptimizationError, match=r"bounds on coordinates as written that coordinate sharing "
                                                r"re-based \(not a box on the state\)"):
        mpc_problem(ocp, 1e3)
