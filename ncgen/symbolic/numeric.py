"""NumPy forms of SymPy expressions.

Every numeric formula in ncgen is produced here from its SymPy source with
:func:`sympy.lambdify`, once per (expression, argument list) and process.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

_CACHE: dict[tuple, Callable] = {}


def _flat_args(args: Sequence) -> list:
    import sympy as sp
    flat = []
    for a in args:
        if isinstance(a, (sp.MatrixBase, list, tuple)):
            flat.append(list(sp.Matrix(a)))
        else:
            flat.append(a)
    return flat


def numpy_function(expr, args: Sequence, key: tuple | None = None) -> Callable:
    """Return ``f(*values) -> np.ndarray`` evaluating ``expr`` (scalar or matrix).

    ``args`` is a sequence of symbols, symbol vectors/matrices (flattened row-major, so
    pass the value with the same number of entries) or MatrixSymbols.  ``key`` names the
    formula for the per-process cache; without it the cache key is the expression itself.
    """
    import sympy as sp
    cache_key = key if key is not None else (sp.srepr(expr), tuple(sp.srepr(a) for a in args))
    fn = _CACHE.get(cache_key)
    if fn is None:
        flat = _flat_args(args)
        if isinstance(expr, sp.Basic) and expr.has(sp.Trace):   # NumPy printer lacks Trace
            expr = expr.replace(sp.Trace, lambda A: sp.Add(*[A[i, i] for i in range(A.shape[0])]))
        raw = sp.lambdify(flat, expr, modules="numpy", cse=True)
        is_matrix = isinstance(expr, (sp.MatrixBase, sp.MatrixExpr))

        def fn(*values, _raw=raw, _flat=flat, _is_matrix=is_matrix):
            vals = []
            for spec, v in zip(_flat, values, strict=True):
                if isinstance(spec, list):
                    vals.append(list(np.asarray(v, dtype=float).reshape(-1)))
                else:
                    vals.append(v)
            out = _raw(*vals)
            return np.array(out, dtype=float) if _is_matrix else float(out)

        _CACHE[cache_key] = fn
    return fn
