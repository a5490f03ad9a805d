"""What to draw of a trajectory, frame by frame: plain NumPy arrays, no matplotlib.

* bars: segments between their two ends, ``(n_t, n_bars, 2, dim)``;
* bodies: the frame (centre of mass and the rotation's columns as axes) and the basic
  points of the body (``r_i``, ``r_j``, ... : the points its natural coordinates name);
* point members: their positions; markers: their positions;
* ground-fixed basic points: constant positions, drawn as anchors;
* contacts: the spheres (centres per frame and radii), the planes fixed to the ground
  (a point and a unit normal each) and, per frame, the contact points that carry a force;
* shapes (:mod:`ncgen.viz.geometry`): every member's pose per frame and the line drawings
  of its primitives in its frame (``outlines``), bars' colours;
* springs and cables (a clustered cable segment by segment): their ends per frame, which are
  cables, when a cable is slack and its tension.
Positions in m, world frame.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ncgen.errors import NcgenError
from ncgen.model.capstan import material_names
from ncgen.runtime.contact_outputs import gaps as gaps_of
from ncgen.viz import geometry


@dataclass
class Scene:
    dim: int
    bar_names: list[str]
    bars: np.ndarray            # (n_t, n_bars, 2, dim)
    body_names: list[str]
    body_origins: np.ndarray    # (n_t, n_bodies, dim)
    body_axes: np.ndarray       # (n_t, n_bodies, dim, dim): column k is axis k
    body_points: np.ndarray     # (n_t, n_body_points, dim)
    points: np.ndarray          # (n_t, n_points, dim): point members
    markers: np.ndarray         # (n_t, n_markers, dim)
    anchors: np.ndarray         # (n_anchors, dim): ground-fixed points
    sphere_centres: np.ndarray = None   # (n_t, n_spheres, dim)
    sphere_radii: np.ndarray = None     # (n_spheres,)
    planes: np.ndarray = None           # (n_planes, 2, dim): point and unit normal of ground planes
    contact_points: np.ndarray = None   # (n_t, nk, dim): contact point, NaN while it carries no force
    contact_forces: np.ndarray = None   # (n_t, nk, dim): normal force on the sphere (first sphere) (N)
    member_R: np.ndarray = None         # (n_t, n_members, dim, dim): every member's rotation
    member_p: np.ndarray = None         # (n_t, n_members, dim): and centre of mass
    outlines: list = None               # [(member index, -1: ground; local points (m, 3); colour)]
    bar_colors: list = None             # colour of each bar
    body_outlined: list = None          # per body: drawn by outlines (else by its axes)
    spring_ends: np.ndarray = None      # (n_t, n_springs, 2, dim)
    spring_cable: np.ndarray = None     # (n_springs,) True: a cable
    spring_slack: np.ndarray = None     # (n_t, n_springs) True: a cable without tension
    spring_tension: np.ndarray = None   # (n_t, n_springs) the element's tension (N)
    spring_owner: np.ndarray = None     # (n_springs,) index of the element in spring_names
    spring_names: list = None           # names of the springs, clustered cables, capstan sides
    shape_box: np.ndarray = None        # (2, dim): smallest and largest coordinate of the outlines
    size: float = 1.0                   # the scene's size (m) that default shapes are scaled by

    def __post_init__(self):
        n, d = self.markers.shape[0], self.dim
        defaults = {"sphere_centres": np.zeros((n, 0, d)), "sphere_radii": np.zeros(0),
                    "planes": np.zeros((0, 2, d)), "contact_points": np.zeros((n, 0, d)),
                    "contact_forces": np.zeros((n, 0, d)),
                    "member_R": np.zeros((n, 0, d, d)), "member_p": np.zeros((n, 0, d)), "outlines": [],
                    "bar_colors": [geometry.PALETTE[0]] * len(self.bar_names),
                    "body_outlined": [False] * len(self.body_names),
                    "spring_ends": np.zeros((n, 0, 2, d)), "spring_cable": np.zeros(0, bool),
                    "spring_slack": np.zeros((n, 0), bool), "spring_tension": np.zeros((n, 0)),
                    "spring_owner": np.zeros(0, int), "spring_names": []}
        for key, value in defaults.items():
            if getattr(self, key) is None:
                setattr(self, key, value)

    def tension_scale(self) -> float:
        """The largest cable tension over the frames (N; 1 without a taut cable): the top of
        the colour scale cables are drawn with."""
        taut = self.spring_tension[:, self.spring_cable] if self.spring_tension.size else np.zeros(0)
        top = float(np.max(taut, initial=0.0))
        return top if top > 0 else 1.0

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Smallest and largest coordinate over all frames and drawn things."""
        clouds = [a.reshape(-1, self.dim) for a in (self.bars, self.body_origins, self.body_points,
                                                   self.points, self.markers, self.anchors,
                                                   self.sphere_centres, self.spring_ends) if a.size]
        if self.shape_box is not None:
            clouds.append(self.shape_box)
        allpts = np.concatenate(clouds) if clouds else np.zeros((1, self.dim))
        return allpts.min(axis=0), allpts.max(axis=0)


def scene(traj, colors: dict | None = None) -> Scene:
    """The scene of ``traj`` (it needs its model: see ``Trajectory.load(path, model=...)``);
    ``colors`` maps member names to colours."""
    model = traj.model
    if model is None:
        raise NcgenError("drawing a trajectory needs its model; this one was loaded without it: "
                         "use Trajectory.load(path, model=model)")
    n, d = len(traj), traj.dim
    bad = ~np.isfinite(traj.q).all(axis=1)
    if bad.any():
        raise NcgenError(f"drawing: the trajectory of {traj.model_name!r} has non-finite coordinates from "
                         f"t = {traj.t[bad.argmax()]:g} s on; draw the part before: traj.head({int(bad.argmax())})")
    members = [model.member(name) for name in model.member_names]
    bars = [m for m in members if m.kind == "bar"]
    bodies = [m for m in members if m.kind == "body"]
    materials = material_names(model.forces)              # a capstan cable's material: not drawn
    points = [m for m in members if m.kind == "point" and m.name not in materials]
    bar_ends = [np.stack([traj.point(m.name, m.rigid.rbar_i),
                          traj.point(m.name, m.rigid.rbar_i + m.rigid.Xbar[:, 0])], axis=1) for m in bars]
    body_points = [traj.point(m.name, local) for m in bodies for local in _basic_points(m)]
    R, p = traj.poses() if bodies else (np.zeros((n, 0, d, d)), np.zeros((n, 0, d)))
    index = [model.member_names.index(m.name) for m in bodies]
    sc = Scene(
        dim=d,
        bar_names=[m.name for m in bars],
        bars=np.stack(bar_ends, axis=1) if bars else np.zeros((n, 0, 2, d)),
        body_names=[m.name for m in bodies],
        body_origins=p[:, index],
        body_axes=R[:, index],
        body_points=np.stack(body_points, axis=1) if body_points else np.zeros((n, 0, d)),
        points=np.stack([traj.point(m.name, np.zeros(d)) for m in points], axis=1) if points
        else np.zeros((n, 0, d)),
        markers=traj.markers,
        anchors=np.array([node.fixed for node in model.layout.nodes if node.fixed is not None]).reshape(-1, d),
        **contact_scene(traj, model),
        **spring_scene(traj),
    )
    _shapes(sc, traj, model, colors)
    return sc


def _shapes(sc: Scene, traj, model, colors) -> None:
    """Fill the member poses and outlines of ``sc`` (see :mod:`ncgen.viz.geometry`)."""
    lo, hi = sc.bounds()
    sc.size = max(float(np.max(hi - lo)), 1e-3)
    prims = geometry.member_primitives(model, sc.size, colors)
    if model.member_names:
        sc.member_R, sc.member_p = traj.poses()
    outlined = set()
    for name, parts in prims.items():
        k = model.member_names.index(name) if name != "ground" else -1
        m = model.member(name) if k >= 0 else None
        for prim in parts:
            if m is not None and m.kind == "bar" and m.shape is None and prim.role == "member":
                continue                                 # a plain bar: drawn as a thick segment
            pts = geometry.outline(_mesh_box(prim) if prim.kind == "mesh" else prim)
            if len(pts):
                sc.outlines.append((k, pts, prim.color))
                if prim.role == "member":
                    outlined.add(name)
    sc.shape_box = _outline_box(sc)
    sc.bar_colors = [prims[name][0].color if prims.get(name) else geometry.PALETTE[0] for name in sc.bar_names]
    sc.body_outlined = [name in outlined for name in sc.body_names]


def _mesh_box(prim: geometry.Primitive) -> geometry.Primitive:
    """The bounding box of a mesh primitive's vertices (same placement and colour), what line
    drawings show of a mesh; the mesh itself when its file cannot be read (nothing drawn)."""
    from ncgen.viz import meshes

    try:
        vertices = meshes.load(str(meshes.resolve(prim.filename)))[0] * prim.size
    except meshes.MeshError:
        return prim
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    return geometry.Primitive("box", np.maximum(hi - lo, 1e-9), prim.R, prim.R @ ((lo + hi) / 2) + prim.p,
                              prim.color, role=prim.role)


def _outline_box(sc: Scene, frames: int = 200) -> np.ndarray | None:
    """Smallest and largest world coordinate of every outline over (at most ``frames``) frames."""
    if not sc.outlines:
        return None
    d, n = sc.dim, sc.member_p.shape[0]
    sub = slice(None, None, max(1, n // frames))
    boxes = []
    for k, pts, _ in sc.outlines:
        local = pts[~np.isnan(pts).any(axis=1), :d]
        world = local[None] if k < 0 else \
            np.einsum("tij,mj->tmi", sc.member_R[sub, k], local) + sc.member_p[sub, k][:, None, :]
        boxes += [world.reshape(-1, d).min(axis=0), world.reshape(-1, d).max(axis=0)]
    return np.array([np.min(boxes, axis=0), np.max(boxes, axis=0)])


#: Cables are coloured from this RGB at no tension to the next at the largest (linear blend;
#: the HTML viewer uses the same two colours).
TENSION_LOW, TENSION_HIGH = (0.17, 0.48, 0.71), (0.84, 0.10, 0.11)


def tension_rgb(tension, scale: float) -> np.ndarray:
    """RGB (… × 3, in [0, 1]) of cable tensions ``tension`` (N) on the scale 0 … ``scale`` N."""
    s = np.clip(np.asarray(tension, float) / scale, 0.0, 1.0)[..., None]
    return (1 - s) * np.array(TENSION_LOW) + s * np.array(TENSION_HIGH)


def spring_scene(traj, idx=None) -> dict:
    """Ends of every spring and cable segment per frame (``idx``: the frames, default all),
    which are cables, when a cable is slack (its pull ``k (l − l₀) + c l̇`` is not positive),
    the tension (N) and the element of each segment (a clustered cable has one segment per
    pair of consecutive points of its path, all with its one tension; a capstan cable's
    sides are one element each, ``<name>.a``, ``<name>.b``, … in path order, each with its own tension).  From the model's
    :class:`~ncgen.assembly.springs.SpringTable` and its force elements."""
    from ncgen.assembly.springs import tension_rows

    model = traj.model
    table = getattr(model, "springs", None)
    rows = tension_rows(model.forces)
    if table is None or not rows:
        return {}
    idx = np.arange(len(traj)) if idx is None else np.asarray(idx)
    d, n = traj.dim, len(idx)
    batch = table.function.map(n)(traj.t[idx][None, :], traj.q[idx].T, traj.v[idx].T, traj.u[idx].T,
                                  np.tile(np.reshape(traj.p, (-1, 1)), (1, n)))
    tension, pulls = (np.asarray(batch[i]).reshape(len(rows), n).T for i in (0, 2))
    ends, owner = [], []
    for j, (_, _, path) in enumerate(rows):
        pts = [np.broadcast_to(np.asarray(at, float), (n, d)) if m.is_ground else traj.point(m.name, at)[idx]
               for m, at in path]
        for a, b in zip(pts, pts[1:]):
            ends.append(np.stack([a, b], axis=1))
            owner.append(j)
    owner = np.array(owner, int)
    cable = np.array(table.cable, bool)
    return {"spring_ends": np.stack(ends, axis=1), "spring_cable": cable[owner],
            "spring_slack": ((pulls <= 0) & cable[None, :])[:, owner],
            "spring_tension": tension[:, owner], "spring_owner": owner, "spring_names": list(table.names)}


def contact_scene(traj, model) -> dict:
    """Spheres, ground planes and loaded contact points of ``traj`` (see :class:`Scene`); the
    plane z = 0 of rolling elements (``model.rolling``)."""
    n, d = len(traj), traj.dim
    planes = [[np.zeros(d), np.eye(d)[-1]]] if getattr(model, "rolling", ()) else []
    if not getattr(model, "nk", 0):
        return {"planes": np.asarray(planes, float).reshape(-1, 2, d)} if planes else {}
    centres, radii, points, forces = [], [], [], []
    translated: dict = {}
    for k, c in enumerate(model.contacts):
        if "plane" in c:                                       # a sphere (or a shape's point) on a plane
            centre, push, contact = _on_plane(traj, model, c)
            centres.append(centre)
            radii.append(c["radius"])
            if c["plane"] == "ground":
                planes.append([c["point"], c["normal"]])
        elif "box" in c or "capsule" in c or "cylinder" in c:  # a sphere or a corner against a box, capsule, cylinder
            at, radius, other = (c["at"], c["radius"], c["box"]) if "box" in c else \
                (c["sphere_at"], c["sphere_radius"], c.get("capsule", c.get("cylinder")))
            centre = traj.point(c["sphere"], at) if c["sphere"] != "ground" else \
                np.broadcast_to(np.asarray(at, float), (n, d))
            centres.append(centre)
            radii.append(radius)
            push = _gap_normals(model, traj, k, c["sphere"], other, translated)  # the other pushes the sphere
            contact = centre - radius * push
        elif "edge_a" in c:                                    # edges crossing: forces on b, not drawn as points
            push = _gap_normals(model, traj, k, c["b"], c["a"], translated)
            contact = np.full((n, d), np.nan)
        else:
            ca_, cb = traj.point(c["a"], c["at_a"]), traj.point(c["b"], c["at_b"])
            centres += [ca_, cb]
            radii += [c["radius_a"], c["radius_b"]]
            u = (cb - ca_) / np.linalg.norm(cb - ca_, axis=1, keepdims=True)
            contact = ca_ + c["radius_a"] * u
            push = -u                                          # b pushes a away
        points.append(np.where(traj.contact_normal[:, k:k + 1] > 0, contact, np.nan))
        forces.append(traj.contact_normal[:, k:k + 1] * push)
    unique = {}
    for plane in planes:
        unique.setdefault(tuple(np.round(np.ravel(plane), 12)), plane)
    return {"sphere_centres": np.stack(centres, axis=1), "sphere_radii": np.asarray(radii, float),
            "planes": np.asarray(list(unique.values()), float).reshape(-1, 2, d),
            "contact_points": np.stack(points, axis=1), "contact_forces": np.stack(forces, axis=1)}


def _on_plane(traj, model, c: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(centre, push, contact point)`` over time of contact ``c``, a sphere (or a shape's
    point) on a plane: the plane pushes the sphere along its normal; a cylinder rim touches at
    its lowest point."""
    centre = traj.point(c["sphere"], c["at"])
    if c["plane"] == "ground":
        normal = np.asarray(c["normal"], float)
    else:
        R = traj.poses()[0][:, model.member_names.index(c["plane"])]
        normal = np.einsum("tij,j->ti", R, model.member(c["plane"]).direction_to_local(c["normal"]))
    push = np.broadcast_to(normal, (len(traj), traj.dim))
    touch = centre
    if c.get("rim_radius", 0) > 0:                     # a cylinder rim's lowest point
        axis = traj.point(c["sphere"], np.add(c["at"], c["axis"])) - centre
        w = push - np.sum(push * axis, axis=1, keepdims=True) * axis
        touch = centre - c["rim_radius"] * w / np.maximum(np.linalg.norm(w, axis=1, keepdims=True), 1e-12)
    return centre, push, touch - c["radius"] * push


def _gap_normals(model, traj, k: int, member: str, other: str, cache: dict, eps: float = 1e-7) -> np.ndarray:
    """``(n_t, dim)`` unit normals of contact ``k`` (against a box, a capsule, or edges
    crossing), pointing towards ``member`` from ``other``, from the model's own gap: its
    central differences when ``member`` (or, on the ground, ``other``) is translated along
    each world axis (exact within a face or region: the gap is then linear in a
    translation).  ``cache`` keeps every contact's differences per translated member."""
    moved, sign = (member, 1.0) if member != "ground" else (other, -1.0)
    if moved not in cache:
        layout = model.layout
        rows = [layout.nodes[i].index for i in layout.slots[moved] if layout.nodes[i].is_point]
        q = np.asarray(traj.q, float)
        p = np.asarray(traj.p if getattr(traj, "p", None) is not None else model.p0, float).reshape(-1, 1)
        diff = np.zeros((len(q), model.nk, model.dim))
        for axis in range(model.dim):
            step = np.zeros(model.nq)
            step[[r + axis for r in rows]] = eps
            diff[:, :, axis] = (gaps_of(model, q + step, p) - gaps_of(model, q - step, p)) / (2 * eps)
        cache[moved] = diff
    out = sign * cache[moved][:, k]
    return out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-300)


def _basic_points(member) -> list[np.ndarray]:
    """Local positions of a member's basic points: ``r̄_i`` and ``r̄_i + x̄_k`` for each later
    point slot (slot k ≥ 1 holds column k − 1 of X̄)."""
    local = member.rigid
    return [local.rbar_i] + [local.rbar_i + local.Xbar[:, s - 1] for s in member.ctype.point_slots if s >= 1]
