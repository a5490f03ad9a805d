"""What every transcription gives the NLP builder (:mod:`ncgen.optim.nlp`).

A transcription turns the index-1 dynamics on a horizon ``[t0, t0 + T]`` split into ``N``
equal intervals of length ``h = T / N`` into decision variables and equality constraints
of a ``casadi.Opti``.  Inputs are piecewise constant: ``u(t) = u_k`` on
``[t_k, t_{k+1})`` (the same parametrisation for every transcription, so a solution warm
starts any of them and re-simulates exactly with piecewise-constant inputs).

The builder owns the initial node ``(q_0, v_0)`` (constants or variables), the final
time ``T`` and the parameter vector ``p``; the transcription owns everything after.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import casadi as ca
import numpy as np

#: Marks an initial state taken from the model (its consistent ``q0``/``v0``) rather than given.
MODEL_STATE = "model"


@dataclass
class Horizon:
    """Builder-owned quantities the transcription works with (``t0`` in s; ``T``: MX or
    float, s; ``p``: MX parameter vector; ``q0``, ``v0``: the initial node, MX or DM)."""

    t0: float
    T: object
    p: object
    q0: object
    v0: object
    N: int


@dataclass
class Guess:
    """An initial guess as functions of time: each maps a 1-D array of times (s) to an
    array ``len(t) × n`` (``q``, ``v``, ``a``: nq; ``lam``: nc; ``u``: nu)."""

    T: float
    q: Callable[[np.ndarray], np.ndarray]
    v: Callable[[np.ndarray], np.ndarray]
    a: Callable[[np.ndarray], np.ndarray]
    lam: Callable[[np.ndarray], np.ndarray]
    u: Callable[[np.ndarray], np.ndarray]


@dataclass
class Discretisation:
    """The transcribed dynamics.

    ``q``, ``v``: nq × (N+1) node states (column 0 is the builder's initial node);
    ``lam``: nc × N multipliers at nodes 1..N; ``U``: nu × N inputs;
    ``path_t``, ``path_q``, ``path_v``: the state points other than node 0 where bounds
    and path constraints are imposed; ``quad_t``, ``quad_q``, ``quad_v``, ``quad_w``: the
    quadrature rule ``∫ g dt ≈ Σ w_i g(t_i, q_i, v_i)`` for integral costs (weights in s);
    ``defects``: labelled dynamics equations ``e == 0``;
    ``set_guess(opti, guess)``: initial values for the transcription's own variables;
    ``expandable``: the NLP may be expanded to SX (no integrator or rootfinder calls);
    ``t_nodes``: node times (1 × (N+1)) where the intervals are not equal (else ``None``),
    ``interval_w``: the lengths (s, 1 × N) weighting the inputs' effort (``None``: ``T/N``),
    ``extra_cost``: a term the transcription adds to the objective (``None``: none);
    joint-space transcriptions (:mod:`ncgen.optim.joint_radau`) also give ``qj``, ``vj``
    (joint coordinates and rates at the nodes) and ``path_qj``, ``path_vj`` (at the state
    points), and ``lam = None`` (no multipliers: they are computed at the nodes afterwards).
    """

    q: object
    v: object
    lam: object
    U: object
    path_t: object
    path_q: object
    path_v: object
    quad_t: object
    quad_q: object
    quad_v: object
    quad_w: object
    defects: list = field(default_factory=list)
    set_guess: Callable = None
    expandable: bool = True
    qj: object = None
    vj: object = None
    path_qj: object = None
    path_vj: object = None
    t_nodes: object = None
    interval_w: object = None
    extra_cost: object = None


class Transcription:
    """Base class: ``hessian`` (IPOPT's ``hessian_approximation``), :meth:`build` and
    :meth:`describe`; :meth:`solve` (how the built NLP is solved: one IPOPT call, or a
    sequence such as a homotopy) and :meth:`finish` (checks and additions to the result)."""

    hessian = "exact"
    #: IPOPT options the transcription needs (the user's ``ipopt={...}`` override them).
    ipopt_options: dict = {}

    def solve(self, nlp, solve_once, tol_ipopt: float):
        return solve_once()

    def finish(self, value, result) -> None:
        """Nothing to add."""

    def build(self, opti: ca.Opti, model, horizon: Horizon) -> Discretisation:
        raise NotImplementedError

    def describe(self) -> str:
        return self.name


def node_times(horizon: Horizon, tau) -> object:
    """Times ``t0 + (k + τ) h`` (row vector, MX or DM) for ``k = 0..N−1`` and each ``τ``."""
    tau = np.atleast_1d(np.asarray(tau, dtype=float))
    frac = (np.arange(horizon.N)[:, None] + tau[None, :]).reshape(1, -1) / horizon.N
    return horizon.t0 + horizon.T * ca.DM(frac)


def guess_times(horizon: Horizon, T: float, tau) -> np.ndarray:
    tau = np.atleast_1d(np.asarray(tau, dtype=float))
    return horizon.t0 + T * ((np.arange(horizon.N)[:, None] + tau[None, :]).reshape(-1) / horizon.N)
