"""The contact broad phase: time per step against the number of sphere pairs and of close pairs.

Scenes (those of benchmarks/contact.py): the sparse scene of N = 20, 50, 100, 200 frictional
spheres at rest on the ground 0.2 m apart (N floor contacts, N (N − 1) / 2 sphere pairs, none
close; N = 200 runs only where the contact solves' blocks are sized by the active rows: before,
3 ND² doubles with ND = 3 × 20 100 rows, 87 GB, refused) and the heap of 20 spheres with friction dropped onto the ground (190 pairs, the close
ones touching or about to); h = 1 ms, ``--t-end`` s (default 0.2), ncgen's nonsmooth stepper on
the contact library's tables (``kernels="tables"``, what ``kernels="auto"`` takes; ``--kernels
flat`` times the models' own packages instead, compiled first).

Each tree (this one and, with ``--peer ROOT``, another checkout, e.g. /work/main: the broad
phase before) runs in its own worker process with its own compile cache; the runs alternate,
this tree's then the peer's, ``--rounds`` times, the stepping CPU time of each
(``info["stepping_cpu_time"]``) kept; printed: per scene the pairs, the candidate sphere pairs of
a select at limit 0 (the pairs whose broad-phase boxes overlap on every axis, what the grid of
ncgen_contact_pairs.h takes, and on the axis the centres spread most, what the one-axis sweep took:
from the samples' positions with the header's box formula, mean over the samples), the close pairs
(sphere pairs whose bounding spheres are within one radius at any sample of the run), the CPU time per
step (min / median), the contacts with an impulse (mean and max over the samples: the active
rows are 3 per contact), the ratio this / peer (min / median of the per-round ratios), and whether
the two trees' trajectories (q and v at every 10 ms sample, and the contact forces: the
impulses summed over each sample interval) are bit-identical.  Then least-squares fits of each tree's
median time per step: t = c0 + c1 N + c2 pairs + c3 close pairs over the scenes (c2: what a far
pair still costs per step), and t = c0 + c1 N + c2 N^1.5 over the sparse scenes.

    python benchmarks/broad_phase.py [--sizes 20 50 100 200] [--heap 20] [--rounds 5] [--peer /work/main]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
H = 1e-3

WORKER = r"""
import hashlib, json, sys, warnings
import numpy as np
sys.path.insert(0, {bench!r})
import contact as B
import ncgen as nc
models = {{}}
for line in sys.stdin:
    cmd = json.loads(line)
    key = (cmd["scene"], cmd["n"])
    if key not in models:
        models[key] = B.sparse(cmd["n"]) if cmd["scene"] == "sparse" else B.heap(cmd["n"], False)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            nc.simulate(models[key], 0.01, 0.01, method="stepper", substeps=10, kernels=cmd["kernels"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tr = nc.simulate(models[key], cmd["t_end"], 0.01, method="stepper", substeps=10, kernels=cmd["kernels"])
    digest = hashlib.sha256(b"".join(np.ascontiguousarray(x).tobytes() for x in
                                     (tr.q, tr.v, tr.contact_normal, tr.contact_tangent))).hexdigest()
    pos = tr.q.reshape(len(tr.t), -1, 3)
    d = np.linalg.norm(pos[:, :, None, :] - pos[:, None, :, :], axis=-1)
    iu = np.triu_indices(pos.shape[1], 1)
    close = int(np.sum((d[:, iu[0], iu[1]] < 3 * B.HEAP_R).any(axis=0)))
    loaded = np.count_nonzero(tr.contact_normal[1:], axis=1)
    # the broad phase's boxes at a select of limit 0 without rates (ncgen_contact_pairs.h: L = R + 1e-6,
    # half-width R + 2 (L / 2 + 1e-6 R), kappa = 1): pairs overlapping on every axis (the grid's
    # candidates) and on the axis the centres spread most (the one-axis sweep's), mean over the samples
    w = B.HEAP_R + 2 * ((B.HEAP_R + 1e-6) / 2 + 1e-6 * B.HEAP_R)
    sep = np.abs(pos[:, :, None, :] - pos[:, None, :, :])[:, iu[0], iu[1]] <= 2 * w
    axis = np.argmax(np.ptp(pos, axis=1), axis=1)
    grid = float(sep.all(axis=-1).sum(axis=1).mean())
    one = float(np.mean([sep[k, :, a].sum() for k, a in enumerate(axis)]))
    print(json.dumps({{"cpu": tr.info["stepping_cpu_time"], "digest": digest, "close": close,
                      "active": float(loaded.mean()), "active_max": int(loaded.max()),
                      "cand_grid": grid, "cand_axis": one}}), flush=True)
"""


def worker(root: Path, cache: str) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(root), "NCGEN_CACHE_DIR": cache}
    return subprocess.Popen([sys.executable, "-c", WORKER.format(bench=str(root / "benchmarks"))], cwd=root, env=env,
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)


def ask(proc: subprocess.Popen, **cmd) -> dict:
    proc.stdin.write(json.dumps(cmd) + "\n")
    proc.stdin.flush()
    line = proc.stdout.readline()
    if not line:
        raise RuntimeError(f"the worker of {proc.args} ended (exit {proc.wait()})")
    return json.loads(line)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="*", default=[20, 50, 100, 200], help="spheres of the sparse scenes")
    ap.add_argument("--heap", type=int, default=20, help="spheres of the heap (0: none)")
    ap.add_argument("--t-end", type=float, default=0.2, help="simulated time per run, s")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--kernels", default="tables", choices=["tables", "flat"])
    ap.add_argument("--peer", type=Path, help="another ncgen checkout, run alternately")
    ap.add_argument("--cache", default=os.environ.get("NCGEN_CACHE_DIR", "/tmp/ncgen_broad_phase"),
                    help="this tree's compile cache (the peer's: the same with '_peer')")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from common import machine
    print(machine())
    trees = {"this": worker(ROOT, args.cache)}
    if args.peer:
        trees["peer"] = worker(args.peer.resolve(), args.cache + "_peer")
    scenes = [("sparse", n) for n in args.sizes] + ([("heap", args.heap)] if args.heap else [])
    steps = int(round(args.t_end / H))
    rows, peer_rows = [], []
    for scene, n in scenes:
        res = {name: [] for name in trees}
        for _ in range(args.rounds):
            for name, proc in trees.items():
                res[name].append(ask(proc, scene=scene, n=n, t_end=args.t_end, kernels=args.kernels))
        pairs = n * (n - 1) // 2
        t = {name: np.array([r["cpu"] for r in rs]) / steps * 1e3 for name, rs in res.items()}
        close, active, amax, cg, ca = (res["this"][0][k] for k in ("close", "active", "active_max", "cand_grid",
                                                                   "cand_axis"))
        line = (f"{scene} N = {n:4d}: pairs {pairs:6d}, candidate sphere pairs at limit 0 (mean) {cg:.1f} on every "
                f"axis, {ca:.1f} on one, close pairs {close:4d}, contacts with an impulse per sample "
                f"{active:.1f} (max {amax}, active rows {3 * active:.1f}); this: ms/step min {t['this'].min():.4f} "
                f"median {np.median(t['this']):.4f}")
        if "peer" in t:
            ratio = t["this"] / t["peer"]
            same = {r["digest"] for r in res["this"] + res["peer"]}
            line += (f"; peer: min {t['peer'].min():.4f} median {np.median(t['peer']):.4f}; RATIO this / peer min "
                     f"{ratio.min():.2f} median {np.median(ratio):.2f}; trajectories "
                     f"{'bit-identical' if len(same) == 1 else 'DIFFERENT'}")
        print(line + f"; load {os.getloadavg()[0]:.2f}", flush=True)
        rows.append((n, pairs, close, float(np.median(t["this"]))))
        if "peer" in t:
            peer_rows.append((n, pairs, close, float(np.median(t["peer"]))))
    for proc in trees.values():
        proc.stdin.close()
        proc.wait()
    for name, rs in (("this tree", rows), ("peer", peer_rows)):
        fit(name, rs)
    return 0


def fit(name: str, rows: list) -> None:
    """Least squares of the medians: t = c0 + c1 N + c2 pairs + c3 close pairs, and over the sparse
    scenes (no close pair) t = c0 + c1 N + c2 N^1.5: the term the one-axis sweep's candidates give."""
    if len(rows) >= 4:
        A = np.array([[1.0, n, p, c] for n, p, c, _ in rows])
        coef, *_ = np.linalg.lstsq(A, np.array([r[3] for r in rows]), rcond=None)
        print(f"fit ({name}, medians) ms/step = {coef[0]:.4g} + {coef[1]:.3g} N + {coef[2]:.3g} pairs + "
              f"{coef[3]:.3g} close pairs: a far pair costs {coef[2] * 1e6:.1f} ns per step")
    sparse = [r for r in rows if r[2] == 0]
    if len(sparse) >= 3:
        A = np.array([[1.0, n, n**1.5] for n, *_ in sparse])
        coef, *_ = np.linalg.lstsq(A, np.array([r[3] for r in sparse]), rcond=None)
        nmax = max(r[0] for r in sparse)
        print(f"fit ({name}, sparse scenes) ms/step = {coef[0]:.4g} + {coef[1]:.3g} N + {coef[2]:.3g} N^1.5: at N = "
              f"{nmax} the N^1.5 term is {coef[2] * nmax**1.5:.4f} ms of {coef[1] * nmax:.4f} (N)")


if __name__ == "__main__":
    raise SystemExit(main())
