"""Matplotlib drawing of a :class:`~ncgen.viz.scene.Scene`, with the Agg canvas (no display,
no pyplot, no change to matplotlib's global backend).  Imported only when drawing."""
from __future__ import annotations

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ncgen.reproducible import perpendicular_basis
from ncgen.viz.scene import Scene, tension_rgb

SPRING_COLOR = "tab:green"
CABLE_COLOR = "tab:red"
SLACK_COLOR = "0.6"
TRAIL_COLOR = "tab:gray"
#: Turns of a drawn spring coil, its radius relative to the scene's size.
COIL_TURNS, COIL_RADIUS = 8, 0.02

BAR_COLOR = "tab:blue"
BODY_COLOR = "tab:orange"
AXIS_COLORS = ("tab:red", "tab:green", "tab:blue")
POINT_COLOR = "tab:purple"
MARKER_COLOR = "k"
ANCHOR_COLOR = "0.3"
SPHERE_COLOR = "tab:gray"
PLANE_COLOR = "0.5"
CONTACT_COLOR = "tab:red"


def figure(width: float, height: float) -> Figure:
    """A figure on an Agg canvas."""
    fig = Figure(figsize=(width, height))
    FigureCanvasAgg(fig)
    return fig


def scene_axes(fig: Figure, scene: Scene, position=111):
    """2D axes with equal scales, or 3D axes with a cube box around the whole motion."""
    lo, hi = scene.bounds()
    centre, half = (lo + hi) / 2, max(float(np.max(hi - lo)) / 2, 1e-3) * 1.1
    if scene.dim == 2:
        ax = fig.add_subplot(position)
        ax.set_aspect("equal")
        ax.set_xlim(centre[0] - half, centre[0] + half)
        ax.set_ylim(centre[1] - half, centre[1] + half)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.grid(True, alpha=0.3)
        return ax
    ax = fig.add_subplot(position, projection="3d")
    for set_lim, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre):
        set_lim(c - half, c + half)
    ax.set_box_aspect((1, 1, 1))
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    return ax


class SceneArtists:
    """The artists of one frame of ``scene`` on ``ax``; :meth:`show` moves them to frame k."""

    def __init__(self, ax, scene: Scene):
        self.ax, self.scene = ax, scene
        lo, hi = scene.bounds()
        self.axis_length = 0.12 * max(float(np.max(hi - lo)), 1e-3)
        self.size = max(float(np.max(hi - lo)), 1e-3)
        self.bars = [self._line(color, lw=4) for color in scene.bar_colors]
        self.axes = [[self._line(c, lw=1.5) for c in AXIS_COLORS[:scene.dim]] if not outlined else []
                     for outlined in scene.body_outlined]
        self.outlines = []
        for k, pts, color in scene.outlines:
            if k < 0:
                self.ax.plot(*pts[:, :scene.dim].T, color=color, lw=1)
            else:
                self.outlines.append((k, pts[:, :scene.dim], self._line(color, lw=1.2)))
        self.springs = [self._line(CABLE_COLOR if cable else SPRING_COLOR, lw=1.5 if cable else 1)
                        for cable in scene.spring_cable]
        self.tension_scale = scene.tension_scale()
        if scene.spring_cable.any():
            text = ax.text2D if hasattr(ax, "text2D") else ax.text
            text(0.01, 0.01, f"cable tension: blue 0 N to red {self.tension_scale:.4g} N", transform=ax.transAxes,
                 fontsize=7)
        self.trails = [self._line(TRAIL_COLOR, lw=0.8) for _ in range(scene.markers.shape[1])]
        self.body_points = self._dots(BODY_COLOR, "o", 30)
        self.points = self._dots(POINT_COLOR, "o", 50)
        self.markers = self._dots(MARKER_COLOR, ".", 25)
        if len(scene.anchors):
            self._scatter(scene.anchors, ANCHOR_COLOR, "^", 60)
        self.spheres = [self._line(SPHERE_COLOR, lw=1) for _ in scene.sphere_radii]
        self.contacts = self._dots(CONTACT_COLOR, "x", 60)
        for point, normal in scene.planes:
            self._plane(point, normal)
        self.title = ax.set_title("")
        #: text before the time in the title (e.g. the model's name)
        self.prefix = ""

    def _plane(self, point, normal):
        """A ground plane: its trace across the scene's box (a line in 2D, a square in 3D)."""
        lo, hi = self.scene.bounds()
        half = max(float(np.max(hi - lo)) / 2, 1e-3) * 1.1
        mid = (lo + hi) / 2
        centre = mid - np.dot(mid - point, normal) * normal       # the box centre projected on the plane
        if self.scene.dim == 2:
            t = np.array([-normal[1], normal[0]])
            pts = [centre + s * half * t for s in (-1, 1)]
        else:
            t1, t2 = perpendicular_basis(normal)
            pts = [centre + half * (a * t1 + b * t2) for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1), (-1, -1))]
        self.ax.plot(*np.asarray(pts).T, color=PLANE_COLOR, lw=1, ls="--")

    def _circles(self, centre, radius) -> np.ndarray:
        """A circle (2D) or three great circles (3D) of a sphere, as one polyline."""
        a = np.linspace(0, 2 * np.pi, 41)
        c, s = np.cos(a), np.sin(a)
        if self.scene.dim == 2:
            return centre + radius * np.column_stack([c, s])
        z = np.zeros_like(a)
        rings = [np.column_stack(r) for r in ((c, s, z), (c, z, s), (z, c, s))]
        return centre + radius * np.concatenate(rings)

    def _line(self, color, lw):
        return self.ax.plot(*([[0, 0]] * self.scene.dim), color=color, lw=lw)[0]

    def _dots(self, color, marker, size):
        return self.ax.plot(*([[]] * self.scene.dim), linestyle="none", marker=marker, color=color,
                            markersize=np.sqrt(size))[0]

    def _scatter(self, pts, color, marker, size):
        self.ax.scatter(*pts.T, color=color, marker=marker, s=size, zorder=3)

    def _set(self, artist, pts: np.ndarray) -> None:
        pts = np.asarray(pts).reshape(-1, self.scene.dim)
        artist.set_data(pts[:, 0], pts[:, 1])
        if self.scene.dim == 3:
            artist.set_3d_properties(pts[:, 2])

    def _coil(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """A coil (3D) or zigzag (2D) from ``a`` to ``b``, straight over its first and last tenth."""
        d = b - a
        length = float(np.linalg.norm(d))
        if length == 0:
            return np.array([a, b])
        u = d / length
        s = np.linspace(0.1, 0.9, 16 * COIL_TURNS + 1)
        r = COIL_RADIUS * self.size
        theta = 2 * np.pi * COIL_TURNS * (s - 0.1) / 0.8
        if self.scene.dim == 2:
            side = np.array([-u[1], u[0]])
            body = a + np.outer(s, d) + r * np.outer(np.sin(theta), side)
        else:
            e1, e2 = perpendicular_basis(u)
            body = a + np.outer(s, d) + r * (np.outer(np.cos(theta) - 1, e1) + np.outer(np.sin(theta), e2))
        return np.vstack([a, body, b])

    def show(self, k: int, t: float) -> list:
        s = self.scene
        for line, seg in zip(self.bars, s.bars[k]):
            self._set(line, seg)
        for i, pts, line in self.outlines:
            self._set(line, pts @ s.member_R[k, i].T + s.member_p[k, i])
        for j, line in enumerate(self.springs):
            a, b = s.spring_ends[k, j]
            if s.spring_cable[j]:
                slack = bool(s.spring_slack[k, j])
                line.set_linestyle("--" if slack else "-")
                line.set_color(SLACK_COLOR if slack else tension_rgb(s.spring_tension[k, j], self.tension_scale))
                self._set(line, [a, b])
            else:
                self._set(line, self._coil(a, b))
        for j, line in enumerate(self.trails):
            self._set(line, s.markers[:k + 1, j])
        for lines, origin, R in zip(self.axes, s.body_origins[k], s.body_axes[k]):
            for j, line in enumerate(lines):
                self._set(line, [origin, origin + self.axis_length * R[:, j]])
        self._set(self.body_points, s.body_points[k])
        self._set(self.points, s.points[k])
        self._set(self.markers, s.markers[k])
        for line, centre, radius in zip(self.spheres, s.sphere_centres[k], s.sphere_radii):
            self._set(line, self._circles(centre, radius))
        loaded = s.contact_points[k]
        self._set(self.contacts, loaded[~np.isnan(loaded).any(axis=1)])
        self.title.set_text(f"{self.prefix}t = {t:.3f} s")
        return [*self.bars, *(a for lines in self.axes for a in lines), *(o[2] for o in self.outlines),
                *self.springs, *self.trails, self.body_points, self.points, self.markers, *self.spheres,
                self.contacts, self.title]
