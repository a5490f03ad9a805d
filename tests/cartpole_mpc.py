"""The cart-pole MPC set-up shared by the MPC tests (tests/test_control_mpc.py,
tests/test_mpc_c_loop.py, tests/test_mpc_fatrop.py, tests/test_mpc_qr_option.py):
examples/cartpole.toml, the horizon problem of examples/cartpole_mpc.toml, the push the
closed loops reject and the tilted starting states."""
from __future__ import annotations

from pathlib import Path

import numpy as np

import ncgen as nc
from ncgen.optim.problem_file import load_problem

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
PUSH = [(1.0, 1.1, [8.0])]                # an 8 N push on the cart for 0.1 s


def cartpole():
    """The cart-pole model (examples/cartpole.toml)."""
    return nc.System.from_toml(EXAMPLES / "cartpole.toml").build()


def cartpole_problem(model=None):
    """The horizon problem of examples/cartpole_mpc.toml on ``model`` (default: :func:`cartpole`)."""
    return load_problem(EXAMPLES / "cartpole_mpc.toml", cartpole() if model is None else model)[0]


def tilted(angle, cart=0.0, model=None):
    """The cart-pole at rest with the pole ``angle`` rad off the upright (cart at ``cart`` m);
    with ``model``, checked on its constraints first."""
    q = np.array([cart, 0, 1, 0, 0, 1, cart + 0.5 * np.sin(angle), 0.5 * np.cos(angle)])
    if model is not None:
        assert np.max(np.abs(np.array(model.functions["phi"](model.t0, q, model.p0)))) < 1e-12
    return np.concatenate([q, np.zeros(8)])
