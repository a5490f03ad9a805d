"""The watch of IDAS runs (``σ_min/σ_max`` of A and its rate): the block evaluation equals the
one-state evaluation, and the rate equals a central difference of the ratio along the motion."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.assembly.manifold import RATE_BLOCK, ManifoldProjector

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("name", ["slider_crank", "fourbar_3d"])
def test_ratio_rates_of_a_block_equal_one_by_one_and_the_rate_a_central_difference(name):
    model = nc.System.from_toml(ROOT / "examples" / f"{name}.toml").build()
    traj = nc.simulate(model, 1.0, 0.001, backend="vm", rtol=1e-10, atol=1e-12)
    X = np.column_stack([traj.q, traj.v])
    watch = ManifoldProjector(model, model.p0, 1e-10)
    block = watch.ratio_rates(traj.t, X)                    # more than one block, the last one partial
    assert len(traj.t) > 2 * RATE_BLOCK and len(traj.t) % RATE_BLOCK
    single = np.array([watch.ratio_rate(t, x) for t, x in zip(traj.t, X)])
    assert np.max(np.abs(block - single)) < 1e-12
    r, h = block[:, 0], traj.t[1] - traj.t[0]
    central = (r[2:] - r[:-2]) / (2 * h)
    scale = np.max(np.abs(block[:, 1]))
    assert scale > 0 and np.max(np.abs(central - block[1:-1, 1])) < 1e-4 * scale
