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


def test_animate_errors(tmp_path, spatial):
    from matplotlib.animation import FFMpegWriter
    with pytest.raises(NcgenError, match=".gif or .mp4"):
        animate(spatial, tmp_path / "a.avi")
    if not FFMpegWriter.isAvailable():
        with pytest.raises(NcgenError, match="ffmpeg"):
            animate(spatial, tmp_path / "a.mp4")
    loaded = Trajectory.load(spatial.save(tmp_path / "t.npz"))
    with pytest.raises(NcgenError, match="needs its model"):
        animate(loaded, tmp_path / "a.gif")
    assert plot(loaded, tmp_path / "loaded.png").is_file()       # plots need no model


def test_import_ncgen_does_not_import_matplotlib():
    code = "import sys, ncgen, ncgen.viz; print('matplotlib' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
