"""``animate(traj, path)``: the motion as a GIF (Pillow) or an MP4 (ffmpeg).

Bars are drawn as segments, bodies as their frame (red/green/blue axes at the centre of
mass) and basic points, point members and markers as dots, ground-fixed points as grey
triangles; planar systems on equal-scale 2D axes, spatial ones in a 3D cube around the
whole motion.  At most ``max_frames`` frames are drawn (every k-th output step); the frame
rate makes playback real time when that needs at most ``MAX_FPS`` frames per second.
"""
from __future__ import annotations

import math
from pathlib import Path

from matplotlib.animation import FFMpegWriter, PillowWriter

from ncgen.errors import NcgenError
from ncgen.files import atomic_path
from ncgen.progress import bar
from ncgen.viz.draw import SceneArtists, figure, scene_axes
from ncgen.viz.scene import scene

MAX_FPS = 30


def animate(traj, path, *, max_frames: int = 150, fps: float | None = None, size: float = 6.0,
            dpi: int = 80) -> Path:
    """Write the animation of ``traj`` to ``path`` (``.gif``, or ``.mp4`` if ffmpeg is
    installed); returns the path."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".gif", ".mp4"):
        raise NcgenError(f"animate: {path}: expected a .gif or .mp4 file name")
    if suffix == ".mp4" and not FFMpegWriter.isAvailable():
        raise NcgenError(f"animate: {path}: writing MP4 needs ffmpeg on PATH; install it or write a .gif")
    sc = scene(traj)
    step = max(1, math.ceil(len(traj) / max_frames))
    frames = list(range(0, len(traj), step))
    if frames[-1] != len(traj) - 1:
        frames.append(len(traj) - 1)
    if fps is None:
        dt = float(traj.t[min(step, len(traj) - 1)] - traj.t[0]) if len(traj) > 1 else 1.0
        fps = min(MAX_FPS, 1.0 / dt) if dt > 0 else MAX_FPS
    fig = figure(size, size)
    ax = scene_axes(fig, sc)
    artists = SceneArtists(ax, sc)
    fig.suptitle(traj.model_name)
    writer = PillowWriter(fps=fps) if suffix == ".gif" else FFMpegWriter(fps=fps)

    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp, writer.saving(fig, str(tmp), dpi), \
            bar(len(frames), f"rendering {path.name}", unit="frame") as progress:
        for k in frames:                      # one draw per frame (FuncAnimation would draw twice)
            artists.show(k, float(traj.t[k]))
            writer.grab_frame()
            progress.update(1)
    return path
