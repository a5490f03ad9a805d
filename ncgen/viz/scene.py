"""What to draw of a trajectory, frame by frame: plain NumPy arrays, no matplotlib.

* bars: segments between their two ends, ``(n_t, n_bars, 2, dim)``;
* bodies: the frame (centre of mass and the rotation's columns as axes) and the basic
  points of the body (``r_i``, ``r_j``, ... : the points its natural coordinates name);
* point members: their positions; markers: their positions;
* ground-fixed basic points: constant positions, drawn as anchors.
Positions in m, world frame.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ncgen.errors import NcgenError


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

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Smallest and largest coordinate over all frames and drawn things."""
        clouds = [a.reshape(-1, self.dim) for a in (self.bars, self.body_origins, self.body_points,
                                                   self.points, self.markers, self.anchors) if a.size]
        allpts = np.concatenate(clouds) if clouds else np.zeros((1, self.dim))
        return allpts.min(axis=0), allpts.max(axis=0)


def scene(traj) -> Scene:
    """The scene of ``traj`` (it needs its model: see ``Trajectory.load(path, model=...)``)."""
    model = traj.model
    if model is None:
        raise NcgenError("drawing a trajectory needs its model; this one was loaded without it: "
                         "use Trajectory.load(path, model=model)")
    n, d = len(traj), traj.dim
    members = [model.member(name) for name in model.member_names]
    bars = [m for m in members if m.kind == "bar"]
    bodies = [m for m in members if m.kind == "body"]
    points = [m for m in members if m.kind == "point"]
    bar_ends = [np.stack([traj.point(m.name, m.rigid.rbar_i),
                          traj.point(m.name, m.rigid.rbar_i + m.rigid.Xbar[:, 0])], axis=1) for m in bars]
    body_points = [traj.point(m.name, local) for m in bodies for local in _basic_points(m)]
    R, p = traj.poses() if bodies else (np.zeros((n, 0, d, d)), np.zeros((n, 0, d)))
    index = [model.member_names.index(m.name) for m in bodies]
    return Scene(
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
    )


def _basic_points(member) -> list[np.ndarray]:
    """Local positions of a member's basic points: ``r̄_i`` and ``r̄_i + x̄_k`` for each later
    point slot (slot k ≥ 1 holds column k − 1 of X̄)."""
    local = member.rigid
    return [local.rbar_i] + [local.rbar_i + local.Xbar[:, s - 1] for s in member.ctype.point_slots if s >= 1]
