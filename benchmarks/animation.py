"""Pictures of a run: wall time of ``nc.viz.animate`` (GIF) against the plain matplotlib way of
writing the same frames, and the size and time of the HTML page (issue 27: a GIF of a 5 s
run of an example in at most 3 s).

For each example: simulate 5 s (output step 0.01 s), then, interleaved, ``--repeat`` times:
ncgen's ``animate`` (axes drawn once, each frame blits what moves, one GIF palette, frame
count fitted to its 2 s budget) and the peer, matplotlib's ``PillowWriter`` grabbing the
same number of frames of the same artists with a full redraw each (what ``animate`` did
before).  Prints the frames, the min and median times and their ratios, then
``traj.to_html`` time and page size.  matplotlib is imported before timing.

    python benchmarks/animation.py [--examples heavy_top tensegrity chain slider_crank] [--repeat 3] [--smoke]
"""
from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))
import ncgen as nc  # noqa: E402
from common import machine  # noqa: E402

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def peer(traj, path: Path, frames: int) -> None:
    """The same artists written with PillowWriter, one full redraw per frame."""
    from matplotlib.animation import PillowWriter

    from ncgen.viz.animation import frame_steps
    from ncgen.viz.draw import SceneArtists, figure, scene_axes
    from ncgen.viz.scene import scene

    sc = scene(traj)
    fig = figure(6.0, 6.0)
    ax = scene_axes(fig, sc)
    artists = SceneArtists(ax, sc)
    writer = PillowWriter(fps=15)
    with writer.saving(fig, str(path), 80):
        for k in frame_steps(0, len(traj) - 1, frames):
            artists.show(k, float(traj.t[k]))
            writer.grab_frame()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--examples", nargs="+", default=["heavy_top", "tensegrity", "chain", "slider_crank"])
    ap.add_argument("--t-end", type=float, default=5.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--smoke", action="store_true", help="one example, 0.5 s, one run (CI)")
    args = ap.parse_args(argv)
    if args.smoke:
        args.examples, args.t_end, args.repeat = ["slider_crank"], 0.5, 1
    print(machine())
    import matplotlib.figure  # noqa: F401  (imported before any timing)
    from PIL import Image

    from ncgen.viz import animate
    out = Path(tempfile.mkdtemp(prefix="ncgen_bench_anim_"))
    for name in args.examples:
        model = nc.System.from_toml(EXAMPLES / f"{name}.toml").build()
        traj = nc.simulate(model, args.t_end, 0.01)
        print(f"\n=== {name}: {args.t_end:g} s, {len(traj)} samples")
        ours, theirs, frames = [], [], 0
        for _ in range(args.repeat):                      # interleaved
            start = time.perf_counter()
            animate(traj, out / f"{name}.gif", progress=False)
            ours.append(time.perf_counter() - start)
            frames = Image.open(out / f"{name}.gif").n_frames
            start = time.perf_counter()
            peer(traj, out / f"{name}_peer.gif", frames)
            theirs.append(time.perf_counter() - start)
        print(f"frames: {frames}")
        print(f"ncgen animate:            min {min(ours):.3f} s, median {statistics.median(ours):.3f} s")
        print(f"matplotlib PillowWriter:  min {min(theirs):.3f} s, median {statistics.median(theirs):.3f} s")
        print(f"RATIO PillowWriter / ncgen animate: min {min(theirs) / min(ours):.2f}, "
              f"median {statistics.median(theirs) / statistics.median(ours):.2f}")
        start = time.perf_counter()
        page = traj.to_html(out / f"{name}.html")
        print(f"to_html: {time.perf_counter() - start:.3f} s, {page.stat().st_size / 1e6:.2f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
