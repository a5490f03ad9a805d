"""``plot_solution(sol, path)``: a PNG (PDF, SVG) of an optimal trajectory — snapshots of
the motion with the marker paths, the inputs (piecewise constant, with their bounds), the
marker coordinates over time and the constraint drift on the nodes.  Matplotlib on the Agg
canvas (:mod:`ncgen.viz.draw`)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ncgen.errors import NcgenError
from ncgen.files import atomic_path

FORMATS = (".png", ".pdf", ".svg")


def plot_solution(sol, path, *, snapshots: int = 8, dpi: int = 100) -> Path:
    """Write the four-panel summary of ``sol`` (an :class:`OptimalTrajectory`) to ``path``;
    ``snapshots``: how many configurations to draw.  Returns the path written."""
    from ncgen.viz.draw import figure

    path = Path(path)
    if path.suffix.lower() not in FORMATS:
        raise NcgenError(f"plot: {path}: expected a file name ending in {', '.join(FORMATS)}")
    fig = figure(12, 8)
    _motion_panel(fig, sol, snapshots)
    _inputs_panel(fig.add_subplot(222), sol)
    _markers_panel(fig.add_subplot(223), sol)
    _drift_panel(fig.add_subplot(224), sol)
    s = sol.stats
    fig.suptitle(f"{sol.model_name}: optimal trajectory ({s.method}, N = {sol.N})")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format=path.suffix.lower()[1:])
    return path


def _motion_panel(fig, sol, snapshots: int) -> None:
    """Top left: ``snapshots`` configurations, fading in with time, and the marker paths."""
    from ncgen.viz.draw import SceneArtists, scene_axes
    from ncgen.viz.scene import scene

    t, sc = sol.t, scene(sol)
    ax = scene_axes(fig, sc, 221)
    frames = np.unique(np.linspace(0, len(t) - 1, max(2, snapshots)).round().astype(int))
    for n, k in enumerate(frames):
        artists = SceneArtists(ax, sc).show(k, t[k])
        for a in artists[:-1]:
            a.set_alpha(0.2 + 0.8 * n / max(1, len(frames) - 1))
    for j, name in enumerate(sol.marker_names):
        ax.plot(*sol.markers[:, j].T, lw=1, label=name)
    ax.set_title(f"motion: {len(frames)} snapshots, t = {t[0]:g} ... {t[-1]:.4g} s")
    if sol.marker_names:
        ax.legend(loc="best", fontsize="x-small")


def _inputs_panel(ax, sol) -> None:
    """The inputs, piecewise constant, with their bounds dotted."""
    t = sol.t
    bounds = sol.nlp.ocp.u_bounds if sol.nlp is not None else None
    names = [n if s == 1 else f"{n}[{k}]" for n, s in zip(sol.input_names, _sizes(sol)) for k in range(s)]
    for i, name in enumerate(names):
        line, = ax.step(t, sol.u[:, i], where="post", label=name)
        if bounds is not None:
            for b in bounds[:, i]:
                if np.isfinite(b):
                    ax.axhline(b, color=line.get_color(), ls=":", lw=1)
    ax.set_title("inputs (piecewise constant; dotted: bounds)")
    ax.set_xlabel("t (s)")
    if names:
        ax.legend(loc="best", fontsize="small")
    ax.grid(True, alpha=0.3)


def _markers_panel(ax, sol) -> None:
    """The markers' coordinates (m) over time."""
    for j, name in enumerate(sol.marker_names):
        for c, style in zip(range(sol.dim), ("-", "--", ":")):
            ax.plot(sol.t, sol.markers[:, j, c], style, label=f"{name} {'xyz'[c]}")
    ax.set_title("markers")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("position (m)")
    if sol.marker_names:
        ax.legend(loc="best", fontsize="x-small", ncol=sol.dim)
    ax.grid(True, alpha=0.3)


def _drift_panel(ax, sol) -> None:
    """The constraint drift on the nodes (both levels), with the solver's status."""
    for values, label in ((sol.constraint_residual, "|phi|_inf (m^2)"),
                          (sol.velocity_residual, "|A v + phi_t|_inf (m^2/s)")):
        ax.semilogy(sol.t, np.where(values > 0, values, np.nan), label=label)
    s = sol.stats
    ax.set_title(f"constraint drift on the nodes\n{s.status}, {s.iterations} iterations, "
                 f"objective {s.objective:.5g}, max defect {s.max_defect:.1e}", fontsize="small")
    ax.set_xlabel("t (s)")
    ax.legend(loc="best", fontsize="small")
    ax.grid(True, which="both", alpha=0.3)


def _sizes(sol) -> list[int]:
    if sol.model is not None:
        return list(sol.model.input_sizes)
    return [1] * len(sol.input_names)
