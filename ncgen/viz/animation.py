"""``animate(traj, path)``: the motion as a GIF (Pillow) or an MP4 (ffmpeg).

The shapes are those of the HTML page (:mod:`ncgen.viz.geometry`) as line drawings: bars as
thick segments between their ends, bodies as the outlines of their shapes (the box of the
same inertia by default; a body drawn by a mesh as its frame, red/green/blue axes), springs
as coils, cables as lines (dashed grey while slack), markers with their trails, contact
spheres and planes, ground-fixed points as grey triangles; planar systems on equal-scale 2D
axes, spatial ones in a 3D cube around the whole motion.

Speed: the axes are drawn once and each frame only redraws what moves (blitting on the Agg
canvas); GIF frames share one palette.  At most ``max_frames`` frames are drawn (every k-th
output step), fewer if the first frames show that drawing them all would take longer than
``budget`` seconds; the frame rate makes playback real time when that needs at most
``MAX_FPS`` frames per second.  A progress bar shows on a terminal (``progress``).
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from matplotlib.animation import FFMpegWriter

from ncgen.errors import NcgenError
from ncgen.files import atomic_path
from ncgen.runtime.simulation_progress import Progress
from ncgen.validation import as_scalar
from ncgen.viz.draw import SceneArtists, figure, scene_axes
from ncgen.viz.scene import scene

MAX_FPS = 30
#: Fewest frames an animation is cut down to by the time budget.
MIN_FRAMES = 24
#: Frames timed before the count is fitted to the budget.
PROBE = 5
#: Time of a frame drawn and encoded over the time of drawing it (measured: about 1.5 for GIFs).
ENCODING = 1.7


def frame_steps(first: int, last: int, count: int) -> list[int]:
    """``count`` (at most ``last − first + 1``) evenly spaced indices from ``first`` to ``last``."""
    count = max(1, min(count, last - first + 1))
    return sorted({int(round(x)) for x in np.linspace(first, last, count)})


def animate(traj, path, *, max_frames: int = 150, fps: float | None = None, size: float = 6.0,
            dpi: int = 80, budget: float | None = 2.0, progress: bool | None = None) -> Path:
    """Write the animation of ``traj`` to ``path`` (``.gif``, or ``.mp4`` if ffmpeg is
    installed); ``budget``: seconds the drawing should take at most (None: no limit; the
    frame count is lowered to fit, down to ``MIN_FRAMES``); returns the path."""
    path = Path(path)
    suffix = path.suffix.lower()
    _check_arguments(traj, path, max_frames, fps, size, dpi, budget)
    ffmpeg = ffmpeg_executable(path) if suffix == ".mp4" else None
    began = time.monotonic()
    sc = scene(traj)
    n = len(traj)
    frames = frame_steps(0, n - 1, max_frames)
    fig = figure(size, size)
    fig.set_dpi(dpi)
    ax = scene_axes(fig, sc)
    artists = SceneArtists(ax, sc)
    artists.prefix = f"{traj.model_name}: "
    moving = artists.show(0, float(traj.t[0]))
    for artist in moving:
        artist.set_animated(True)
    canvas = fig.canvas
    canvas.draw()
    background = canvas.copy_from_bbox(fig.bbox)
    images, start = [], time.monotonic()
    bar = Progress(float(traj.t[0]), float(traj.t[-1]), mode=progress, label="animation ")
    k_done = 0
    while k_done < len(frames):
        k = frames[k_done]
        canvas.restore_region(background)
        for artist in artists.show(k, float(traj.t[k])):
            ax.draw_artist(artist) if artist.axes is ax else fig.draw_artist(artist)
        images.append(np.asarray(canvas.buffer_rgba())[..., :3].copy())
        k_done += 1
        if budget is not None and k_done == PROBE and len(frames) > MIN_FRAMES:
            now = time.monotonic()
            per_frame = (now - start) / PROBE * ENCODING
            fit = max(MIN_FRAMES, PROBE + int((budget - (now - began)) / max(per_frame, 1e-6)))
            if fit < len(frames):
                done = frames[:PROBE]
                frames = done + frame_steps(done[-1] + 1, n - 1, fit - PROBE)
        bar.update(float(traj.t[k]))
    bar.close()
    if fps is None:
        span = float(traj.t[-1] - traj.t[0]) if n > 1 else 0.0
        fps = min(MAX_FPS, (len(frames) - 1) / span) if span > 0 else MAX_FPS
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        if suffix == ".gif":
            _write_gif(images, tmp, fps)
        else:
            _write_mp4(images, tmp, fps, ffmpeg)
    return path


def _check_arguments(traj, path: Path, max_frames, fps, size, dpi, budget) -> None:
    """Refuse, naming it, a file type other than GIF or MP4, an option out of its range, or
    an empty trajectory (:func:`animate`'s arguments)."""
    if path.suffix.lower() not in (".gif", ".mp4"):
        raise NcgenError(f"animate: {path}: expected a .gif or .mp4 file name")
    if fps is not None and not (as_scalar(fps, "animate: fps") > 0):
        raise NcgenError(f"animate: fps: expected a positive number of frames per second, got {fps!r}")
    if isinstance(max_frames, bool) or not isinstance(max_frames, (int, np.integer)) or max_frames < 2:
        raise NcgenError(f"animate: max_frames: expected an integer >= 2 (frames of the animation), got {max_frames!r}")
    for value, what, unit in ((size, "size", "the figure's width in inches"), (dpi, "dpi", "dots per inch")) + \
            (() if budget is None else ((budget, "budget", "seconds of drawing, or None"),)):
        if not as_scalar(value, f"animate: {what}") > 0:
            raise NcgenError(f"animate: {what}: expected a positive number ({unit}), got {value!r}")
    if not len(traj.t):
        raise NcgenError(f"animate: {path}: the trajectory is empty (no samples): nothing to show")


def ffmpeg_executable(path) -> str:
    """The ffmpeg binary for an MP4: matplotlib's (``animation.ffmpeg_path``, on PATH by
    default), else the one the ``imageio-ffmpeg`` wheel ships (``pip install 'ncgen[viz]'``)."""
    from matplotlib import rcParams

    if FFMpegWriter.isAvailable():
        return rcParams["animation.ffmpeg_path"]
    try:
        import imageio_ffmpeg
    except ImportError:
        raise NcgenError(f"animate: {path}: writing MP4 needs ffmpeg: pip install 'ncgen[viz]' "
                         "(imageio-ffmpeg ships one), put ffmpeg on PATH, or write a .gif") from None
    return imageio_ffmpeg.get_ffmpeg_exe()


def _write_gif(images: list[np.ndarray], path: Path, fps: float) -> None:
    """Frames as a looping GIF; one palette, from the first, middle and last frames."""
    from PIL import Image

    probe = np.concatenate([images[0], images[len(images) // 2], images[-1]], axis=1)
    palette = Image.fromarray(probe).quantize(colors=128, method=Image.Quantize.FASTOCTREE)
    frames = [Image.fromarray(im).quantize(palette=palette, dither=Image.Dither.NONE) for im in images]
    frames[0].save(path, format="GIF", save_all=True, append_images=frames[1:], loop=0,
                   duration=max(20, int(round(1000 / fps))), disposal=1)


def _write_mp4(images: list[np.ndarray], path: Path, fps: float, ffmpeg: str) -> None:
    """Frames as an H.264 MP4 through the binary ``ffmpeg`` (:func:`ffmpeg_executable`)."""
    import subprocess

    h, w = images[0].shape[:2]
    cmd = [ffmpeg, "-y", "-loglevel", "error", "-f", "rawvideo", "-pix_fmt", "rgb24",
           "-s", f"{w}x{h}", "-r", f"{fps:g}", "-i", "-", "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2",
           "-pix_fmt", "yuv420p", "-vcodec", "libx264", "-f", "mp4", str(path)]
    run = subprocess.run(cmd, input=b"".join(np.ascontiguousarray(im).tobytes() for im in images),
                         capture_output=True)
    if run.returncode:
        raise NcgenError(f"animate: {path}: ffmpeg failed: {run.stderr.decode(errors='replace').strip()}")
