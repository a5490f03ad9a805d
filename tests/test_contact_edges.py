"""Edges of boxes crossing edges (``nc.BoxBox``'s edge contacts): gaps against hand geometry
and an independent nearest-point search, contact Jacobians against finite differences, and
the nonsmooth stepper on boxes crossed at 45° (they rest on their edges instead of passing
through each other)."""
import warnings

import numpy as np
import pytest
from scipy.optimize import minimize

import ncgen as nc

QUICK_COMPILE = True             # its time is gcc compiling its scenes: -O0 (tests/conftest.py)

G = 9.81


def R_x(b):
    return np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])


def R_y(b):
    return np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])


def R_z(b):
    return np.array([[np.cos(b), -np.sin(b), 0], [np.sin(b), np.cos(b), 0], [0, 0, 1]])


def box_inertia(m, size):
    a, b, c = size
    return m / 12 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])


def box_box_distance(ca, Ra, ha, cb, Rb, hb):
    """Distance (m) between two solid boxes, by an independent search: the closest pair of
    points minimised over both boxes' local coordinates (a convex problem), from several starts."""
    def f(x):
        return np.sum((ca + Ra @ x[:3] - cb - Rb @ x[3:]) ** 2)
    bounds = [(-h, h) for h in ha] + [(-h, h) for h in hb]
    best = min((minimize(f, x0, method="L-BFGS-B", bounds=bounds, options={"ftol": 1e-16, "gtol": 1e-13})
                for x0 in (np.zeros(6), np.r_[ha, -hb] * 0.5, np.r_[-ha, hb] * 0.5)), key=lambda r: r.fun)
    return np.sqrt(best.fun)


def edge_rows(model, element):
    return [i for i, n in enumerate(model.contact_names) if n.startswith(f"{element}.edge")]


def tangent_fd(model, q):
    eps = 1e-7
    _, sv, Vt = np.linalg.svd(model.A(q))
    T = Vt[np.sum(sv > 1e-10):].T
    dg = np.array([(model.gap(q + eps * e) - model.gap(q - eps * e)) / (2 * eps) for e in T.T]).T
    return model.contact_jacobian(q)[0] @ T, dg


BEAM = np.array([0.6, 0.08, 0.08])                  # long along x, square section


def crossed_beams(angle, lift):
    """A beam on the ground rolled by 0.6 rad about its long axis (an edge on top) and a beam
    above it rolled by 0.9 rad about its own (an edge below), crossed at ``angle`` about the
    vertical, their edges ``lift`` (m) apart at the crossing."""
    s = nc.System("beams")
    reach = [BEAM[1] / 2 * (abs(np.sin(r)) + abs(np.cos(r))) for r in (0.6, 0.9)]  # centre to the edge
    top_rot = R_z(angle) @ R_x(0.9)
    top = s.add_body("top", mass=1.0, inertia=box_inertia(1.0, BEAM), rotation=top_rot,
                     position=(0.05, -0.03, sum(reach) + lift), velocity=(0.2, -0.1, 0.3), angular_velocity=(1, 2, -1))
    s.add_contact(nc.BoxBox(s.ground, BEAM, top, BEAM, at_a=(0.05, -0.03, 0), rotation_a=R_x(0.6), name="cross",
                            edges=True))
    return s.build(contacts="smooth"), top_rot, sum(reach)     # smooth: starts inside allowed


# one angle in the fast tier (a model built per case, 30 s each on 2 loaded cores), the others slow: the same rows
@pytest.mark.parametrize("angle", [pytest.param(np.pi / 2, marks=pytest.mark.slow), 0.7,
                                   pytest.param(2.2, marks=pytest.mark.slow)])
@pytest.mark.parametrize("lift", [0.01, -5e-4])   # inside: less than the margin, 0.8 mm
def test_crossed_beams_touch_at_their_edges(angle, lift):
    """The smallest edge gap is the distance between the two edges along their common normal
    (hand geometry: ``lift``), the brute-force distance between the beams where apart; no
    corner is in contact; W_N = ∂g/∂q wherever the edge contacts hold."""
    model, top_rot, height = crossed_beams(angle, lift)
    g = model.gap(model.q0)
    edges = edge_rows(model, "cross")
    assert len(edges) == 36
    np.testing.assert_allclose(g[edges].min(), lift, atol=1e-12)
    assert np.sort(g[edges])[1] > 0.02                # one crossing: the others are far or off their edges
    corners = [i for i, n in enumerate(model.contact_names) if "corner" in n]
    assert g[corners].min() > 0.01
    if lift > 0:
        d = box_box_distance(np.array([0.05, -0.03, 0]), R_x(0.6), BEAM / 2,
                             np.array([0.05, -0.03, height + lift]), top_rot, BEAM / 2)
        np.testing.assert_allclose(d, lift, atol=1e-7)
    WN_T, dg = tangent_fd(model, model.q0)
    held = [k for k in edges if g[k] < 1.0]
    np.testing.assert_allclose(WN_T[held], dg[held], atol=1e-7)
    WN = model.contact_jacobian(model.q0)[0]
    k = edges[int(np.argmin(g[edges]))]
    np.testing.assert_allclose(WN[k, 0:3], [0, 0, 1], atol=1e-12)     # the upper beam's centre lifts the gap


@pytest.mark.slow      # 16 models built; fast: test_crossed_beams_touch_at_their_edges[0.01-0.7] (the edge gap equals
#                         the brute-force distance between boxes apart)
def test_edge_gaps_never_report_contact_between_boxes_apart():
    """Random poses of two boxes: wherever the boxes are apart (brute-force distance > 0),
    every edge gap is at least that distance (no contact while apart), and equals it where
    the closest points are on two edges."""
    rng = np.random.default_rng(3)
    size_a, size_b = np.array([0.3, 0.2, 0.1]), np.array([0.25, 0.15, 0.2])
    checked = exact = 0
    for _ in range(16):
        Ra = R_z(rng.uniform(-3, 3)) @ R_y(rng.uniform(-3, 3)) @ R_x(rng.uniform(-3, 3))
        Rb = R_z(rng.uniform(-3, 3)) @ R_y(rng.uniform(-3, 3)) @ R_x(rng.uniform(-3, 3))
        cb = rng.normal(size=3)
        cb *= rng.uniform(0.2, 0.35) / np.linalg.norm(cb)
        d = box_box_distance(np.zeros(3), Ra, size_a / 2, cb, Rb, size_b / 2)
        if d < 1e-4:
            continue
        s = nc.System("apart")
        a = s.add_body("a", mass=1.0, inertia=box_inertia(1.0, size_a), rotation=Ra, position=(0, 0, 0))
        b = s.add_body("b", mass=1.0, inertia=box_inertia(1.0, size_b), rotation=Rb, position=cb)
        s.add_contact(nc.BoxBox(a, size_a, b, size_b, name="ab", edges=True))
        model = s.build(contacts="nonsmooth")        # refuses any gap below 0: none while apart
        g = model.gap(model.q0)[edge_rows(model, "ab")]
        assert g.min() >= d - 1e-9, (g.min(), d)
        checked += 1
        exact += bool(np.isclose(g.min(), d, atol=1e-9))
    assert checked >= 6 and exact >= 1, (checked, exact)


CUBE = np.array([0.2, 0.2, 0.2])


def cubes_at_45(drop, mu):
    s = nc.System("cubes45")
    lower = s.add_body("lower", mass=2.0, inertia=box_inertia(2.0, CUBE), position=(0, 0, CUBE[2] / 2))
    upper = s.add_body("upper", mass=1.0, inertia=box_inertia(1.0, CUBE), rotation=R_z(np.pi / 4),
                       position=(0, 0, 1.5 * CUBE[2] + drop))
    s.add_contact(nc.BoxPlane(lower, size=CUBE, mu=mu, name="floor"))
    s.add_contact(nc.BoxBox(upper, CUBE, lower, CUBE, mu=mu, name="stack", edges=True))
    return s.build(contacts="nonsmooth")


# slow: 86 s each on 2 loaded cores; fast: test_crossed_beams_touch_at_their_edges (the edge rows, gaps and W_N,
# that the step reads) and tests/c/test_contact.c (the contact step on hand-made rows)
@pytest.mark.slow
@pytest.mark.parametrize("drop,mu", [(0.0, 0.0), (0.01, 0.0), (0.01, 0.5)])
def test_equal_cubes_crossed_at_45_degrees_rest_on_their_edges(drop, mu):
    """An equal cube turned 45° about the vertical, set on (or dropped from 1 cm onto) a cube
    on the floor: no corner of either is over the other's face, so only the eight crossings
    of their edges can hold it.  It comes to rest at the height 1.5 × edge, the crossings
    carrying its weight (1e-9), the corners nothing; the floor the weight of both."""
    model = cubes_at_45(drop, mu)
    edges = edge_rows(model, "stack")
    g = model.gap(model.q0)
    np.testing.assert_allclose(np.sort(g[edges])[:8], drop, atol=1e-12)   # the eight crossings
    assert np.sort(g[edges])[8] > 0.05
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tr = nc.simulate(model, 1.0, 0.01, method="stepper", substeps=10)
    rest = tr.t > (0.2 if drop else 0.0)
    x = tr.point("upper", (0, 0, 0))
    np.testing.assert_allclose(x[rest, 2], 1.5 * CUBE[2], atol=1e-8)
    # sideways: the friction impulses of the landing, shared among eight redundant crossings
    # by the solver, shift it by ~8e-6 m (none without friction)
    assert np.abs(x[rest, :2]).max() < (1e-4 if mu else 1e-9)
    # then at rest, but for the friction solve's creep (1.7e-8 m over 0.7 s measured; the
    # solver's, as with a box on a box face: docs/contact.md)
    assert np.ptp(x[rest][10:, :2], axis=0).max() < 1e-7
    f = tr.contact_normal
    rest = rest & (tr.t > 0.005)
    # with friction after the landing the normal forces exceed the weight by 4e-7 of it
    # (measured; no tilt, 1e-16 rad): the friction solve's, not the geometry's
    rtol = 1e-9 if mu == 0 else 1e-6
    np.testing.assert_allclose(f[rest][:, edges].sum(axis=1), 1.0 * G, rtol=rtol)
    corners = [i for i, n in enumerate(tr.contact_names) if n.startswith("stack.") and "corner" in n]
    assert np.all(f[rest][:, corners] == 0)
    floor = [i for i, n in enumerate(tr.contact_names) if n.startswith("floor.")]
    np.testing.assert_allclose(f[rest][:, floor].sum(axis=1), 3.0 * G, rtol=rtol)
    assert tr.gap[:, edges].min() > -1e-8


@pytest.mark.slow      # two box-box scenes compiled; fast: test_crossed_beams_touch_at_their_edges (edge contacts on)
def test_edges_are_off_by_default_and_round_trip_through_toml():
    s = nc.System("flags")
    a = s.add_body("a", mass=1.0, inertia=box_inertia(1.0, CUBE), position=(0, 0, 0.1))
    b = s.add_body("b", mass=1.0, inertia=box_inertia(1.0, CUBE), position=(0, 0, 0.4), rotation=R_z(0.3))
    s.add_contact(nc.BoxBox(b, CUBE, a, CUBE, name="plain"))
    s.add_contact(nc.BoxBox(b, CUBE, a, CUBE, name="full", edges=True))
    model = s.build(contacts="smooth")
    assert sum(n.startswith("plain.") for n in model.contact_names) == 16
    assert sum(n.startswith("full.edge") for n in model.contact_names) == 36
    text = s.to_toml()
    assert text.count("edges = true") == 1
    assert nc.System.from_toml(text).build(contacts="smooth").contacts == model.contacts
    with pytest.raises(nc.ModelError, match=r"'bad' \(BoxBox\): edges: expected true or false, got 1"):
        s.add_contact(nc.BoxBox(b, CUBE, a, CUBE, name="bad", edges=1))
    flat = nc.System("flat", gravity=(0, -G))
    p = flat.add_body("p", coords="ruv", mass=1.0, inertia=0.01, position=(0, 1))
    with pytest.raises(nc.ModelError, match=r"edge crossings need a 3D system"):
        flat.add_contact(nc.BoxBox(p, (1, 1), flat.ground, (1, 1), name="bb", edges=True))
