"""Which constraints may be dropped as redundant: only those *implied* by the others.

A row of ``A`` that depends linearly on the others at one configuration
(:func:`~ncgen.assembly.initial_state.dependent_rows`) is not necessarily redundant: at a
singular configuration (a chain held fully stretched, a parallelogram lying flat) the rank
of ``A`` drops although the constraint still removes motion nearby, and a constraint can
also depend on the others *and contradict them* (a distance drive asking for 5 m between
two points of one rigid bar).  Dropping either silently changes the mechanism.

The rule (:func:`classify`): with ``K`` the kept rows and ``d`` a dependent one,

1. move ``q0`` onto ``Φ_K(t0, q) = 0`` (minimum-norm Newton): ``q*``;
2. take :data:`SAMPLES` random tangent steps of length :data:`STEP` × the system's size
   in the null space of ``A_K(q*)`` (one of them at ``t0 + TIME_STEP``) and move each back
   onto ``Φ_K = 0``;
3. ``d`` is *implied* when its residual ``Φ_d`` is the same at ``q*`` and at every sample
   to :data:`IMPLIED_TOL` × size²: the kept constraints determine it near ``q0``, not only
   at ``q0`` (a constraint that matters changes to first or second order along the
   tangent steps: by ≥ ~STEP² × size², four orders of magnitude above the tolerance);
4. an implied row is *satisfied* when that common residual is ≤ IMPLIED_TOL × size².

Only implied and satisfied rows are dropped.  Implied but violated rows are a contradiction
between constraints; rows that are not implied mean that the configuration is singular.
Both are errors naming the constraints (the build does not guess which of them the user
meant).  The samples come from a fixed seed, so a model always builds the same way.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ncgen.assembly.manifold import NEWTON_TOL as TOL, newton, null_basis, system_size

#: Random tangent samples per check.
SAMPLES = 4
#: Length of a tangent step, relative to the system's size.
STEP = 1e-2
#: A sample at a later time (s), so that a drive implied only at ``t0`` is not dropped.
TIME_STEP = 1e-2
#: Residual spread (relative to size²) below which a dependent row counts as implied.
IMPLIED_TOL = 1e-9


@dataclass
class Redundancy:
    """The dependent rows split by :func:`classify` (indices into the constraint rows)."""

    droppable: list[int] = field(default_factory=list)      # implied and satisfied
    violated: dict[int, float] = field(default_factory=dict)  # implied, residual (units of Φ)
    singular: dict[int, float] = field(default_factory=dict)  # not implied: largest change seen
    unverified: list[int] = field(default_factory=list)    # the kept constraints could not be solved


def classify(phi, jac, q0: np.ndarray, t0: float, dependent: list[int], *,
             samples: int = SAMPLES, seed: int = 0) -> Redundancy:
    """Split the ``dependent`` rows of ``Φ`` (``phi(t, q)``, ``jac(t, q)``: all rows) by the
    rule in the module docstring."""
    out = Redundancy()
    if not dependent:
        return out
    n_rows = np.asarray(phi(t0, q0)).size
    dep = set(dependent)
    keep = np.array([i for i in range(n_rows) if i not in dep], dtype=int)
    size = system_size(q0)
    tol = IMPLIED_TOL * size**2
    free = np.arange(q0.size)

    def onto(t, q):
        q_new, _, res = newton(lambda x: phi(t, x)[keep], lambda x: jac(t, x)[keep], q, free,
                               tol=TOL * size**2)
        return q_new if np.isfinite(res) and res <= 1e3 * TOL * size**2 else None

    base = onto(t0, q0)
    if base is None:
        out.unverified = sorted(dep)
        return out
    rng = np.random.default_rng(seed)
    tangent = null_basis(jac(t0, base)[keep] if keep.size else np.zeros((0, q0.size)), q0.size).T
    points = [(t0, base)]
    for k in range(samples):
        if tangent.shape[0] == 0:
            break
        step = tangent.T @ rng.standard_normal(tangent.shape[0])
        step *= STEP * size / max(np.linalg.norm(step), 1e-300)
        t = t0 + (TIME_STEP if k == samples - 1 else 0.0)
        q = onto(t, base + step)
        if q is None:
            out.unverified = sorted(dep)
            return out
        points.append((t, q))
    values = np.array([np.asarray(phi(t, q))[dependent] for t, q in points])
    for j, i in enumerate(dependent):
        spread = float(np.ptp(values[:, j]))
        if spread > tol:
            out.singular[i] = spread
        elif abs(values[0, j]) > tol:
            out.violated[i] = float(values[0, j])
        else:
            out.droppable.append(i)
    return out
