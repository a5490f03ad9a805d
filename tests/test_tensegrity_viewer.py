"""Cables in the viewer: a clustered cable is drawn segment by segment with its one tension
(matplotlib colours and the HTML page's data), and statics reports it; checked against the
closed-form tension of a weight hung in a V of one cable (``2 T sin θ = m g``)."""
import numpy as np
import pytest

import ncgen as nc
from ncgen.viz import html
from ncgen.viz.scene import scene, tension_rgb

G, M, K = 9.81, 2.0, 1e4
SIN = 0.8                                   # anchors at (±0.3, 0, 0.4): segments of 0.5 m


def v_cable(stretch: float = 0.0):
    """A point of mass M on a vertical line, hung from two ground pulleys by one cable whose
    rest length gives the closed-form tension ``M g / (2 sin θ)`` (plus ``K stretch``)."""
    s = nc.System("vcable", gravity=(0, 0, -G))
    p = s.add_point("w", mass=M, position=(0, 0, 0))
    s.add_joint(nc.PointOnLine(s.ground, p, at=(0, 0, 0), axis=(0, 0, 1)))
    T = M * G / (2 * SIN)
    s.add_force(nc.ClusteredCable([(s.ground, (-0.3, 0, 0.4)), (p, (0, 0, 0)), (s.ground, (0.3, 0, 0.4))],
                                  k=K, rest_length=1.0 - T / K - stretch, name="rope"))
    s.add_force(nc.Spring(s.ground, (0, 0, 0.5), p, (0, 0, 0), k=1.0, rest_length=2.0, cable=True, name="loose"))
    return s


def test_statics_reports_the_clustered_cable_tension():
    eq = nc.equilibrium(v_cable().build())
    T = {name: (t, length, slack) for name, t, length, slack in eq.springs}
    assert T["rope"][0] == pytest.approx(M * G / (2 * SIN), rel=1e-9)
    assert T["rope"][1] == pytest.approx(1.0, abs=1e-9) and not T["rope"][2]
    assert T["loose"][2] and eq.slack == ["loose"]


@pytest.fixture(scope="module")
def swinging():
    return nc.simulate(v_cable(stretch=0.0005).build(), t_end=0.1, dt=0.005, backend="vm")


def test_scene_draws_each_segment_with_the_cable_tension(swinging):
    sc = scene(swinging)
    assert sc.spring_names == ["rope", "loose"]
    assert list(sc.spring_owner) == [0, 0, 1] and sc.spring_cable.all()
    w = swinging.point("w", (0, 0, 0))
    a, b = np.array([-0.3, 0, 0.4]), np.array([0.3, 0, 0.4])
    np.testing.assert_allclose(sc.spring_ends[:, 0, 0], np.broadcast_to(a, w.shape))
    np.testing.assert_allclose(sc.spring_ends[:, 0, 1], w, atol=1e-12)
    np.testing.assert_allclose(sc.spring_ends[:, 1, 1], np.broadcast_to(b, w.shape))
    L = np.linalg.norm(w - a, axis=1) + np.linalg.norm(w - b, axis=1)
    T = K * (L - (1.0 - M * G / (2 * SIN) / K - 0.0005))
    np.testing.assert_allclose(sc.spring_tension[:, 0], T, rtol=1e-9)
    np.testing.assert_allclose(sc.spring_tension[:, 1], T, rtol=1e-9)
    assert np.ptp(T) > 1.0, "the stretched cable oscillates: the colours must follow its tension"
    assert not sc.spring_slack[:, :2].any() and sc.spring_slack[:, 2].all()
    assert sc.tension_scale() == pytest.approx(T.max())


def test_matplotlib_colours_cables_by_tension(swinging):
    from ncgen.viz.draw import SLACK_COLOR, SceneArtists, figure, scene_axes

    sc = scene(swinging)
    artists = SceneArtists(scene_axes(figure(4, 4), sc), sc)
    for k in (0, len(swinging) - 1):
        artists.show(k, float(swinging.t[k]))
        for j in (0, 1):
            np.testing.assert_allclose(artists.springs[j].get_color(),
                                       tension_rgb(sc.spring_tension[k, j], sc.tension_scale()))
        assert artists.springs[2].get_color() == SLACK_COLOR
    low = int(np.argmin(sc.spring_tension[:, 0]))
    artists.show(low, float(swinging.t[low]))
    assert not np.allclose(artists.springs[0].get_color(), tension_rgb(sc.spring_tension.max(), sc.tension_scale()))


def test_html_page_carries_segments_tensions_and_a_tension_panel(swinging, tmp_path):
    data = html.page_data(swinging)
    assert [s["name"] for s in data["springs"]] == ["rope", "rope", "loose"]
    assert all("tension" in s for s in data["springs"]) and data["tension_scale"] > 0
    panel = [p for p in data["plots"] if p["title"] == "spring and cable tensions"]
    assert panel and [s["label"] for s in panel[0]["series"]] == ["rope", "loose"]
    page = swinging.to_html(tmp_path / "v.html")
    assert "tension_scale" in page.read_text()


@pytest.mark.slow      # headless Chromium: 10-30 s on a loaded machine
def test_html_page_with_a_clustered_cable_runs_without_console_errors(swinging, tmp_path):
    from test_viz_html import CHROMIUM, report

    if CHROMIUM is None:
        pytest.skip("chromium is not installed")
    page = swinging.to_html(tmp_path / "vcable.html")
    _, console = report(page, 0.05, tmp_path)
    assert console == []
