"""ncgen.viz: pictures of trajectories (matplotlib, Agg canvas; imported only when used).

* :func:`plot` — PNG with energy drift, constraint drift and chosen points;
* :func:`animate` — GIF (or MP4 through ffmpeg or imageio-ffmpeg) of the moving system;
* :func:`to_html` — one self-contained, offline HTML page with an interactive 3D view and
  plots (also ``traj.to_html(path)``).
"""


def plot(traj, path, points=None, **kwargs):
    """See :func:`ncgen.viz.summary_plot.plot`."""
    from ncgen.viz.summary_plot import plot as _plot
    return _plot(traj, path, points, **kwargs)


def animate(traj, path, **kwargs):
    """See :func:`ncgen.viz.animation.animate`."""
    from ncgen.viz.animation import animate as _animate
    return _animate(traj, path, **kwargs)


def to_html(traj, path, **kwargs):
    """See :func:`ncgen.viz.html.to_html`."""
    from ncgen.viz.html import to_html as _to_html
    return _to_html(traj, path, **kwargs)


__all__ = ["animate", "plot", "to_html"]
