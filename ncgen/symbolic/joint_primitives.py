"""Joint primitives: the few constraint equations every joint is assembled from.

In natural coordinates a body-fixed point is ``r = C(c) q`` and a body-fixed direction is
``d = X(q) c_d``, both *linear* in q.  Every joint of ncgen is a combination of the
primitives below applied to such points and directions, so every joint constraint is at
most quadratic in q and its Hessian is constant (time-dependent drivers aside).

Each primitive is a SymPy expression in generic vector symbols (``r_A``, ``a``, ...) and
scalar constants; :func:`primitive` returns it together with its argument groups so that
it can be instantiated numerically or in CasADi.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import sympy as sp


@dataclass(frozen=True)
class Primitive:
    """A constraint primitive ``expr(args)``; ``args`` are symbol vectors or scalars."""

    name: str
    expr: sp.Matrix
    args: tuple
    doc: str


def _v(name: str, dim: int) -> sp.Matrix:
    import sympy as sp
    return sp.Matrix([sp.Symbol(f"{name}_{a}", real=True) for a in "xyz"[:dim]])


def _dot(a: sp.Matrix, b: sp.Matrix):
    return (a.T * b)[0]


def _cross2(a: sp.Matrix, b: sp.Matrix):
    return a[0] * b[1] - a[1] * b[0]


@lru_cache(maxsize=None)
def primitive(name: str, dim: int) -> Primitive:
    """The primitive ``name`` in dimension ``dim`` (see :data:`PRIMITIVES`)."""
    import sympy as sp
    rA, rB, a, b, m1, m2 = (_v(n, dim) for n in ("r_A", "r_B", "a", "b", "m_1", "m_2"))
    d, L, theta = sp.Symbol("d", real=True), sp.Symbol("L", positive=True), sp.Symbol("theta", real=True)
    if name == "coincidence":
        return Primitive(name, rA - rB, (rA, rB), "two points coincide: r_A − r_B = 0")
    if name == "dot":
        return Primitive(name, sp.Matrix([_dot(a, b) - d]), (a, b, d),
                         "two directions keep their dot product: aᵀb − d = 0")
    if name == "offset_dot":
        return Primitive(name, sp.Matrix([_dot(rB - rA, a) - d]), (rA, rB, a, d),
                         "a point keeps its offset along a direction: (r_B − r_A)ᵀa − d = 0")
    if name == "distance":
        return Primitive(name, sp.Matrix([_dot(rB - rA, rB - rA) - L**2]), (rA, rB, L),
                         "two points keep their distance: |r_B − r_A|² − L² = 0")
    if name == "slider_ratio":
        rC, rD, s1, s2 = _v("r_C", dim), _v("r_D", dim), sp.Symbol("s_1", real=True), sp.Symbol("s_2", real=True)
        expr = sp.Matrix([s1 * _dot(rB - rA, a) - s2 * _dot(rD - rC, b) - d])
        return Primitive(name, expr, (rA, rB, a, rC, rD, b, s1, s2, d),
                         "two sliders' offsets in a fixed ratio: s_1 (r_B − r_A)ᵀa − s_2 (r_D − r_C)ᵀb − d = 0")
    if name == "angle":
        # a rotates to m_1 by θ about the joint axis; m_2 is a direction ⟂ m_1 (3D: axis × m_1)
        if dim == 2:
            expr = sp.Matrix([_cross2(a, m1) * sp.cos(theta) - _dot(a, m1) * sp.sin(theta)])
            return Primitive(name, expr, (a, m1, theta),
                             "relative angle θ from a to m_1: (a × m_1) cos θ − (a·m_1) sin θ = 0")
        expr = sp.Matrix([_dot(a, m1) * sp.sin(theta) + _dot(a, m2) * sp.cos(theta)])
        return Primitive(name, expr, (a, m1, m2, theta),
                         "relative angle θ about an axis: (a·m_1) sin θ + (a·m_2) cos θ = 0")
    raise KeyError(f"unknown joint primitive {name!r}; known: {', '.join(PRIMITIVES)}")


PRIMITIVES = ("coincidence", "dot", "offset_dot", "distance", "slider_ratio", "angle")


def primitive_rows(name: str, dim: int) -> int:
    """The number of equations of the primitive ``name`` in dimension ``dim`` without deriving
    it: ``dim`` for ``coincidence`` (a vector equation), 1 for the scalar ones."""
    if name not in PRIMITIVES:
        raise KeyError(f"unknown joint primitive {name!r}; known: {', '.join(PRIMITIVES)}")
    return dim if name == "coincidence" else 1
