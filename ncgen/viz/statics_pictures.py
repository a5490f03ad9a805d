"""Pictures of statics results: the equilibrium configuration and mode shapes (PNG).

Each mode is drawn at its two extreme deflections (``±`` amplitude, solid and faded) over
the equilibrium, one panel per mode, from :meth:`ncgen.analysis.modes.Modes.trajectory`."""
from __future__ import annotations

import math
from pathlib import Path

from ncgen.files import atomic_path
from ncgen.viz.animation import animate
from ncgen.viz.draw import SceneArtists, figure, scene_axes
from ncgen.viz.scene import scene


def plot_modes(modes, path, *, count: int = 6, amplitude: float | None = None, size: float = 3.5,
               dpi: int = 100) -> Path:
    """PNG with the first ``count`` vibration modes of ``modes`` (zero modes skipped)."""
    path = Path(path)
    picks = [i for i, k in enumerate(modes.kind) if k != "zero"][:count]
    cols = min(3, max(1, len(picks)))
    rows = max(1, math.ceil(len(picks) / cols))
    fig = figure(size * cols, size * rows)
    grid = fig.add_gridspec(rows, cols)
    for n, i in enumerate(picks):
        traj = modes.trajectory(i, amplitude=amplitude, cycles=1, frames_per_cycle=4)
        sc = scene(traj)
        ax = scene_axes(fig, sc, grid[n])
        SceneArtists(ax, sc).show(1, 0.0)
        faded = SceneArtists(ax, sc)
        faded.show(3, 0.0)
        for artist in faded.bars:
            artist.set_alpha(0.35)
        f = modes.frequencies[i]
        label = f"{f:.4g} Hz" if modes.kind[i] == "vibration" else "unstable"
        ax.set_title(f"mode {i + 1}: {label}", fontsize=9)
    if not picks:
        fig.suptitle("no vibration modes")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
    return path


def plot_configuration(model, q, path, *, title: str = "", size: float = 5.0, dpi: int = 100) -> Path:
    """PNG of ``model`` in configuration ``q``."""
    import numpy as np

    from ncgen.runtime.trajectory import Trajectory
    path = Path(path)
    traj = Trajectory.from_states(model, np.zeros(1), np.asarray(q)[None, :], np.zeros((1, model.nq)),
                                  np.zeros((1, model.nc)), np.zeros((1, model.nu)), model.p0,
                                  {"method": "configuration", "complete": True})
    sc = scene(traj)
    fig = figure(size, size)
    ax = scene_axes(fig, sc)
    SceneArtists(ax, sc).show(0, 0.0)
    ax.set_title(title or model.name)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
    return path


def animate_mode(modes, index: int, path, *, amplitude: float | None = None, cycles: int = 2,
                 frames_per_cycle: int = 40, **kwargs):
    """Write an animation (``.gif``/``.mp4``, :func:`ncgen.viz.animate`) of mode ``index``
    (0-based) of ``modes`` (:func:`ncgen.modes`): the motion of
    :meth:`~ncgen.analysis.modes.Modes.trajectory`, drawn on the constraint manifold for
    ``cycles`` periods; ``amplitude`` in m of the largest coordinate motion (default 5 % of
    the system's size)."""
    return animate(modes.trajectory(index, amplitude=amplitude, cycles=cycles,
                                    frames_per_cycle=frames_per_cycle), path, **kwargs)
