"""A capstan cable in the viewer and the spring table: its two sides drawn segment by segment
(side a weight → drum, side b drum → pulley → hand), each with its own tension, the material
point not drawn.  The rig is examples/capstan_lift.py slipping up (θ = π, F = 30 N); the
tensions are recomputed here in NumPy from the trajectory's coordinates and rates
(``T = EA (l − s)/s + c (l̇ ∓ ṡ)``, ncgen/model/capstan.py) and, while slipping, obey the
capstan law ``T_b = e^{μθ} T_a`` (up to the strain terms and the material's inertia, < 1 %)."""
import importlib.util
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.viz import geometry, html
from ncgen.viz.scene import scene, tension_rgb

MU, EA, C, FORCE = 0.3, 1e5, 20.0, 30.0
DRUM, PULLEY = np.array([-0.1, 0, 1.0]), np.array([0.1, 0, 1.0])
_spec = importlib.util.spec_from_file_location("capstan_lift", Path(__file__).resolve().parent.parent
                                               / "examples" / "capstan_lift.py")
example = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(example)


@pytest.fixture(scope="module")
def lifting():
    model = example.capstan_lift(FORCE, np.pi, mu=MU, ea=EA, damping=C).build()
    return nc.simulate(model, t_end=0.1, dt=0.005, backend="vm")


def numpy_tensions(traj):
    """``(T_a, T_b)`` per frame from the trajectory's coordinates (module docstring)."""
    rope = next(f for f in traj.model.forces if f.kind == "CapstanCable")
    r = {n: np.stack([traj.coordinate(f"{n}.r_i.{x}")[0] for x in "xyz"], axis=1) for n in ("weight", "hand")}
    v = {n: np.stack([traj.coordinate(f"{n}.r_i.{x}")[1] for x in "xyz"], axis=1) for n in ("weight", "hand")}
    rm = np.stack([traj.coordinate(f"rope_material.r_i.{x}")[0] for x in "xyz"], axis=1)
    vm = np.stack([traj.coordinate(f"rope_material.r_i.{x}")[1] for x in "xyz"], axis=1)
    e = np.asarray(rope.axis, float)
    s0, total = rope.rest_lengths[0], sum(rope.rest_lengths)
    s, slip = s0 + (rm - DRUM) @ e, vm @ e
    da, dh = DRUM - r["weight"], r["hand"] - PULLEY
    l_a, l_b = np.linalg.norm(da, axis=1), np.linalg.norm(PULLEY - DRUM) + np.linalg.norm(dh, axis=1)
    rate_a = -np.sum(da * v["weight"], axis=1) / l_a
    rate_b = np.sum(dh * v["hand"], axis=1) / np.linalg.norm(dh, axis=1)
    t_a = EA * (l_a - s) / s + C * (rate_a - slip)
    t_b = EA * (l_b - total + s) / (total - s) + C * (rate_b + slip)
    return np.maximum(t_a, 0), np.maximum(t_b, 0)


def test_spring_table_has_the_two_sides(lifting):
    table = lifting.model.springs
    assert table.names == ("rope.a", "rope.b") and table.cable == (True, True) and table.segments == (1, 2)


def test_scene_draws_both_sides_with_their_tensions(lifting):
    sc = scene(lifting)
    assert sc.spring_names == ["rope.a", "rope.b"] and list(sc.spring_owner) == [0, 1, 1]
    w, h = lifting.point("weight", (0, 0, 0)), lifting.point("hand", (0, 0, 0))
    np.testing.assert_allclose(sc.spring_ends[:, 0, 0], w, atol=1e-12)
    np.testing.assert_allclose(sc.spring_ends[:, 0, 1], np.broadcast_to(DRUM, w.shape))
    np.testing.assert_allclose(sc.spring_ends[:, 1, 0], np.broadcast_to(DRUM, w.shape))
    np.testing.assert_allclose(sc.spring_ends[:, 1, 1], np.broadcast_to(PULLEY, w.shape))
    np.testing.assert_allclose(sc.spring_ends[:, 2, 1], h, atol=1e-12)
    t_a, t_b = numpy_tensions(lifting)
    np.testing.assert_allclose(sc.spring_tension[:, 0], t_a, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(sc.spring_tension[:, 1], t_b, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(sc.spring_tension[:, 2], t_b, rtol=1e-9, atol=1e-9)
    late = lifting.t >= 0.05                                     # slipping: the capstan law
    np.testing.assert_allclose(t_b[late] / t_a[late], np.exp(MU * np.pi), rtol=0.01)
    assert not sc.spring_slack.any() and sc.tension_scale() == pytest.approx(t_b.max())


def test_the_material_point_is_not_drawn(lifting):
    sc = scene(lifting)
    assert sc.points.shape[1] == 2                               # weight and hand only
    prims = geometry.member_primitives(lifting.model, 1.0)
    assert prims["rope_material"] == [] and prims["weight"] != []


def test_matplotlib_colours_each_side_by_its_tension(lifting):
    from ncgen.viz.draw import SceneArtists, figure, scene_axes

    sc = scene(lifting)
    artists = SceneArtists(scene_axes(figure(4, 4), sc), sc)
    k = len(lifting) - 1
    artists.show(k, float(lifting.t[k]))
    for j in range(3):
        np.testing.assert_allclose(artists.springs[j].get_color(),
                                   tension_rgb(sc.spring_tension[k, j], sc.tension_scale()))
    assert not np.allclose(artists.springs[0].get_color(), artists.springs[1].get_color())


def test_html_page_carries_the_sides(lifting, tmp_path):
    data = html.page_data(lifting)
    assert [s["name"] for s in data["springs"]] == ["rope.a", "rope.b", "rope.b"]
    panel = [p for p in data["plots"] if p["title"] == "spring and cable tensions"]
    assert panel and [s["label"] for s in panel[0]["series"]] == ["rope.a", "rope.b"]
    assert "rope.b" in lifting.to_html(tmp_path / "capstan.html").read_text()


def test_table_pulls_and_their_derivatives(lifting):
    """``model.springs``' pulls at a perturbed state: the NumPy formula, and their Jacobian in
    ``(q, v)`` against central differences (what ``min_tension`` and IPOPT use)."""
    import casadi as ca

    model = lifting.model
    rng = np.random.default_rng(41)
    q = lifting.q[-1] + 1e-3 * rng.normal(size=model.nq)
    v = lifting.v[-1] + 0.1 * rng.normal(size=model.nq)
    f = model.springs.function
    pulls = lambda x, y: np.asarray(f(0.0, x, y, np.zeros(model.nu), model.p0)[2]).reshape(-1)
    one = nc.Trajectory.from_states(model, np.zeros(1), q[None], v[None], np.zeros((1, model.nc)),
                                    np.zeros((1, model.nu)), model.p0, {})
    t_a, t_b = numpy_tensions(one)
    np.testing.assert_allclose(np.maximum(pulls(q, v), 0), [t_a[0], t_b[0]], rtol=1e-10)
    Q, V = ca.SX.sym("q", model.nq), ca.SX.sym("v", model.nq)
    P = f(0.0, Q, V, np.zeros(model.nu), model.p0)[2]
    J = np.asarray(ca.Function("J", [Q, V], [ca.jacobian(P, ca.vertcat(Q, V))])(q, v))
    z, eps = np.concatenate([q, v]), 1e-6
    fd = np.column_stack([(pulls(*np.split(z + eps * e, 2)) - pulls(*np.split(z - eps * e, 2))) / (2 * eps)
                          for e in np.eye(2 * model.nq)])
    np.testing.assert_allclose(J, fd, rtol=1e-6, atol=1e-4)
