"""``to_html(traj, path)``: one self-contained, offline HTML page of a run — an interactive 3D
view (three.js, inlined with its licence) with play/pause, a time slider, speed, trails and
plots (energy, constraint residual, joint positions, contact gaps and forces) whose cursor
follows the time.  ``page.html?t=1.5`` opens paused at t = 1.5 s.

Data are float32 in base64 (poses as position + quaternion per member and frame, at most
``fps`` frames per simulated second); mesh vertices are quantised to 16 bits.  The 3D view
takes the window less the plot panel (``PANEL_WIDTH`` px, right) and the control bar
(``CONTROLS_HEIGHT`` px, bottom); the camera is computed here (:func:`camera`), so a
point's pixel is known in Python (:func:`project`)."""
from __future__ import annotations

import base64
import json
import math
import os
import warnings
from pathlib import Path

import numpy as np

from ncgen.errors import NcgenError
from ncgen.files import atomic_path
from ncgen.validation import as_scalar
from ncgen.version import __version__
from ncgen.viz import geometry, meshes
from ncgen.viz.scene import TENSION_HIGH, TENSION_LOW
from ncgen.viz.scene import scene as make_scene

FPS = 60
PANEL_WIDTH = 360
CONTROLS_HEIGHT = 48
FOV = 40.0                      # vertical field of view of the perspective camera (deg)
#: Direction from the target to the camera, in (right, forward, up) of the gravity frame.
VIEW_DIRECTION = (1.0, -1.6, 0.9)
MAX_JOINT_CURVES = 12


def to_html(traj, path, *, fps: float = FPS, colors: dict | None = None, mesh_paths=(), title: str | None = None,
            trails: bool = True, plots: bool = True) -> Path:
    """Write the page of ``traj`` (a :class:`~ncgen.runtime.trajectory.Trajectory` with its
    model) to ``path`` (``.html``); ``colors`` maps member names to CSS colours;
    ``mesh_paths``: extra folders holding mesh files; ``plots=False``: the 3D view alone (a
    single configuration).  Returns the path."""
    path = Path(path)
    if path.suffix.lower() not in (".html", ".htm"):
        raise NcgenError(f"to_html: {path}: expected a file name ending in .html")
    if not len(traj.t):
        raise NcgenError(f"to_html: {path}: the trajectory is empty (no samples): nothing to show")
    fps = as_scalar(fps, "to_html: fps")
    if fps <= 0:
        raise NcgenError(f"to_html: fps: expected a positive number of frames per second, got {fps:g}")
    if title is not None and not isinstance(title, str):
        raise NcgenError(f"to_html: title: expected text or None, got {type(title).__name__} {title!r}")
    mesh_paths = _folders(mesh_paths)
    data = page_data(traj, fps=fps, colors=colors, mesh_paths=mesh_paths, trails=trails, with_plots=plots)
    text = render_page(data, title or f"{traj.model_name} — ncgen")
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        Path(tmp).write_text(text, encoding="utf-8")
    return path


def _folders(mesh_paths) -> list:
    """``mesh_paths`` as a list of folders: one folder (text or a path) or a list of them."""
    if isinstance(mesh_paths, (str, os.PathLike)):
        return [mesh_paths]
    try:
        folders = list(mesh_paths)
    except TypeError:
        raise NcgenError(f"to_html: mesh_paths: expected a folder or a list of folders, got "
                         f"{type(mesh_paths).__name__} {mesh_paths!r}") from None
    for i, folder in enumerate(folders):
        if not isinstance(folder, (str, os.PathLike)):
            raise NcgenError(f"to_html: mesh_paths[{i}]: expected a folder (text or a path), got "
                             f"{type(folder).__name__} {folder!r}")
    return folders


# ----------------------------------------------------------------- rendering
def templates_dir() -> Path:
    """The shipped ``html`` templates (``templates/html``, installed as ``ncgen._templates/html``)."""
    from ncgen.codegen.render import shipped_templates_dir
    return shipped_templates_dir("html")


def render_page(data: dict, title: str) -> str:
    """The HTML text of a page showing ``data`` (:func:`page_data`)."""
    import jinja2

    folder = templates_dir()
    vendor = folder / "vendor" / "three"
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(folder)), undefined=jinja2.StrictUndefined,
                             autoescape=False, keep_trailing_newline=True)
    payload = json.dumps(data, separators=(",", ":"), allow_nan=False).replace("</", "<\\/")
    return env.get_template("viewer.html.j2").render(
        title=_escape(title), data_json=payload, version=__version__,
        three_js=(vendor / "three.module.min.js").read_text(encoding="utf-8"),
        orbit_js=(vendor / "OrbitControls.js").read_text(encoding="utf-8"),
        three_version=(vendor / "VERSION").read_text(encoding="utf-8").strip(),
        three_license=_escape((vendor / "LICENSE").read_text(encoding="utf-8")),
        panel_width=PANEL_WIDTH, controls_height=CONTROLS_HEIGHT)


def _escape(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def _pack(a, dtype=np.float32) -> dict:
    """An array as ``{"shape", "dtype", "b64"}`` (little-endian)."""
    a = np.ascontiguousarray(np.asarray(a).astype(np.dtype(dtype).newbyteorder("<")))
    return {"shape": list(a.shape), "dtype": np.dtype(dtype).name, "b64": base64.b64encode(a.tobytes()).decode()}


# ------------------------------------------------------------------- camera
def camera(lo, hi, dim: int, gravity, aspect: float = 1.0) -> dict:
    """Camera looking at the box ``lo``–``hi`` (3D, m): perspective from above and in front
    (up = −gravity) in 3D, orthographic along −z in a planar system."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    target = (lo + hi) / 2
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 1e-3)
    if dim == 2:
        g = np.asarray(gravity, float)
        up = _in_plane_up(-g if np.linalg.norm(g) > 0 else np.array([0.0, 1.0]))
        return {"ortho": True, "target": target.tolist(), "position": (target + [0, 0, 4 * radius]).tolist(),
                "up": up.tolist(), "half_height": 1.1 * radius, "near": 0.01 * radius, "far": 10 * radius}
    g = np.asarray(gravity, float)
    up = -g / np.linalg.norm(g) if np.linalg.norm(g) > 0 else np.array([0.0, 0.0, 1.0])
    helper = np.eye(3)[int(np.argmin(np.abs(up)))]
    right = np.cross(helper, up)
    right /= np.linalg.norm(right)
    forward = np.cross(up, right)
    d = np.array(VIEW_DIRECTION) @ np.array([right, forward, up])
    d /= np.linalg.norm(d)
    half = math.radians(FOV) / 2
    distance = 1.2 * radius / math.sin(min(half, math.atan(aspect * math.tan(half))))
    return {"ortho": False, "target": target.tolist(), "position": (target + distance * d).tolist(),
            "up": up.tolist(), "fov": FOV, "near": distance / 100, "far": distance * 10}


def _in_plane_up(v) -> np.ndarray:
    v = np.asarray(v, float)
    return np.array([v[0], v[1], 0.0]) / np.linalg.norm(v)


def view_size(width: int, height: int, has_panel: bool) -> tuple[int, int]:
    """Size (px) of the 3D view in a window of ``width`` × ``height``."""
    return width - (PANEL_WIDTH if has_panel else 0), height - CONTROLS_HEIGHT


def project(cam: dict, points, width: int, height: int) -> np.ndarray:
    """Pixel coordinates ``(n, 2)`` (x right, y down, origin at the view's top-left corner) of
    world points ``(n, 3)`` seen by ``cam`` in a view of ``width`` × ``height`` px."""
    eye, target, up = (np.asarray(cam[k], float) for k in ("position", "target", "up"))
    z = eye - target
    z /= np.linalg.norm(z)
    x = np.cross(up, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    rel = np.asarray(points, float).reshape(-1, 3) - eye
    xc, yc, zc = rel @ x, rel @ y, rel @ z
    aspect = width / height
    if cam["ortho"]:
        h = cam["half_height"]
        ndc = np.column_stack([xc / (h * aspect), yc / h])
    else:
        f = 1 / math.tan(math.radians(cam["fov"]) / 2)
        ndc = np.column_stack([f / aspect * xc / -zc, f * yc / -zc])
    return np.column_stack([(ndc[:, 0] + 1) / 2 * width, (1 - ndc[:, 1]) / 2 * height])


# --------------------------------------------------------------------- data
def frame_indices(t: np.ndarray, fps: float) -> np.ndarray:
    """Indices of at most ``fps`` samples per second of ``t`` (first and last kept)."""
    n = len(t)
    if n < 2:
        return np.arange(n)
    count = min(n, int(math.ceil((t[-1] - t[0]) * fps)) + 1)
    grid = np.linspace(t[0], t[-1], max(count, 2))
    idx = np.unique(np.clip(np.searchsorted(t, grid), 0, n - 1))
    return idx


def page_data(traj, *, fps: float = FPS, colors=None, mesh_paths=(), trails: bool = True,
              with_plots: bool = True) -> dict:
    """Everything the page draws, as JSON-ready data (see the module docstring)."""
    from scipy.spatial.transform import Rotation

    model = traj.model
    sc = make_scene(traj, colors)           # raises a clear error without a model
    d = traj.dim
    idx = frame_indices(traj.t, fps)
    lo, hi = sc.bounds()
    lo, hi = geometry.embed(lo, d), geometry.embed(hi, d)
    size = sc.size
    prims = geometry.member_primitives(model, size, colors)
    R, p = geometry.embed_rotation(sc.member_R[idx]), geometry.embed(sc.member_p[idx], d)
    n, k = p.shape[:2]
    quat = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_quat().reshape(n, k, 4) if k else np.zeros((n, 0, 4))
    members, mesh_list, boxes = _members(model, prims, R, p, size, mesh_paths)
    lo, hi = np.min([lo, *boxes], axis=0), np.max([hi, *boxes], axis=0)
    springs = _springs(traj, sc, idx)
    contacts = {"radii": sc.sphere_radii.tolist(),
                "centres": _pack(geometry.embed(sc.sphere_centres[idx], d)) if len(sc.sphere_radii) else None,
                "planes": [[geometry.embed(pt, d).tolist(), geometry.embed(nr, d).tolist()] for pt, nr in sc.planes],
                "points": _pack(np.nan_to_num(geometry.embed(sc.contact_points[idx], d), nan=1e30))
                if sc.contact_points.shape[1] else None,
                "forces": _pack(geometry.embed(sc.contact_forces[idx], d)) if sc.contact_points.shape[1] else None,
                "force_scale": _force_scale(sc.contact_forces)}
    markers = geometry.embed(traj.markers[idx], d)
    if markers.shape[1] == 0 and model.member_names:
        # no markers: the trail of the last member's centre of mass (a robot's hand, a chain's end)
        markers, trail_names = p[:, -1:], list(model.member_names[-1:])
    else:
        trail_names = list(traj.marker_names)
    return {
        "version": __version__, "model": traj.model_name, "dim": d, "complete": traj.complete,
        "t": _pack(traj.t[idx], np.float64), "position": _pack(p), "quaternion": _pack(quat),
        "members": members, "meshes": mesh_list,
        "anchors": geometry.embed(sc.anchors, d).tolist(),
        "springs": springs, "contacts": contacts,
        "trails": {"names": trail_names, "positions": _pack(markers), "on": bool(trails)},
        "camera": camera(lo, hi, d, model.gravity), "size": size,
        "bounds": [lo.tolist(), hi.tolist()],
        "plots": plots(traj, idx) + _tensions(sc, idx) if with_plots and len(idx) > 1 else [],
        "tension_scale": sc.tension_scale(),
        "tension_colors": [_hex(TENSION_LOW), _hex(TENSION_HIGH)],
    }


def _members(model, prims, R, p, size: float, mesh_paths) -> tuple[list, list, list]:
    """``(members, meshes, corners)``: each member's parts as page data, the mesh table, and
    corners of boxes holding every mesh over the motion (its centre's path ± its size)."""
    table: dict[str, int] = {}
    mesh_list: list[dict] = []
    boxes, members = [], []
    for name in [*model.member_names, "ground"]:
        if name not in prims:
            continue
        i = model.member_names.index(name) if name != "ground" else -1
        parts, missing = [], False
        for prim in prims[name]:
            part = _part(prim, table, mesh_list, mesh_paths)
            if part is None:
                missing = True
                continue
            parts.append(part)
            extent = part.pop("_extent", None)
            if extent is not None:
                centre = np.asarray(part["p"])[None] if i < 0 else \
                    np.einsum("tij,j->ti", R[:, i], np.asarray(part["p"])) + p[:, i]
                boxes += [np.min(centre, axis=0) - extent, np.max(centre, axis=0) + extent]
        if missing and i >= 0 and model.member(name).kind == "body" and \
                not any(part["role"] == "member" for part in parts):   # its meshes could not be read
            parts.append(_part(geometry.inertia_box(model.member(name), size, geometry.PALETTE[0]), {}, [], ()))
        members.append({"name": name, "index": i, "parts": parts})
    for entry in mesh_list:
        entry.pop("_extent")
    return members, mesh_list, boxes


def _part(prim: geometry.Primitive, table: dict, mesh_list: list, mesh_paths) -> dict | None:
    part = {"kind": prim.kind, "size": prim.size.tolist(), "R": prim.R.tolist(), "p": prim.p.tolist(),
            "color": prim.color, "role": prim.role}
    if prim.kind != "mesh":
        return part
    try:
        path = str(meshes.resolve(prim.filename, mesh_paths))
        if path not in table:
            v, f, color = meshes.load(path)
            q, low, high = meshes.quantize(v)
            table[path] = len(mesh_list)
            mesh_list.append({"file": Path(path).name, "vertices": _pack(q, np.uint16), "low": low.tolist(),
                              "high": high.tolist(), "faces": _pack(f, np.uint16 if len(v) <= 65535 else np.uint32),
                              "color": color, "_extent": float(np.max(np.linalg.norm(v, axis=1)))})
    except meshes.MeshError as e:
        warnings.warn(f"to_html: {e}; drawing the member's inertia box instead", stacklevel=3)
        return None
    entry = mesh_list[table[path]]
    part["mesh"] = table[path]
    if entry["color"] is not None:
        part["color"] = entry["color"]
    part["_extent"] = entry["_extent"] * float(np.max(prim.size))
    return part


def _springs(traj, sc, idx) -> list[dict]:
    """Per spring or cable segment (a clustered cable's segments each): its ends
    ``(n, 2, 3)`` per frame, whether it is a cable and slack, its element's rest length and
    tension (N) per frame; ``sc`` holds the frames ``idx``."""
    from ncgen.assembly.springs import tension_rows

    rows = tension_rows(traj.model.forces)
    out = []
    for i, j in enumerate(sc.spring_owner):
        s, name, _ = rows[j]
        out.append({"name": name, "cable": bool(sc.spring_cable[i]),
                    "rest_length": float(s.rest_length) if not hasattr(s, "path")
                    and isinstance(s.rest_length, (int, float)) else None,
                    "ends": _pack(geometry.embed(sc.spring_ends[idx, i], traj.dim)),
                    "slack": _pack(sc.spring_slack[idx, i], np.uint8),
                    "tension": _pack(sc.spring_tension[idx, i])})
    return out


def _tensions(sc, idx) -> list[dict]:
    """A panel of the tensions (N) of the springs and cables (at most ``MAX_JOINT_CURVES``)."""
    if not sc.spring_names:
        return []
    first = [int(np.flatnonzero(sc.spring_owner == j)[0]) for j in range(len(sc.spring_names))]
    return [{"title": "spring and cable tensions", "unit": "N", "log": False,
             "series": [{"label": name, "y": _pack(sc.spring_tension[idx, first[j]])}
                        for j, name in enumerate(sc.spring_names[:MAX_JOINT_CURVES])]}]


def plots(traj, idx) -> list[dict]:
    """Panels of curves: energy, constraint residual, joint positions, contact gaps and forces."""
    out = [{"title": f"energy E − E(t0), E(t0) = {traj.energy[0]:.6g} J", "unit": "J", "log": False,
            "series": [{"label": "E − E(t0)", "y": _pack(traj.energy[idx] - traj.energy[0])}]},
           {"title": "constraint residual |Φ|∞", "unit": "m²", "log": True,
            "series": [{"label": "|Φ|∞", "y": _pack(_positive(traj.constraint_residual[idx]))},
                       {"label": "|A v + Φ_t|∞ (m²/s)", "y": _pack(_positive(traj.velocity_residual[idx]))}]}]
    if traj.joint_position_names:
        cols = list(range(min(len(traj.joint_position_names), MAX_JOINT_CURVES)))
        out.append({"title": "joint positions" + (f" (first {len(cols)})"
                                                  if len(cols) < len(traj.joint_position_names) else ""),
                    "unit": "rad or m", "log": False,
                    "series": [{"label": traj.joint_position_names[c], "y": _pack(traj.qj[idx, c])} for c in cols]})
    elif traj.marker_names:
        out.append({"title": "markers", "unit": "m", "log": False,
                    "series": [{"label": f"{name} {'xyz'[j]}", "y": _pack(traj.markers[idx, m, j])}
                               for m, name in enumerate(traj.marker_names[:4]) for j in range(traj.dim)]})
    if traj.u.shape[1] and np.any(traj.u[idx]):
        names = [f"{n}[{i}]" if size > 1 else n for n, size in zip(traj.input_names, _input_sizes(traj))
                 for i in range(size)]
        out.append({"title": "inputs", "unit": "N, N·m", "log": False,
                    "series": [{"label": names[c], "y": _pack(traj.u[idx, c])}
                               for c in range(min(traj.u.shape[1], MAX_JOINT_CURVES))]})
    if traj.contact_names:
        out.append({"title": "contact gaps (< 0: penetration)", "unit": "m", "log": False,
                    "series": [{"label": c, "y": _pack(traj.gap[idx, k])} for k, c in enumerate(traj.contact_names)]})
        out.append({"title": "contact normal forces", "unit": "N", "log": False,
                    "series": [{"label": c, "y": _pack(traj.contact_normal[idx, k])}
                               for k, c in enumerate(traj.contact_names)]})
    return out


def _hex(rgb) -> int:
    """``0xRRGGBB`` of an RGB triple in [0, 1]."""
    r, g, b = (int(round(255 * c)) for c in rgb)
    return (r << 16) | (g << 8) | b


def _positive(x: np.ndarray) -> np.ndarray:
    """``x`` with zeros (nothing to draw on a log scale) as NaN."""
    return np.where(x > 0, x, np.nan)


def _input_sizes(traj) -> list[int]:
    sizes = getattr(traj.model, "input_sizes", None)
    return list(sizes) if sizes is not None else [1] * traj.u.shape[1]


def _force_scale(forces: np.ndarray) -> float:
    """The largest contact force (N; 0 without any): the page draws it 1/5 of the scene's size."""
    return float(np.max(np.linalg.norm(forces, axis=-1))) if forces.size else 0.0
