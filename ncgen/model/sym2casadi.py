"""CasADi forms of SymPy expressions.

A small, deterministic tree walker: every SymPy node maps to the CasADi operation of the
same meaning.  The substitution dictionary gives, for each free symbol, a CasADi
expression (SX/MX/DM) or a number; a symbol without a value is an error.
"""
from __future__ import annotations

from functools import lru_cache, reduce

import casadi as ca

from ncgen.errors import NcgenError


@lru_cache(maxsize=None)
def _tables() -> tuple[dict, dict]:
    """The unary functions and the relations, SymPy class -> CasADi form (SymPy is imported on
    first use, so that importing this module stays cheap)."""
    import sympy as sp

    unary = {
        sp.sin: ca.sin, sp.cos: ca.cos, sp.tan: ca.tan,
        sp.asin: ca.asin, sp.acos: ca.acos, sp.atan: ca.atan,
        sp.sinh: ca.sinh, sp.cosh: ca.cosh, sp.tanh: ca.tanh,
        sp.exp: ca.exp, sp.log: ca.log, sp.Abs: ca.fabs, sp.sign: ca.sign,
        sp.floor: ca.floor, sp.ceiling: ca.ceil,
    }
    relations = {
        sp.StrictLessThan: lambda a, b: a < b, sp.LessThan: lambda a, b: a <= b,
        sp.StrictGreaterThan: lambda a, b: a > b, sp.GreaterThan: lambda a, b: a >= b,
        sp.Equality: lambda a, b: a == b, sp.Unequality: lambda a, b: a != b,
    }
    return unary, relations


def to_casadi(expr, values: dict):
    """Translate ``expr`` (SymPy scalar or explicit matrix) to CasADi.

    ``values`` maps each free symbol of ``expr`` to a CasADi expression or a float.
    Matrices become a CasADi matrix of the same shape (type follows the values given).
    """
    import sympy as sp

    memo: dict = {}
    if isinstance(expr, sp.MatrixBase):
        rows = [[_walk(expr[i, j], values, memo) for j in range(expr.shape[1])]
                for i in range(expr.shape[0])]
        return matrix(rows) if rows and rows[0] else ca.DM.zeros(*expr.shape)
    return _walk(sp.sympify(expr), values, memo)


def matrix(rows: list):
    """A CasADi matrix of the rows' entries."""
    return ca.vertcat(*[ca.horzcat(*r) for r in rows])


def _walk(e, values, memo):
    hit = memo.get(e)
    if hit is not None:
        return hit
    out = _convert(e, values, memo)
    memo[e] = out
    return out


def _convert(e, values, memo):
    import sympy as sp

    if e.is_Atom:
        return _atom(e, values)
    if isinstance(e, sp.Piecewise):
        return _piecewise(e, values, memo)
    args = [_walk(a, values, memo) for a in e.args]
    if e.is_Add:
        return reduce(lambda a, b: a + b, args)
    if e.is_Mul:
        return reduce(lambda a, b: a * b, args)
    if e.is_Pow:
        return _power(e.exp, *args)
    return _function(e, args)


def _atom(e, values):
    """A symbol's value, or a number or constant as CasADi takes it."""
    import sympy as sp

    if e.is_Symbol:
        if e not in values:
            raise NcgenError(f"to_casadi: no value given for symbol {e}")
        return values[e]
    if e.is_Integer:
        return int(e)
    if e.is_Number:
        return float(e)
    constants = {sp.pi: ca.pi, sp.E: ca.exp(1), sp.true: 1, sp.false: 0}
    if e in constants:
        return constants[e]
    raise NcgenError(f"to_casadi: no CasADi form for {type(e).__name__} in {e}")


def _power(exponent, base, expo):
    """``base ** expo`` (``exponent`` the SymPy exponent): a square root, a reciprocal and a
    positive integer power in their own CasADi forms."""
    import sympy as sp

    if exponent == sp.Rational(1, 2):
        return ca.sqrt(base)
    if exponent == -1:
        return 1 / base
    if exponent.is_Integer and exponent > 0:
        return ca.constpow(base, int(exponent))
    return base ** expo


def _function(e, args):
    """A function, relation or logical operation ``e`` of the converted ``args``."""
    import sympy as sp

    unary, relations = _tables()
    f = unary.get(type(e))
    if f is not None:
        return f(args[0])
    if isinstance(e, sp.atan2):
        return ca.atan2(args[0], args[1])
    if isinstance(e, sp.Max):
        return reduce(ca.fmax, args)
    if isinstance(e, sp.Min):
        return reduce(ca.fmin, args)
    if type(e) in relations:
        return relations[type(e)](args[0], args[1])
    if isinstance(e, sp.And):
        return reduce(ca.logic_and, args)
    if isinstance(e, sp.Or):
        return reduce(ca.logic_or, args)
    if isinstance(e, sp.Not):
        return ca.logic_not(args[0])
    raise NcgenError(f"to_casadi: no CasADi form for {type(e).__name__} in {e}")


def _piecewise(e, values, memo):
    """``Piecewise((v1, c1), (v2, c2), ..., (vn, True))`` as nested ``if_else``."""
    import sympy as sp

    *branches, (default, last_cond) = e.args
    if last_cond is not sp.true:
        raise NcgenError(f"to_casadi: Piecewise without a default branch: {e}")
    result = _walk(default, values, memo)
    for val, cond in reversed(branches):
        result = ca.if_else(_walk(cond, values, memo), _walk(val, values, memo), result)
    return result
