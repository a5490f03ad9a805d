"""Issue 35, class 7: ``nc.step_function`` refuses a step ``h`` (and a tolerance) that is not a
positive finite number, naming it, and a step whose Newton iterations end with NaN or inf
(``h = 1e300`` returned an infinite state without an error) — through the step, its
Jacobians, rollouts and their gradients."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import ncgen as nc
from ncgen.errors import NcgenError

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


@pytest.fixture(scope="module")
def cartpole():
    return nc.System.from_toml(EXAMPLES / "cartpole.toml").build()


@pytest.mark.parametrize("h", [0.0, -0.01, float("inf"), float("nan"), "abc", None, True, [0.01, 0.02]])
def test_a_step_that_is_not_positive_and_finite_is_named(cartpole, h):
    with pytest.raises(NcgenError, match=r"step_function: h: expected a positive, finite step in seconds, got"):
        nc.step_function(cartpole, h)


@pytest.mark.parametrize("abstol", [0.0, -1e-12, float("nan"), "tight"])
def test_a_tolerance_that_is_not_positive_and_finite_is_named(cartpole, abstol):
    with pytest.raises(NcgenError, match=r"step_function: abstol: expected a positive, finite tolerance"):
        nc.step_function(cartpole, 0.02, abstol=abstol)


def test_a_huge_step_ends_in_an_error_not_an_infinite_state(cartpole):
    st = nc.step_function(cartpole, 1e300)
    x = np.concatenate([cartpole.q0, cartpole.v0])
    x[cartpole.nq:] = nc.project_velocity(cartpole, cartpole.q0, np.ones(cartpole.nq))
    message = r"step of 'cartpole' \(h = 1e\+300 s\).*(NaN or inf in the state|residual)"
    with pytest.raises(nc.StepDidNotConverge, match=message):
        st(x, 1.0)
    with pytest.raises(nc.StepDidNotConverge, match=message):
        st.jacobians(x, 1.0)
    with pytest.raises(nc.StepDidNotConverge, match=r"step of 'cartpole' \(h = 1e\+300 s\) 0 of the rollout"):
        st.rollout(x, np.ones((3, 1)))
    with pytest.raises(nc.StepDidNotConverge, match=r"0 of the rollout"):
        st.rollout_gradient(x, np.ones((3, 1)), np.ones((3, st.nx)))
