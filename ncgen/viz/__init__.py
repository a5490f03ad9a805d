"""ncgen.viz: pictures of trajectories (matplotlib, Agg canvas; imported only when used).

* :func:`plot` — PNG with energy drift, constraint drift and chosen points;
* :func:`animate` — GIF (or MP4 with ffmpeg) of the moving system.
"""


def plot(traj, path, points=None, **kwargs):
    """See :func:`ncgen.viz.plots.plot`."""
    from ncgen.viz.plots import plot as _plot
    return _plot(traj, path, points, **kwargs)


def animate(traj, path, **kwargs):
    """See :func:`ncgen.viz.animation.animate`."""
    from ncgen.viz.animation import animate as _animate
    return _animate(traj, path, **kwargs)


__all__ = ["animate", "plot"]
