"""Assembly by continuation of the drives (``build(assemble=True)``).

A drive that prescribes another position at ``t0`` than the members' given poses (a
``Revolute(..., drive="pi/2 + t")`` on a bar lying at angle 0) must move the mechanism
before anything is checked at the initial configuration.  Newton's method from the given
poses can fail there: the drive equation of a hinge, ``(a × m₁) cos θ − (a·m₁) sin θ = 0``,
is at its extreme when the hinge is a quarter turn away, so its gradient is parallel to the
bar-length constraint's and the Jacobian is singular (it also vanishes at θ + π, so a
perturbed Newton step could pick the wrong half-turn).  Instead, every driven joint that
measures its own coordinate (``Revolute``, ``Prismatic``: ``joint.coordinate``) gets the
drive value

    θ_s = (1 − s) θ_given + s θ_drive(t0),        s = 0 → 1,

in steps (halved where Newton fails), each solved by the manifold's Newton
(:func:`ncgen.assembly.manifold.newton`: minimum-norm least-squares steps on the coordinates
not fixed).  At ``s = 0`` the given poses hold it; the
motion then follows the drive continuously to the branch it prescribes.  Other drives
(``Distance``, coordinate drivers) keep their value throughout.
"""
from __future__ import annotations

from typing import Callable

import casadi as ca
import numpy as np

from ncgen.assembly.manifold import newton

#: Continuation steps in s at first (halved where Newton fails, at most HALVINGS times).
STEPS = 16
HALVINGS = 8
#: Gauss–Newton iterations per continuation step at most, and the residual accepted
#: (times 1 + the largest |q|) on the way and at the end.
MAX_ITER = 25
TOL_PATH, TOL = 1e-8, 1e-12


def continued_drives(system) -> list:
    """The joints whose drives :func:`assemble_drives` continues."""
    return [j for j in system.joints if j.drive is not None and hasattr(j, "coordinate")]


def assemble_drives(system, ctx, rows_of: Callable, q: np.ndarray, p: np.ndarray, t0: float,
                    fixed=()) -> np.ndarray:
    """The configuration reached from ``q`` by continuing the drives from their measured
    values to their values at ``t0`` (module docstring); ``rows_of(ctx)`` returns the
    constraint expressions; coordinates ``fixed`` (indices) are kept.  Returns ``q``
    unchanged when there is nothing to continue or the continuation fails (the consistent
    initial state that follows then reports the failure)."""
    driven = continued_drives(system)
    if not driven:
        return q
    s = ca.SX.sym("s")
    measured = ca.Function("measured", [ctx.t, ctx.q, ctx.p], [ca.vertcat(*(j.coordinate(ctx) for j in driven))])
    start = np.array(measured(t0, q, p), dtype=float).reshape(-1)
    ctx.drive_blend = {j.name: (lambda expr, c=float(c): (1 - s) * c + s * expr) for j, c in zip(driven, start)}
    try:
        phi = ca.vertcat(*rows_of(ctx))
    finally:
        ctx.drive_blend = {}
    f = (ca.Function("phi_s", [ctx.t, ctx.q, ctx.p, s], [phi]),
         ca.Function("A_s", [ctx.t, ctx.q, ctx.p, s], [ca.jacobian(phi, ctx.q)]))
    free = np.setdiff1d(np.arange(len(q)), np.asarray(list(fixed), dtype=int))
    at, step, halvings = 0.0, 1.0 / STEPS, 0
    while at < 1.0:
        target = min(1.0, at + step)
        moved = _newton(f, q, p, t0, target, free, TOL if target == 1.0 else TOL_PATH)
        if moved is None:
            halvings += 1
            if halvings > HALVINGS:
                return q
            step /= 2
            continue
        q, at = moved, target
    return q


def _newton(f, q, p, t0, s, free, tol) -> np.ndarray | None:
    """``q`` moved onto the blended constraints at ``s`` (residual ≤ ``tol`` × (1 + max |q|)),
    or None where Newton does not get there in :data:`MAX_ITER` iterations."""
    phi, jac = f
    bound = tol * (1.0 + float(np.max(np.abs(q), initial=0.0)))
    try:
        q_new, _, res = newton(lambda x: np.array(phi(t0, x, p, s), dtype=float).reshape(-1),
                               lambda x: np.array(jac(t0, x, p, s), dtype=float), q, free,
                               tol=bound, max_iter=MAX_ITER)
    except np.linalg.LinAlgError:                   # a Jacobian that is not finite
        return None
    return q_new if res <= bound else None
