"""Values of a model that must not be negative (spring stiffness, damping, rest length),
checked for the parameter values actually used.

A force element lists them in ``Force.nonnegative()`` (name -> value).  A number is checked
when the force is added; a value given as an expression of parameters is checked here, when
the model is built (default parameters, and ``--param`` overrides) and again by
``simulate(p=...)``.  Values depending on time or inputs are checked only where they are
constant.  A negative stiffness makes the spring push its ends apart without bound and its
"potential energy" unbounded below, which is never what a model means.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ncgen.errors import ModelError


@dataclass(frozen=True)
class Limits:
    """``labels[i]`` must be ≥ 0; ``values(p)`` evaluates all of them (``None``: there are none)."""

    labels: tuple[str, ...]
    values: ca.Function | None

    def check(self, p: np.ndarray, parameter_names=(), where: str = "") -> None:
        """Raise a :class:`ModelError` naming the first negative value (and the parameters it uses)."""
        if self.values is None:
            return
        v = np.array(self.values(p), dtype=float).reshape(-1)
        for label, x in zip(self.labels, v):
            if not np.isfinite(x) or x < 0:
                uses = f" (from the parameters {', '.join(parameter_names)})" if parameter_names else ""
                raise ModelError(f"{where}{label} = {x:g}{uses}: expected a finite number >= 0")


def model_limits(system, ctx) -> Limits:
    """The non-negative values of every force of ``system`` that depend on parameters only."""
    labels, rows = [], []
    p_hashes = {ctx.p[i].element_hash() for i in range(ctx.p.numel())}
    for force in system.forces:
        for key, value in force.nonnegative().items():
            what = f"{force.label}: {key}"
            e = ctx.expression(value, 1, what, inputs=True)
            if any(s.element_hash() not in p_hashes for s in ca.symvar(e)):
                continue          # depends on t or inputs: not checked here
            labels.append(what)
            rows.append(e)
    if not rows:
        return Limits((), None)
    return Limits(tuple(labels), ca.Function("nonnegative", [ctx.p], [ca.vertcat(*rows)]))
