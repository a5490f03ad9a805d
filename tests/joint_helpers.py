"""Test mechanisms for the joint library: members of every kind placed through a point,
and the constraint Jacobian of a system without building the whole model."""
from __future__ import annotations

import casadi as ca
import numpy as np

from ncgen.assembly.build import constraint_rows, initial_guess
from ncgen.model.context import Context
from ncgen.model.layout import make_layout

AT3 = np.array([0.3, -0.2, 0.5])
AXIS3 = np.array([1.0, 2.0, 2.0]) / 3.0                  # a generic unit direction
ACROSS3 = np.array([2.0, -2.0, 1.0]) / 3.0               # ⟂ AXIS3
AT2 = np.array([0.3, -0.2])
AXIS2 = np.array([0.6, 0.8])
ACROSS2 = np.array([-0.8, 0.6])


def rotation3(seed: int = 1) -> np.ndarray:
    Q, R = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    Q = Q * np.sign(np.diag(R))
    return Q if np.linalg.det(Q) > 0 else -Q


def make_member(s, kind: str, name: str, at, along=None, across=None):
    """A member of ``kind`` through the world point ``at``: the ground, a body (rotated,
    its centre of mass off ``at``), a bar along ``along`` or ``across`` (through ``at``), a
    point member at ``at``."""
    at = np.asarray(at, float)
    d = s.dim
    if kind == "ground":
        return s.ground
    if kind == "body":
        if d == 3:
            return s.add_body(name, coords="rrvw", mass=1.3, inertia=np.diag([0.2, 0.3, 0.4]),
                              position=at + [0.1, 0.2, -0.1], rotation=rotation3(len(name)))
        return s.add_body(name, coords="rrv", mass=1.3, inertia=0.2, position=at + [0.1, 0.2], rotation=0.4)
    if kind in ("bar_along", "bar_across"):
        e = np.asarray(along if kind == "bar_along" else across, float)
        return s.add_bar(name, coords="rr" if len(name) % 2 else "ru", mass=0.7,
                         ends=[at - 0.4 * e, at + 0.8 * e])
    if kind == "point":
        return s.add_point(name, mass=0.5, position=at)
    raise ValueError(kind)


def jacobian(s, q=None, t=0.0):
    """``(labels, A)`` of the system's constraints at ``q`` (default: the initial guess)."""
    members = list(s.members.values())
    layout = make_layout(s.dim, members)
    ctx = Context(s, layout)
    labels, rows = constraint_rows(s, ctx)
    q = initial_guess(layout, members)[0] if q is None else q
    phi = ca.vertcat(*rows)
    p0 = np.concatenate([v for _, v in s.parameters.values()]) if s.parameters else np.zeros(0)
    A = ca.Function("A", [ctx.t, ctx.q, ctx.p], [ca.jacobian(phi, ctx.q)])
    return labels, np.array(A(t, q, p0))


def removed_dof(s) -> tuple[int, int]:
    """(number of joint equations, rank they add to the intrinsic constraints)."""
    labels, A = jacobian(s)
    n_intr = sum(1 for lab in labels if ".rigid." in lab)
    r_all = np.linalg.matrix_rank(A)
    r_intr = np.linalg.matrix_rank(A[:n_intr]) if n_intr else 0
    return len(labels) - n_intr, int(r_all - r_intr)
