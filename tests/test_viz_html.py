"""The offline HTML page (ncgen.viz.html): opened in headless Chromium without a network, the
bodies are drawn where the simulation puts them (pixels against positions projected in
Python with the page's camera), the drawn parts have the bounding boxes of their shapes,
nothing is logged to the console; shapes are validated; URDF meshes load."""
from __future__ import annotations

import base64
import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.viz import geometry, html

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
needs_chromium = pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (Debian package "
                                    "'chromium'; .ci/run installs it): the HTML page is not opened")
WINDOW = (900, 600)
#: Console lines that are the software renderer's, not the page's.
DRIVER_NOISE = ("GL Driver Message",)


def chromium(url: str, tmp_path: Path, *args: str) -> tuple[str, list[str]]:
    """Run headless Chromium on ``url`` with no network; ``(stdout, console lines)``."""
    profile = tmp_path / f"profile{len(list(tmp_path.glob('profile*')))}"
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader",
           "--use-angle=swiftshader", "--disable-background-networking", "--disable-component-update",
           "--no-first-run", "--disable-sync", "--host-resolver-rules=MAP * ~NOTFOUND",
           f"--user-data-dir={profile}", "--enable-logging=stderr", "--v=0", f"--window-size={WINDOW[0]},{WINDOW[1]}",
           "--hide-scrollbars", "--virtual-time-budget=10000", *args, url]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=180)
    console = [line for line in run.stderr.splitlines()
               if ":CONSOLE" in line and not any(n in line for n in DRIVER_NOISE)]
    return run.stdout, console


def screenshot(page: Path, t: float, tmp_path: Path) -> tuple[np.ndarray, list[str]]:
    from PIL import Image

    png = tmp_path / f"shot_{t:g}.png"
    _, console = chromium(f"{page.as_uri()}?t={t}", tmp_path, f"--screenshot={png}")
    return np.asarray(Image.open(png).convert("RGB")).astype(int), console


def report(page: Path, t: float, tmp_path: Path) -> tuple[dict, list[str]]:
    dom, console = chromium(f"{page.as_uri()}?t={t}&report=1", tmp_path, "--dump-dom")
    found = re.search(r'<pre id="report"[^>]*>([^<]+)</pre>', dom)
    assert found, "the page wrote no report: it did not run (see the console lines)\n" + "\n".join(console)
    return json.loads(found.group(1)), console


@needs_chromium
def test_console_capture_sees_page_errors(tmp_path):
    """The console check of the tests above can fail: an error and an exception are seen."""
    page = tmp_path / "bad.html"
    page.write_text('<!doctype html><link rel="icon" href="data:,"><script>console.error("boom");'
                    'null.x;</script>', encoding="utf-8")
    _, console = chromium(page.as_uri(), tmp_path, "--dump-dom")
    text = "\n".join(console)
    assert "boom" in text and "TypeError" in text


def pendulum(dim: int):
    """A box swinging about a hinge at the origin, its centre of mass 0.5 m away (red)."""
    g = (0.0, -9.81) if dim == 2 else (0.0, 0.0, -9.81)
    s = nc.System(f"pendulum{dim}", gravity=g)
    if dim == 2:
        bob = s.add_body("bob", coords="ruv", mass=1.0, inertia=0.01, position=(0.5, 0.0),
                         basis=[(-0.5, 0.0), (1.0, 0.0), (0.0, 1.0)], shape=nc.Box(0.3, 0.16, 0.05))
        s.add_joint(nc.Revolute(s.ground, bob, at=(0.0, 0.0)))
    else:
        bob = s.add_body("bob", mass=1.0, inertia=np.diag([0.01, 0.02, 0.02]), position=(0.5, 0.0, 0.0),
                         shape=nc.Box(0.3, 0.16, 0.16))
        s.add_joint(nc.Revolute(s.ground, bob, at=(0.0, 0.0, 0.0), axis=(0.0, 1.0, 0.0)))
    return s.build()


def red_centroid(image: np.ndarray) -> tuple[np.ndarray, int]:
    r, g, b = image[..., 0], image[..., 1], image[..., 2]
    mask = (r > 100) & (g < 70) & (b < 70) & (r > 2 * g)
    ys, xs = np.nonzero(mask)
    return np.array([xs.mean(), ys.mean()]) if len(xs) else np.full(2, np.nan), int(mask.sum())


@needs_chromium
@pytest.mark.parametrize("dim", [3, 2])
def test_page_draws_the_body_where_the_simulation_puts_it(dim, tmp_path):
    model = pendulum(dim)
    traj = nc.simulate(model, 0.6, 0.01)
    page = traj.to_html(tmp_path / "p.html", colors={"bob": "#ff0000"}, trails=False)
    text = page.read_text(encoding="utf-8")
    assert not re.search(r'(src|href)="(https?:)?//', text), "the page must load nothing from the network"
    data = html.page_data(traj, colors={"bob": "#ff0000"})
    cam = data["camera"]
    assert cam["ortho"] == (dim == 2)
    width, height = html.view_size(*WINDOW, has_panel=True)
    centres = []
    for t in (0.0, 0.6):
        image, console = screenshot(page, t, tmp_path)
        assert image.shape[:2] == (WINDOW[1], WINDOW[0])
        assert not console, "console output:\n" + "\n".join(console)
        centroid, count = red_centroid(image[:height, :width])
        assert count > 200, f"the red body is not on the screenshot at t = {t}"
        k = int(np.argmin(np.abs(traj.t - t)))
        expected = html.project(cam, geometry.embed(traj.poses()[1][k, 0], dim), width, height)[0]
        np.testing.assert_allclose(centroid, expected, atol=6.0, err_msg=f"t = {t}: body drawn off its place")
        centres.append(centroid)
    moved = np.linalg.norm(traj.poses()[1][-1, 0] - traj.poses()[1][0, 0])
    assert moved > 0.2 and np.linalg.norm(centres[1] - centres[0]) > 30, "the body did not move on the page"


def box_corners(prim, R, p) -> np.ndarray:
    """World corners of a box primitive placed in a member frame (R, p)."""
    h = prim.size / 2
    local = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * h
    return (R @ (prim.R @ local.T + prim.p[:, None])).T + p


def cylinder_box(prim, R, p) -> tuple[np.ndarray, np.ndarray]:
    """Exact world bounding box of a cylinder primitive: centre ± (|a| L/2 + r √(1 − a²))."""
    a = R @ prim.R[:, 2]
    c = R @ prim.p + p
    radius, length = prim.size
    half = np.abs(a) * length / 2 + radius * np.sqrt(np.clip(1 - a ** 2, 0, 1))
    return c - half, c + half


@needs_chromium
def test_drawn_parts_have_the_bounding_boxes_of_their_shapes(tmp_path):
    s = nc.System("shapes")
    R = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]) @ \
        np.array([[1.0, 0.0, 0.0], [0.0, 0.8, -0.6], [0.0, 0.6, 0.8]])
    body = s.add_body("body", mass=2.0, inertia=np.diag([0.02, 0.03, 0.04]), position=(0.3, 0.2, 0.5), rotation=R,
                      angular_velocity=(0.5, -1.0, 2.0), shape=nc.Box(0.4, 0.2, 0.1, position=(0.01, 0.02, 0.03)))
    bar = s.add_bar("bar", mass=1.0, ends=[(0.0, 0.0, 0.0), (0.6, 0.3, 0.2)], angular_velocity=(0, 0, 3.0),
                    velocity=(-0.45, 0.9, 0.0))
    s.add_joint(nc.Spherical(s.ground, bar, at=(0.0, 0.0, 0.0)))
    s.add_force(nc.Spring(bar, (0.0, 0.0, 0.0), body, (0.0, 0.0, 0.0), k=10.0, rest_length=0.3))
    s.add_body("egg", mass=1.0, inertia=np.diag([0.01, 0.02, 0.02]), position=(-0.5, 0.0, 0.3), rotation=R.T,
               angular_velocity=(1.0, 2.0, 0.5), shape=nc.Ellipsoid(0.15, 0.1, 0.05, rotation=R))
    s.add_bar("rod", mass=1.0, ends=[(0.0, -0.6, 0.0), (0.3, -0.6, 0.4)], angular_velocity=(2.0, 0, 0),
              shape=nc.Capsule(0.03, 0.4))
    s.add_point("dot", mass=1.0, position=(0.0, 0.6, 0.2), velocity=(0.5, 0.0, 1.0), shape=nc.Sphere(0.07))
    model = s.build()
    traj = nc.simulate(model, 0.5, 0.05)
    page = traj.to_html(tmp_path / "s.html")
    got, console = report(page, 0.5, tmp_path)
    assert not console, "console output:\n" + "\n".join(console)
    k = got["frame"]
    size = html.page_data(traj)["size"]
    prims = geometry.member_primitives(model, size)
    Rs, ps = traj.poses()
    idx = html.frame_indices(traj.t, html.FPS)[k]
    kinds = set()
    for name in ("body", "bar", "egg", "rod", "dot"):
        i = model.member_names.index(name)
        Ri, pi = Rs[idx, i], ps[idx, i]
        for prim, (lo, hi) in zip(prims[name], got["parts"][name]):
            centre = Ri @ prim.p + pi
            if prim.kind == "box":
                corners = box_corners(prim, Ri, pi)
                want = corners.min(axis=0), corners.max(axis=0)
                tol = 1e-5
            elif prim.kind == "cylinder":
                want = cylinder_box(prim, Ri, pi)
                tol = 0.02 * prim.size[0] + 1e-5        # a 24-gon stands for the circle
            elif prim.kind == "capsule":                 # segment ⊕ ball: |a| L/2 + r
                half = np.abs(Ri @ prim.R[:, 2]) * prim.size[1] / 2 + prim.size[0]
                want, tol = (centre - half, centre + half), 0.02 * prim.size[0]
            elif prim.kind in ("ellipsoid", "sphere"):  # √(Σ_j (M_ij s_j)²), M = R R_s
                semi = np.resize(prim.size, 3)
                half = np.sqrt(((Ri @ prim.R) ** 2) @ semi ** 2)
                want, tol = (centre - half, centre + half), 0.02 * semi.max()
            else:
                continue
            kinds.add(prim.kind)
            np.testing.assert_allclose(lo, want[0], atol=tol, err_msg=f"{name} {prim.kind}")
            np.testing.assert_allclose(hi, want[1], atol=tol, err_msg=f"{name} {prim.kind}")
    assert kinds >= {"box", "cylinder", "capsule", "ellipsoid", "sphere"}
    # the bar's cylinder runs from end to end
    cyl = prims["bar"][0]
    ends = traj.point("bar", (-0.5 * np.linalg.norm([0.6, 0.3, 0.2]), 0, 0))[idx], \
        traj.point("bar", (0.5 * np.linalg.norm([0.6, 0.3, 0.2]), 0, 0))[idx]
    i = model.member_names.index("bar")
    axis_ends = [Rs[idx, i] @ (cyl.p + sgn * cyl.R[:, 2] * cyl.size[1] / 2) + ps[idx, i] for sgn in (-1, 1)]
    np.testing.assert_allclose(axis_ends, ends, atol=1e-6)     # the bar length drifts by |Φ| ~ 1e-8


def test_inertia_box_has_the_inertia_of_the_body():
    rng = np.random.default_rng(3)
    Q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    I = Q @ np.diag([0.02, 0.05, 0.06]) @ Q.T
    s = nc.System("b")
    b = s.add_body("b", mass=3.0, inertia=I)
    box = geometry.inertia_box(b, 1.0, "#000000")
    a, bb, c = box.size
    I_box = 3.0 / 12 * np.diag([bb ** 2 + c ** 2, a ** 2 + c ** 2, a ** 2 + bb ** 2])    # closed form, box axes
    np.testing.assert_allclose(box.R @ I_box @ box.R.T, I, atol=1e-12)


def test_shapes_are_validated_and_round_trip_through_toml(tmp_path):
    with pytest.raises(nc.ModelError, match="box: edge y: expected a positive number"):
        nc.Box(0.1, -0.2, 0.3)
    with pytest.raises(nc.ModelError, match="sphere: expected 1 dimensions"):
        nc.Sphere(0.1, 0.2)
    s = nc.System("s")
    with pytest.raises(nc.ModelError, match="body 'b': shape: expected nc.Box"):
        s.add_body("b", mass=1.0, inertia=np.eye(3), shape="box")
    s.add_body("b", mass=1.0, inertia=np.eye(3), shape=nc.Cylinder(0.1, 0.4, position=(0, 0, 0.1)))
    s.add_point("p", mass=1.0, position=(1, 0, 0), shape=nc.Sphere(0.05))
    again = nc.System.from_toml(s.to_toml())
    assert isinstance(again.member("b").shape, nc.Cylinder)
    np.testing.assert_array_equal(again.member("b").shape.size, [0.1, 0.4])
    np.testing.assert_array_equal(again.member("b").shape.position, [0, 0, 0.1])
    assert again.member("p").shape.size[0] == 0.05
    text = s.to_toml().replace("cylinder = [0.1, 0.4]", "cylinder = [0.1]")
    with pytest.raises(nc.ModelError, match=r"members\[0\]\.shape: cylinder: expected 2 dimensions"):
        nc.System.from_toml(text)
    text = s.to_toml().replace("cylinder = [0.1, 0.4]", "cone = [0.1, 0.4]")
    with pytest.raises(nc.ModelError, match=r"members\[0\]\.shape: expected exactly one of box"):
        nc.System.from_toml(text)
    model_file = tmp_path / "m.toml"
    model_file.write_text(s.to_toml().replace('shape = {cylinder = [0.1, 0.4], position = [0.0, 0.0, 0.1]}',
                                              'shape = {mesh = "part.stl", scale = 0.001}'))
    mesh = nc.System.from_toml(model_file).member("b").shape
    assert isinstance(mesh, nc.Mesh) and Path(mesh.filename) == tmp_path / "part.stl"
    np.testing.assert_array_equal(mesh.scale, [0.001] * 3)


def test_html_refuses_a_bad_file_name_and_a_trajectory_without_its_model(tmp_path):
    model = pendulum(3)
    traj = nc.simulate(model, 0.05, 0.01)
    with pytest.raises(nc.NcgenError, match="expected a file name ending in .html"):
        traj.to_html(tmp_path / "x.png")
    q = np.where(traj.t[:, None] > 0.025, np.nan, traj.q)
    broken = nc.Trajectory.from_states(model, traj.t, q, traj.v, traj.lam, traj.u, traj.p, {"complete": False})
    with pytest.raises(nc.NcgenError, match=r"non-finite coordinates from t = 0.03 s on"):
        broken.to_html(tmp_path / "broken.html")
    assert not (tmp_path / "broken.html").exists()
    traj.save(tmp_path / "x.npz")
    with pytest.raises(nc.NcgenError, match="needs its model"):
        nc.Trajectory.load(tmp_path / "x.npz").to_html(tmp_path / "x.html")


@pytest.mark.slow      # robot scale (the Panda); fast: test_a_missing_mesh_file_warns_and_draws_the_inertia_box
def test_a_urdf_robot_page_has_its_meshes(tmp_path):
    """The Panda's visual meshes (example-robot-data) load and are drawn where the links are;
    a 10 s motion at 60 frames per second makes a page under 5 MB."""
    pytest.importorskip("trimesh")
    pytest.importorskip("yourdfpy")
    import importlib.metadata as md

    files = [f for f in (md.files("example-robot-data") or [])
             if str(f).endswith("panda_description/urdf/panda.urdf")]
    if not files:
        pytest.skip("example-robot-data with the Panda is not installed")
    import trimesh

    text = re.sub(r"<mimic[^>]*/>", "", Path(files[0].locate()).read_text())
    model = nc.System.from_urdf(text).build()
    t = np.arange(601) / 60.0                                 # 10 s at 60 frames per second
    limits = model.joint_limits
    mid = np.array([(limits[j]["lower"] + limits[j]["upper"]) / 2 for j in model.joint_names])
    amp = np.array([(limits[j]["upper"] - limits[j]["lower"]) / 4 for j in model.joint_names])
    phase = 2 * np.pi * 0.2 * t[:, None] + np.arange(len(mid))
    qj, vj = mid + amp * np.sin(phase), amp * 2 * np.pi * 0.2 * np.cos(phase)
    q, v = map(np.array, zip(*(model.from_joint_space(a, b) for a, b in zip(qj, vj))))
    traj = nc.Trajectory.from_states(model, t, q, v, np.zeros((len(t), model.nc)), np.zeros((len(t), model.nu)),
                                     model.p0, {"method": "joint-space motion"})
    data = html.page_data(traj)
    mesh_visuals = [v for v in model.visuals if v["shape"] == "mesh"]
    assert mesh_visuals and len(data["meshes"]) == len({v["filename"] for v in mesh_visuals})
    drawn = [p for m in data["members"] for p in m["parts"] if p["kind"] == "mesh"]
    assert len(drawn) == len(mesh_visuals)
    files = {html.meshes.resolve(v["filename"]).name: html.meshes.resolve(v["filename"]) for v in mesh_visuals}
    assert len(files) == len(data["meshes"])
    for entry in data["meshes"]:
        source = trimesh.load(str(files[entry["file"]]), force="mesh")
        q = np.frombuffer(base64.b64decode(entry["vertices"]["b64"]), "<u2").reshape(-1, 3)
        v = np.asarray(entry["low"]) + q / 65535 * (np.asarray(entry["high"]) - np.asarray(entry["low"]))
        np.testing.assert_allclose(v.min(axis=0), source.bounds[0], atol=1e-4 * np.ptp(source.bounds))
        np.testing.assert_allclose(v.max(axis=0), source.bounds[1], atol=1e-4 * np.ptp(source.bounds))
    from ncgen.viz.scene import scene
    sc = scene(traj.head(2))                   # line drawings (matplotlib) show each mesh's bounding box
    assert all(sc.body_outlined), [n for n, o in zip(sc.body_names, sc.body_outlined) if not o]
    page = traj.to_html(tmp_path / "panda.html")
    assert page.stat().st_size < 5e6
    if CHROMIUM is None:
        return
    got, console = report(page, 0.0, tmp_path)           # the browser builds every mesh
    assert not console, "console output:\n" + "\n".join(console)
    Rs, ps = traj.poses()
    for member in data["members"]:
        boxes = got["parts"][member["name"]]
        assert len(boxes) == len(member["parts"])
        i = member["index"]
        R, p = (Rs[0, i], ps[0, i]) if i >= 0 else (np.eye(3), np.zeros(3))
        for part, (lo, hi) in zip(member["parts"], boxes):
            if part["kind"] != "mesh":
                continue
            entry = data["meshes"][part["mesh"]]
            q = np.frombuffer(base64.b64decode(entry["vertices"]["b64"]), "<u2").reshape(-1, 3)
            v = np.asarray(entry["low"]) + q / 65535 * (np.asarray(entry["high"]) - np.asarray(entry["low"]))
            world = (R @ (np.asarray(part["R"]) @ (v * part["size"]).T + np.asarray(part["p"])[:, None])).T + p
            tol = 1e-4 * np.ptp(world)
            np.testing.assert_allclose(lo, world.min(axis=0), atol=tol, err_msg=member["name"])
            np.testing.assert_allclose(hi, world.max(axis=0), atol=tol, err_msg=member["name"])


EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def test_cli_writes_pages_for_simulate_optimize_modes_and_equilibrium(tmp_path, capsys):
    from ncgen.cli import main

    assert main(["simulate", str(EXAMPLES / "heavy_top.toml"), "--t-end", "0.2", "--backend", "vm",
                 "--html", str(tmp_path / "top.html")]) == 0
    data = json.loads(re.search(r'<script type="application/json" id="scene-data">(.*?)</script>',
                                (tmp_path / "top.html").read_text(encoding="utf-8"), re.S).group(1))
    assert data["model"] == "heavy_top" and data["trails"]["names"] == ["top.crown"]
    assert [m["name"] for m in data["members"]] == ["top"]
    assert main(["modes", str(EXAMPLES / "double_pendulum.toml"), "--html", str(tmp_path / "mode.html")]) == 0
    assert main(["equilibrium", str(EXAMPLES / "tensegrity.toml"), "--html", str(tmp_path / "eq.html")]) == 0
    assert re.search(r"<title>tensegrity: equilibrium \((stable|neutral|unstable)\)</title>",
                     (tmp_path / "eq.html").read_text(encoding="utf-8"))
    assert main(["optimize", str(EXAMPLES / "cartpole_swingup.toml"), "-o", str(tmp_path / "cp.npz"),
                 "--html", str(tmp_path / "cp.html")]) == 0
    assert (tmp_path / "cp.html").stat().st_size > 0
    capsys.readouterr()
    assert main(["simulate", str(EXAMPLES / "heavy_top.toml"), "--t-end", "0.1"]) == 0   # no file: the summary only
    assert "heavy_top" in capsys.readouterr().out
    assert main(["simulate", str(EXAMPLES / "heavy_top.toml"), "--html", str(tmp_path / "x.png")]) == 2
    assert "expected a file name ending in .html" in capsys.readouterr().err


def test_a_missing_mesh_file_warns_and_draws_the_inertia_box(tmp_path):
    s = nc.System("meshy")
    s.add_body("part", mass=1.0, inertia=np.diag([0.01, 0.02, 0.03]), shape=nc.Mesh(tmp_path / "nowhere.stl"))
    model = s.build()
    traj = nc.simulate(model, 0.02, 0.01)
    with pytest.warns(UserWarning, match=r"nowhere.stl.*file not found.*mesh_paths"):
        data = html.page_data(traj)
    parts = data["members"][0]["parts"]
    assert [p["kind"] for p in parts] == ["box"] and not data["meshes"]
