"""ncgen.viz: PNG summaries and GIF animations are written (valid headers, frames), matplotlib
is imported only when drawing."""
import subprocess
import sys

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import NcgenError
from ncgen.runtime import Trajectory
from ncgen.viz import animate, plot
from ncgen.viz.scene import scene

PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def spatial():
    """Every kind of member in 3D: a bar pinned to the ground, an rrvw body sharing its end,
    a free point; markers on the bar and the body."""
    s = nc.System("zoo")
    bar = s.add_bar("bar", mass=1.0, ends=[s.ground.point((0, 0, 0)), (0.4, 0.0, -0.3)])
    bar.add_marker("mid", (0.0, 0, 0))
    box = s.add_body("box", "rrvw", mass=2.0, inertia=np.diag([0.02, 0.03, 0.04]), position=(0.5, 0.1, -0.5),
                     share={"r_i": bar.end(1)}, basis=[(-0.1, -0.1, 0.2), (0.1, 0.1, -0.2), (0, 1, 0), (0, 0, 1)])
    box.add_marker("corner", (0.1, 0.1, 0.1))
    s.add_point("pt", mass=0.3, position=(0.0, 0.5, -0.5), velocity=(0.0, 0.0, 3.0))
    return nc.simulate(s.build(), 0.5, 0.05)


@pytest.fixture(scope="module")
def planar():
    s = nc.System("slider", gravity=(0, -9.81))
    crank = s.add_bar("crank", mass=1.0, ends=[s.ground.point((0, 0)), (0.3, 0.2)])
    crank.add_marker("tip", (np.hypot(0.3, 0.2) / 2, 0))
    s.add_bar("rod", mass=0.5, ends=[crank.end(1), (0.9, 0.0)])
    return nc.simulate(s.build(), 0.5, 0.05)


def test_scene_contents(spatial):
    sc = scene(spatial)
    n = len(spatial)
    assert sc.bar_names == ["bar"] and sc.bars.shape == (n, 1, 2, 3)
    np.testing.assert_allclose(sc.bars[0, 0], [[0, 0, 0], [0.4, 0, -0.3]], atol=1e-12)
    assert sc.body_names == ["box"] and sc.body_axes.shape == (n, 1, 3, 3)
    assert sc.body_points.shape == (n, 2, 3)                     # r_i and r_j of the rrvw body
    np.testing.assert_allclose(sc.body_points[:, 0], sc.bars[:, 0, 1], atol=1e-12)
    assert sc.points.shape == (n, 1, 3) and sc.markers.shape == (n, 2, 3)
    np.testing.assert_array_equal(sc.anchors, [[0, 0, 0]])


@pytest.mark.parametrize("which", ["spatial", "planar"])
def test_plot_writes_a_png(tmp_path, request, which):
    traj = request.getfixturevalue(which)
    out = plot(traj, tmp_path / f"{which}.png")
    data = out.read_bytes()
    assert data[:8] == PNG and len(data) > 10_000
    assert [p.name for p in tmp_path.iterdir()] == [f"{which}.png"]


def test_plot_chosen_points(tmp_path, spatial):
    out = plot(spatial, tmp_path / "p.png", points=["box.corner", ("bar", (0.1, 0, 0)), ("pt", (0, 0, 0))])
    assert out.read_bytes()[:8] == PNG
    assert plot(spatial, tmp_path / "p.svg", points=["bar.mid"]).read_text().startswith("<?xml")
    with pytest.raises(NcgenError, match="expected marker names or"):
        plot(spatial, tmp_path / "q.png", points=[3])
    with pytest.raises(NcgenError, match="no marker named"):
        plot(spatial, tmp_path / "q.png", points=["nope"])
    with pytest.raises(NcgenError, match=".png, .pdf, .svg"):
        plot(spatial, tmp_path / "p.jpg")


@pytest.mark.parametrize("which", ["spatial", "planar"])
def test_animate_writes_a_gif(tmp_path, request, which):
    from PIL import Image
    traj = request.getfixturevalue(which)
    out = animate(traj, tmp_path / f"{which}.gif", max_frames=4)
    assert out.read_bytes()[:6] in (b"GIF89a", b"GIF87a")
    with Image.open(out) as im:
        assert im.n_frames >= 2 and im.size == (480, 480)
    assert [p.name for p in tmp_path.iterdir()] == [f"{which}.gif"]


def test_animate_writes_an_mp4_whose_frames_show_the_motion(tmp_path, spatial):
    """The MP4 decodes (through the same ffmpeg) to frames of the drawn size, as many as
    drawn, and its first and last frames differ where the system moved."""
    imageio_ffmpeg = pytest.importorskip("imageio_ffmpeg")
    out = animate(spatial, tmp_path / "spatial.mp4", max_frames=6)
    assert out.read_bytes()[4:8] == b"ftyp"
    reader = imageio_ffmpeg.read_frames(str(out))
    meta = next(reader)
    w, h = meta["size"]
    frames = [np.frombuffer(f, np.uint8).reshape(h, w, 3) for f in reader]
    assert (w, h) == (480, 480) and len(frames) == 6
    changed = np.abs(frames[0].astype(int) - frames[-1].astype(int)).max(axis=2) > 60
    assert 0.001 < changed.mean() < 0.5           # the moving members, not the whole picture
    assert [p.name for p in tmp_path.iterdir()] == ["spatial.mp4"]


def test_animate_errors(tmp_path, spatial, monkeypatch):
    import builtins

    from matplotlib.animation import FFMpegWriter
    with pytest.raises(NcgenError, match=".gif or .mp4"):
        animate(spatial, tmp_path / "a.avi")
    monkeypatch.setattr(FFMpegWriter, "isAvailable", classmethod(lambda cls: False))
    real_import = builtins.__import__
    monkeypatch.setattr(builtins, "__import__", lambda name, *a, **k: (_ for _ in ()).throw(ImportError(name))
                        if name == "imageio_ffmpeg" else real_import(name, *a, **k))
    with pytest.raises(NcgenError, match="ncgen\\[viz\\]"):
        animate(spatial, tmp_path / "a.mp4")
    monkeypatch.undo()
    assert not (tmp_path / "a.mp4").exists()
    loaded = Trajectory.load(spatial.save(tmp_path / "t.npz"))
    with pytest.raises(NcgenError, match="needs its model"):
        animate(loaded, tmp_path / "a.gif")
    assert plot(loaded, tmp_path / "loaded.png").is_file()       # plots need no model


def test_import_ncgen_does_not_import_matplotlib():
    code = "import sys, ncgen, ncgen.viz; print('matplotlib' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


# ------------------------------------------------------------------ shapes in matplotlib
@pytest.fixture(scope="module")
def sprung():
    """A bar on a ball joint, a box-shaped body hung from it by a spring, a slack cable."""
    s = nc.System("sprung")
    bar = s.add_bar("bar", mass=1.0, ends=[(0.0, 0.0, 0.0), (0.5, 0.0, 0.0)])
    s.add_joint(nc.Spherical(s.ground, bar, at=(0.0, 0.0, 0.0)))
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    box = s.add_body("box", mass=1.0, inertia=np.diag([0.01, 0.02, 0.03]), position=(0.5, 0.0, -0.4), rotation=R,
                     shape=nc.Box(0.2, 0.1, 0.05))
    s.add_force(nc.Spring(bar, (0.25, 0.0, 0.0), box, (0.0, 0.0, 0.0), k=200.0, rest_length=0.3))
    s.add_force(nc.Spring(s.ground, (0.0, 0.0, -0.2), box, (0.0, 0.0, 0.0), k=50.0, rest_length=2.0, cable=True))
    return nc.simulate(s.build(), 0.3, 0.01)


def test_animation_frames_draw_the_shapes_where_the_members_are(sprung):
    from ncgen.viz.draw import SceneArtists, figure, scene_axes

    sc = scene(sprung)
    fig = figure(4, 4)
    artists = SceneArtists(scene_axes(fig, sc), sc)
    k = 20
    artists.show(k, float(sprung.t[k]))
    data = lambda line: np.column_stack(line.get_data_3d())        # noqa: E731
    L = 0.5
    ends = np.array([sprung.point("bar", (-L / 2, 0, 0))[k], sprung.point("bar", (L / 2, 0, 0))[k]])
    np.testing.assert_allclose(data(artists.bars[0]), ends, atol=1e-12)            # a thick segment end to end
    i_box = sprung.member_names.index("box")
    box_lines = [data(line) for i, _, line in artists.outlines if i == i_box]
    assert box_lines, "the box body has no outline"
    pts = box_lines[0][~np.isnan(box_lines[0]).any(axis=1)]
    corners = np.array([sprung.point("box", (sx * 0.1, sy * 0.05, sz * 0.025))[k]
                        for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    np.testing.assert_allclose(pts.min(axis=0), corners.min(axis=0), atol=1e-12)  # its bounding box
    np.testing.assert_allclose(pts.max(axis=0), corners.max(axis=0), atol=1e-12)
    coil, cable = (data(line) for line in artists.springs)
    np.testing.assert_allclose(coil[[0, -1]], [sprung.point("bar", (0.25, 0, 0))[k], sprung.point("box", (0, 0, 0))[k]],
                               atol=1e-12)
    assert len(coil) > 50 and np.max(np.linalg.norm(np.diff(coil, axis=0), axis=1)) < 0.2   # a coil, not a line
    np.testing.assert_allclose(cable, [[0.0, 0.0, -0.2], sprung.point("box", (0, 0, 0))[k]], atol=1e-12)
    assert artists.springs[1].get_linestyle() == "--", "a slack cable is drawn dashed"


def test_animation_fits_its_time_budget_and_shows_progress(sprung, tmp_path, capsys):
    from PIL import Image

    from ncgen.viz.animation import MIN_FRAMES

    animate(sprung, tmp_path / "all.gif", budget=None, progress=False)
    assert Image.open(tmp_path / "all.gif").n_frames == len(sprung)
    animate(sprung, tmp_path / "few.gif", budget=1e-6, progress=True)
    assert Image.open(tmp_path / "few.gif").n_frames == MIN_FRAMES
    assert "animation:" in capsys.readouterr().err          # the tqdm bar (ncgen.progress)


def test_summary_has_no_empty_panel_and_states_small_units():
    from ncgen.viz.summary_plot import summary_figure, unit_scale

    s = nc.System("arm")                                  # joints, no markers: joint positions and a path
    a = s.add_body("a", mass=1.0, inertia=np.diag([0.01, 0.01, 0.002]), position=(0.0, 0.0, -0.2))
    b = s.add_body("b", mass=1.0, inertia=np.diag([0.01, 0.01, 0.002]), position=(0.0, 0.2, -0.4))
    s.add_joint(nc.Revolute(s.ground, a, at=(0.0, 0.0, 0.0), axis=(1.0, 0.0, 0.0)))
    s.add_joint(nc.Revolute(a, b, at=(0.0, 0.0, -0.4), axis=(1.0, 0.0, 0.0)))
    traj = nc.simulate(s.build(), 0.5, 0.01)
    fig = summary_figure(traj)
    for ax in fig.axes:
        assert ax.lines or ax.collections, f"empty panel {ax.get_title()!r}"
    assert fig.axes[2].get_title() == "joint positions" and len(fig.axes[2].lines) == 2
    assert "(rad or m)" in fig.axes[2].get_ylabel()
    assert unit_scale(np.array([3e-7, -1e-7]), "J") == (1e-7, "1e-07 J")
    assert unit_scale(np.array([0.5, 20.0]), "J") == (1.0, "J")


def test_a_tiny_wobble_is_drawn_flat(tmp_path):
    from ncgen.viz.summary_plot import summary_figure

    s = nc.System("circle")                            # a point on a horizontal circle: z constant to round-off
    p = s.add_point("p", mass=1.0, position=(0.1, 0.0, 0.0), velocity=(0.0, 0.5, 0.0))
    s.add_joint(nc.Distance(s.ground, p, at=[(0.0, 0.0, 0.0), (0.1, 0.0, 0.0)]))
    s.add_force(nc.PointForce(p, (0.0, 0.0, 0.0), force=(0.0, 0.0, 9.81)))
    p.add_marker("m", (0.0, 0.0, 0.0))
    traj = nc.simulate(s.build(), 1.0, 0.01)
    fig = summary_figure(traj)
    path = fig.axes[3]
    spans = [np.ptp(lim) for lim in (path.get_xlim(), path.get_ylim(), path.get_zlim())]
    np.testing.assert_allclose(spans, spans[0], rtol=1e-12)          # equal scales: the circle's z range is flat
    assert not path.zaxis.get_major_formatter().get_offset()
