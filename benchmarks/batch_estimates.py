"""Which runs of a batch each error estimate flags: ``simulate_batch(check=True)`` with
``estimate=True`` (the shadow run, steps of 2h) and ``estimate="local"`` (a fifth of the
cost) against the true error, on a set where some runs are bad.

Model: the 5-bar chain of benchmarks/batch.py, released from the rest staircase with random
bar angular velocities (σ per axis from ``--speeds``, ``--per-speed`` runs each: slow runs
the step follows, fast ones it does not).  Fixed steps ``--h`` (fourth-order composition,
the default), output every 0.1 s.  Truth: IDAS (rtol = atol = 1e-11) per run; a run is
**bad** where its largest error in q over the output rows passes 1 % of the model's size
(``ERROR_FRACTION`` × max |q0|, the check's own threshold).  Printed per step and estimate:
the runs flagged (any check, and by the error estimate: ``"estimated error"`` in the
message), the bad runs missed (flagged by no check), the good runs flagged, and the CPU
time of the checked batch.

    python benchmarks/batch_estimates.py             about a minute
    python benchmarks/batch_estimates.py --smoke     seconds (CI)
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

from batch import N_BARS, OUTPUT_DT
from common import chain_system, ends, machine


#: What a run's message says, by the check that flagged it.
REASONS = {"estimate": "estimated error", "energy": "energy", "newton": "iterations per RATTLE step",
           "splits": "had to be split", "failed": "the stepper failed"}


def rates(speeds, per_speed: int, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """``(V0, sigma)``: natural-coordinate rates of random bar angular velocities (no spin about
    a bar), ``per_speed`` runs per σ (rad/s per axis), and each run's σ."""
    rng = np.random.default_rng(seed)
    pts = ends(N_BARS)
    V0, sigma = [], []
    for s in speeds:
        for _ in range(per_speed):
            v_end, v = np.zeros(3), []
            for k in range(N_BARS):
                d = pts[k + 1] - pts[k]
                w = s * rng.normal(size=3)
                w -= (w @ d) / (d @ d) * d
                v_end = v_end + np.cross(w, d)
                v.append(v_end)
            V0.append(np.concatenate(v))
            sigma.append(s)
    return np.array(V0), np.array(sigma)


def true_errors(model, V0, t_end: float) -> np.ndarray:
    """Per run: the largest |q − q_IDAS|∞ over the output rows is measured later; here IDAS's q
    on the output grid (runs × rows × nq)."""
    import ncgen as nc
    return np.array([nc.simulate(model, t_end, OUTPUT_DT, v0=v, rtol=1e-11, atol=1e-11, backend="compiled",
                                 max_steps=10**7).q for v in V0])


def main(argv=None) -> int:
    import ncgen as nc
    from ncgen.runtime.stepper_checks import ERROR_FRACTION

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--speeds", type=float, nargs="+", default=[0.5, 2.0, 5.0, 10.0, 15.0, 20.0])
    p.add_argument("--per-speed", type=int, default=8)
    p.add_argument("--h", type=float, nargs="+", default=[1e-3, 2e-3, 5e-3])
    p.add_argument("--t-end", type=float, default=2.0)
    p.add_argument("--smoke", action="store_true")
    args = p.parse_args(argv)
    if args.smoke:
        args.speeds, args.per_speed, args.h, args.t_end = [0.5, 20.0], 2, [5e-3], 0.5
    print(machine())
    print(f"load average now: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    model = chain_system(N_BARS).build()
    V0, sigma = rates(args.speeds, args.per_speed)
    ref = true_errors(model, V0, args.t_end)
    size = float(np.max(np.abs(model.q0)))
    print(f"{len(V0)} runs of {args.t_end:g} s, sigma {args.speeds} rad/s ({args.per_speed} each); a run is bad "
          f"where its error in q passes {ERROR_FRACTION:g} x {size:.3g} m (against IDAS, rtol 1e-11)")
    for h in args.h:
        unchecked = nc.simulate_batch(model, args.t_end, OUTPUT_DT, v0=V0, substeps=int(round(OUTPUT_DT / h)),
                                      project=False, check=False, outputs=False, workers=1)
        err = np.nanmax(np.abs(unchecked.q - ref), axis=(1, 2))
        err[~unchecked.ok] = np.inf
        bad = ~(err <= ERROR_FRACTION * size)
        print(f"\nh = {h:g} s: {int(bad.sum())} bad run(s) of {len(V0)}; true error per sigma (median): " +
              ", ".join(f"{s:g}: {np.median(err[sigma == s]):.2g} m" for s in args.speeds))
        for estimate in (True, "local"):
            cpu = time.process_time()
            r = nc.simulate_batch(model, args.t_end, OUTPUT_DT, v0=V0, substeps=int(round(OUTPUT_DT / h)),
                                  project=False, check=True, estimate=estimate, workers=1)
            cpu = time.process_time() - cpu
            flagged = ~r.ok
            kinds = {k: sum(w in m for m in r.message) for k, w in REASONS.items()}
            missed, extra = np.flatnonzero(bad & ~flagged), np.flatnonzero(~bad & flagged)
            name = "shadow" if estimate is True else "local"
            print(f"  estimate={name!r}: flagged {int(flagged.sum())} (reasons: "
                  f"{', '.join(f'{k} {c}' for k, c in kinds.items() if c) or 'none'}); "
                  f"bad runs missed {len(missed)} {[f'{sigma[i]:g} rad/s, {err[i]:.2g} m' for i in missed]}; "
                  f"good runs flagged {len(extra)} {[f'{sigma[i]:g} rad/s, {err[i]:.2g} m' for i in extra]}; "
                  f"CPU {cpu:.2f} s")
    print(f"load average at the end: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
