"""Plain-data signatures of CasADi functions: names, shapes and sparsity of inputs and outputs.

Sparsity is given in compressed column storage (CCS, CasADi's native format):
``colind`` has ``ncol + 1`` entries, ``row`` has ``nnz``; the nonzeros of column ``j``
are ``row[colind[j]:colind[j+1]]``.  Numeric data passed to or returned by a kernel are
these nonzeros in that order.
"""
from __future__ import annotations

import casadi as ca


def sparsity_json(sp: ca.Sparsity) -> dict:
    """Shape, nnz and CCS pattern of ``sp``."""
    return {"shape": [sp.size1(), sp.size2()], "nnz": sp.nnz(), "dense": sp.is_dense(),
            "colind": [int(i) for i in sp.colind()], "row": [int(i) for i in sp.row()]}


def function_signature(f: ca.Function) -> dict:
    """Inputs and outputs of ``f`` with their sparsity, in argument order."""
    return {
        "inputs": [{"name": f.name_in(i), **sparsity_json(f.sparsity_in(i))} for i in range(f.n_in())],
        "outputs": [{"name": f.name_out(i), **sparsity_json(f.sparsity_out(i))} for i in range(f.n_out())],
    }
