"""CasADi forms of the rotation formulas the joint coordinates use, each translated once
(:func:`ncgen.model.sym2casadi.to_casadi`) from its SymPy source in
:mod:`ncgen.symbolic.rigid_motion`: ``quaternion`` (Shepperd, ``qw ≥ 0``), ``swing`` (rotation
vector of the smallest rotation between two directions) and ``exp_so3`` (Rodrigues).  Each is
an SX :class:`casadi.Function`: called with SX it inlines, with numbers it returns DM.
"""
from __future__ import annotations

from functools import lru_cache

import casadi as ca
import sympy as sp

from ncgen.model.sym2casadi import to_casadi
from ncgen.symbolic import rigid_motion as rm


def _symbols(name: str, rows: int, cols: int = 1) -> sp.Matrix:
    return sp.Matrix(rows, cols, lambda i, j: sp.Symbol(f"{name}_{i}{j}", real=True))


@lru_cache(maxsize=None)
def function(name: str) -> ca.Function:
    """The SX function ``name``: ``quaternion(R) -> quat``, ``swing(u0, u) -> phi``,
    ``exp_so3(omega) -> R``."""
    shapes = {"quaternion": [("R", 3, 3)], "swing": [("u0", 3, 1), ("u", 3, 1)], "exp_so3": [("omega", 3, 1)]}
    outs = {"quaternion": "quat", "swing": "phi", "exp_so3": "R"}
    args = [(n, _symbols(n, r, c), ca.SX.sym(n, r, c)) for n, r, c in shapes[name]]
    values = {s[i, j]: x[i, j] for _, s, x in args for i in range(s.shape[0]) for j in range(s.shape[1])}
    expr = getattr(rm, name)(*[s for _, s, _ in args])
    return ca.Function(name, [x for _, _, x in args], [to_casadi(expr, values)],
                       [n for n, _, _ in args], [outs[name]])


def quaternion(R):
    """Unit quaternion ``[qx, qy, qz, qw]`` (``qw ≥ 0``) of the rotation matrix ``R``."""
    return function("quaternion")(R)


def swing(u0, u):
    """``φ = (θ / sin θ)(u0 × u)``: the rotation vector taking the unit ``u0`` to ``u``."""
    return function("swing")(u0, u)


def exp_so3(omega):
    """``exp(ω̂)``: rotation by ``|ω|`` about ``ω``."""
    return function("exp_so3")(omega)
